"""The command line as a user types it: outputs, files, and one-line errors with exit status 2."""

import json
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from _cli import run_cli as run
from persuasive.cli import main
from persuasive.cli.simulate import json_summary
from persuasive.simulation import simulate
from persuasive.config import Config
from persuasive.studies.compare import AV_KINDS, DEFAULT_HV_KINDS

REQUIRED = ("mode", "scenario", "av", "hv", "hv_role", "pa", "pa_hat", "seed", "streams",
            "hv_initial_state", "first_at_line", "first_at_conflict_point", "collision",
            "min_distance_to_line_m", "min_distance_m", "idx_end", "infeasible_steps",
            "hv_role_changes", "safety_distance_m", "distance_measured")




@pytest.mark.parametrize("mode", ["paper", "corrected"])
def test_simulate_json_in_both_modes(capsys, mode):
    code, out, err = run(capsys, "simulate", "--json", "--mode", mode, "--seed", "7")
    assert code == 0 and err == ""
    payload = json.loads(out)  # exactly one JSON object
    assert set(REQUIRED) <= set(payload)
    assert payload["mode"] == mode and payload["seed"] == 7 and payload["av"] == "persuasive"
    assert (payload["hv"], payload["scenario"]) == ("lfg", "intersection")
    assert payload["streams"] == ("legacy" if mode == "paper" else "per-agent")
    assert payload["pa_hat"] == payload["pa"] == 1.0
    expected = simulate(Config(mode=mode), 7).summary()
    assert payload == json.loads(json.dumps(expected))


@pytest.mark.parametrize("scenario, measured", [
    ("intersection", "along the paths"), ("left-turn", "along the paths"),
    ("crossing", "between the centres"), ("merge", "between the centres")])
def test_the_summary_names_the_threshold_and_how_distances_are_measured(capsys, scenario,
                                                                        measured):
    args = ["--scenario", scenario]
    if scenario == "crossing":  # at 90 degrees the crossing is the intersection, bit for bit
        args += ["--set", "scenario.angle_deg=60"]
    code, out, _ = run(capsys, "simulate", "--json", *args)
    payload = json.loads(out)
    assert code == 0 and "min_dist_m" not in payload  # the threshold's old, confusable name
    assert payload["safety_distance_m"] == 7.5 and payload["distance_measured"] == measured
    code, out, _ = run(capsys, "simulate", *args)
    assert f"over the run ({measured}; safe set 7.5 m)" in out


def test_bare_groups_print_their_help_and_exit_0(capsys):
    code, out, err = run(capsys)
    assert code == 0 and err == "" and out.startswith("Usage: persuasive [OPTIONS] COMMAND")
    assert "simulate" in out and "reproduce" in out
    code, out, err = run(capsys, "plot")
    assert code == 0 and err == "" and out.startswith("Usage: persuasive plot [OPTIONS]")
    bare = subprocess.run([sys.executable, "-m", "persuasive"], capture_output=True, text=True)
    assert bare.returncode == 0 and bare.stdout.startswith("Usage: persuasive")
    assert bare.stderr == ""


def test_plot_from_a_csv_log_says_only_parquet_is_read(capsys, tmp_path):
    code, _, _ = run(capsys, "simulate", "--out", str(tmp_path / "run.csv"))
    assert code == 0
    code, out, err = run(capsys, "plot", "profile", "--from", str(tmp_path / "run.csv"),
                         "--out", str(tmp_path / "f.png"))
    assert code == 2 and out == ""
    assert err == f"error: run file {str(tmp_path / 'run.csv')!r} is not a Parquet file: only " \
                  "the .parquet logs of 'simulate --out' and the trials of 'drive' are read " \
                  "back (a .csv log holds no configuration)\n"
    assert not (tmp_path / "f.png").exists()


def test_simulate_options_reach_the_configuration(capsys):
    code, out, _ = run(capsys, "simulate", "--json", "--av", "lfg", "--hv-role", "follower",
                       "--pa", "0.7", "--seed", "3", "--set", "mpc.epsilon=0.05")
    payload = json.loads(out)
    assert (payload["av"], payload["hv_role"], payload["pa"]) == ("lfg", "follower", 0.7)
    cfg = Config().with_overrides({"av.kind": "lfg", "hv.role": "follower", "roles.p_a": 0.7,
                                   "mpc.epsilon": 0.05})
    assert payload == json.loads(json.dumps(json_summary(simulate(cfg, 3).summary(), cfg)))
    assert payload["pa_hat"] is None  # the lfg AV reads no estimate


def test_simulate_agent_and_scenario_options(capsys):
    # --av mpc is the persuasive planner's old name; --hv and --scenario pick the human model
    # and the geometry
    _, out, _ = run(capsys, "simulate", "--json", "--av", "mpc", "--seed", "3")
    assert json.loads(out) == json.loads(json.dumps(simulate(Config(), 3).summary()))
    code, out, _ = run(capsys, "simulate", "--json", "--av", "passive", "--hv", "stubborn",
                       "--scenario", "crossing", "--mode", "corrected", "--seed", "3")
    payload = json.loads(out)
    assert code == 0
    assert (payload["av"], payload["hv"], payload["scenario"]) == ("passive", "stubborn",
                                                                   "crossing")
    cfg = Config(mode="corrected").with_overrides({"av.kind": "passive", "hv.kind": "stubborn",
                                                   "scenario.kind": "crossing"})
    # the passive AV reads no p_a_hat, the stubborn human no p_a: null, not a default
    summary = simulate(cfg, 3).summary()
    assert (summary["pa"], summary["pa_hat"]) == (1.0, 1.0)
    assert payload == json.loads(json.dumps({**summary, "pa": None, "pa_hat": None}))
    # the explicit option beats --set
    _, out, _ = run(capsys, "simulate", "--json", "--set", "av.kind=cv", "--av", "lfg")
    assert json.loads(out)["av"] == "lfg"


def test_simulate_text_and_parquet(capsys, tmp_path):
    out_file = tmp_path / "log.parquet"
    code, out, _ = run(capsys, "simulate", "--seed", "996", "--out", str(out_file))
    assert code == 0
    assert "first at the crossing line: AV" in out and "collision: no" in out
    assert "persuasive AV, lfg HV starting as leader" in out and "safe set 7.5 m" in out
    log = pd.read_parquet(out_file)
    record = simulate(Config(), 996)
    assert len(log) == 61
    pd.testing.assert_frame_equal(log, record.frame())


def test_simulate_csv_is_csv(capsys, tmp_path):
    out_file = tmp_path / "log.csv"
    code, _, _ = run(capsys, "simulate", "--seed", "3", "--out", str(out_file))
    assert code == 0
    assert not out_file.read_bytes().startswith(b"PAR1")
    log = pd.read_csv(out_file)
    frame = simulate(Config(), 3).frame()
    assert list(log.columns) == list(frame.columns) and len(log) == 61
    assert (log["av_s_m"].to_numpy() == frame["av_s_m"].to_numpy()).all()


def test_config_file_and_precedence(capsys, tmp_path):
    toml = tmp_path / "c.toml"
    toml.write_text('mode = "corrected"\n[roles]\np_a = 0.5\n[mpc]\nepsilon = 0.05\n')
    _, out, _ = run(capsys, "simulate", "--json", "--config", str(toml))
    assert json.loads(out)["mode"] == "corrected" and json.loads(out)["pa"] == 0.5
    _, out, _ = run(capsys, "simulate", "--json", "--config", str(toml), "--pa", "0.3",
                    "--mode", "paper")
    assert json.loads(out)["pa"] == 0.3 and json.loads(out)["mode"] == "paper"


BAD = [
    (["simulate", "--pa", "1.5"], "roles.p_a = 1.5"),
    (["simulate", "--pa-hat", "-0.1"], "mpc.p_a_hat"),
    (["simulate", "--pa", "nan"], "roles.p_a"),
    (["simulate", "--set", "mpc.epsilon=1"], "mpc.epsilon"),
    (["simulate", "--set", "vehicle.u_min_mps2=0"], "vehicle.u_min_mps2"),
    (["simulate", "--set", "vehicle.v_max_mps=0"], "vehicle.v_max_mps"),
    (["simulate", "--set", "simulation.dt_s=0"], "simulation.dt_s"),
    (["simulate", "--set", "scenario.hv_s0_m=0"], "scenario.hv_s0_m"),
    (["simulate", "--set", "roles.w_s_m2=inf"], "roles.w_s_m2"),
    (["simulate", "--mode", "exact"], "--mode"),
    (["simulate", "--hv-role", "boss"], "--hv-role"),
    (["simulate", "--av", "human"], "--av"),
    (["simulate", "--hv", "robot"], "--hv"),
    (["simulate", "--scenario", "roundabout"], "--scenario"),
    (["simulate", "--set", "simulation.av=lfg"], "simulation.av moved to av.kind"),
    (["simulate", "--set", "simulation.hv_role=follower"], "simulation.hv_role moved to hv.role"),
    (["simulate", "--set", "scenario.av_s0_m=-5"], "scenario.av_s0_m"),
    (["simulate", "--set", "hv.kind=replay"], "hv.replay.file"),
    (["simulate", "--set", "nonsense"], "--set"),
    (["simulate", "--set", "mpc.horizon=3"], "mpc.horizon"),
    (["simulate", "--seed", "-4"], "seed"),
    (["simulate", "--hv", "replay", "--set", "hv.replay.file=no-such.parquet"],
     "hv.replay.file = 'no-such.parquet' cannot be read: no such file"),
    (["reproduce", "table3"], "table3"),
    (["reproduce", "table1", "--seeds", "0"], "--seeds"),
    (["reproduce", "table1", "--workers", "0"], "--workers"),
    (["reproduce", "table1", "--workers", "100000"], "--workers"),
    (["simulate", "--set", "nosection.x=1"], "unknown section 'nosection'"),
    (["simulate", "--set", "mpc.x=1"], "mpc.x: unknown key; allowed: epsilon, p_a_hat"),
    (["simulate", "--set", "mpc.epsilon=1e-13"], "mpc.epsilon"),
    (["simulate", "--scenario", "crossing", "--set", "scenario.angle_deg=0.001"],
     "scenario.angle_deg = 0.001 is out of range; allowed: [15, 165] degrees for a crossing "
     "(flatter roads run side by side instead of crossing)"),
    (["simulate", "--scenario", "merge", "--set", "scenario.angle_deg=5"],
     "scenario.angle_deg = 5.0 is out of range; allowed: [15, 90] degrees for a merge"),
]


@pytest.mark.parametrize("args, names", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_is_one_line_and_exit_2(capsys, args, names):
    code, out, err = run(capsys, *args)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("error: ") and names in err
    assert "Traceback" not in err


def test_malformed_and_missing_config_files(capsys, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[roles\np_a = ")
    code, _, err = run(capsys, "simulate", "--config", str(bad))
    assert code == 2 and "not valid TOML" in err and err.count("\n") == 1
    code, _, err = run(capsys, "simulate", "--config", str(tmp_path / "none.toml"))
    assert code == 2 and "cannot be read" in err
    unknown = tmp_path / "unknown.toml"
    unknown.write_text("[roles]\np_x = 1\n")
    code, _, err = run(capsys, "simulate", "--config", str(unknown))
    assert code == 2 and "roles.p_x: unknown key; allowed: p_a, adapt_role" in err
    assert "out of range" not in err
    unknown.write_text("[rolez]\np_a = 1\n")
    code, _, err = run(capsys, "simulate", "--config", str(unknown))
    assert code == 2 and "unknown section 'rolez'" in err and "roles" in err


#: A TOML file with a Latin-1 byte in a comment: not UTF-8, so not TOML.
NOT_UTF8 = b'mode = "paper"\n# caf\xe9\n'


@pytest.mark.parametrize("command, what", [
    (["simulate", "--config", "{toml}"], "config file"),
    (["reproduce", "table1", "--seeds", "1", "--config", "{toml}", "--out", "{out}"],
     "config file"),
    (["plot", "profile", "--single", "--config", "{toml}", "--out", "{out}.png"], "config file"),
    (["sweep", "{toml}", "--out", "{out}"], "grid file"),
    (["drive", "--study", "{toml}", "--out", "{out}", "--port", "0"], "study file"),
], ids=["simulate", "reproduce", "plot", "sweep", "drive"])
def test_toml_that_is_not_utf8_is_one_line_naming_the_file(capsys, tmp_path, command, what):
    toml = tmp_path / "x.toml"
    toml.write_bytes(NOT_UTF8)
    args = [a.format(toml=toml, out=tmp_path / "out") for a in command]
    code, out, err = run(capsys, *args)
    assert code == 2 and out == ""
    assert err == f"error: {what} {str(toml)!r} is not UTF-8 text (byte 0xe9 at offset 20); " \
                  "TOML files must be UTF-8\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.toml"]  # nothing written


def test_a_results_summary_that_is_not_utf8_is_one_line(capsys, tmp_path):
    (tmp_path / "summary.json").write_bytes(b'{"table": "caf\xe9"}')
    code, out, err = run(capsys, "plot", "table", "--from", str(tmp_path), "--out",
                         str(tmp_path / "t.png"))
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "has no readable summary.json (UnicodeDecodeError)" in err


@pytest.mark.parametrize("args, message", [
    (["reproduce", "table1", "--seeds", "99999999999"],
     "--seeds = 99999999999 is out of range; allowed: integer in [1, 4294967295]"),
    (["reproduce", "all", "--seeds", "4294967295"],
     "--seeds = 4294967295 is out of range; allowed: 1..62500 for 16 rows (at most 1000000 "
     "runs, summarised in memory; 'persuasive sweep' streams more to disk)"),
    (["compare", "--seeds", "4000000000"],  # every planner x every human but replay
     "--seeds = 4000000000 is out of range; allowed: "
     f"1..{1_000_000 // (len(AV_KINDS) * len(DEFAULT_HV_KINDS))} for "
     f"{len(AV_KINDS) * len(DEFAULT_HV_KINDS)} pairs (at most 1000000 runs, summarised in "
     "memory; 'persuasive sweep' streams more to disk)"),
    (["compare", "--seeds", "4294967296", "--av", "cv", "--hv", "idm"],
     "--seeds = 4294967296 is out of range; allowed: integer in [1, 4294967295]"),
], ids=["reproduce-beyond-2^32", "reproduce-too-many-runs", "compare-too-many-runs",
        "compare-beyond-2^32"])
def test_huge_seed_counts_are_refused_up_front(capsys, tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)  # the default results folder would go here
    code, out, err = run(capsys, *args, "--quiet")
    assert (code, out, err) == (2, "", f"error: {message}\n")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command, what", [
    (["compare", "--av", "cv", "--hv", "idm", "--seeds", "2"], "comparison folder"),
    (["reproduce", "table1", "--seeds", "2"], "results folder"),
    (["sweep", "{grid}"], "sweep folder"),
], ids=["compare", "reproduce", "sweep"])
@pytest.mark.parametrize("target", ["/proc/study", "{tmp}/afile/study"],
                         ids=["proc", "under-a-file"])
def test_errors_start_their_own_line_in_the_commands_words(capsys, tmp_path, command, what,
                                                           target):
    """With the progress bar on: /proc/study fails only when the folder is made (as root,
    once the bar is drawn), afile/study when the folder is checked (before any bar)."""
    (tmp_path / "afile").write_text("a file, not a folder")
    (tmp_path / "g.toml").write_text('seeds = 2\n[axes]\n"av.kind" = ["cv"]\n')
    out = target.format(tmp=tmp_path)
    args = [a.format(grid=tmp_path / "g.toml") for a in command]
    code, stdout, err = run(capsys, *args, "--workers", "1", "--out", out)
    assert code == 2 and stdout == ""
    last = err.rstrip("\n").split("\n")[-1]  # a line of its own, not the bar's
    assert last.startswith(f"error: {what} {out!r} cannot be written"), repr(err)
    assert err.count("error:") == 1 and "Traceback" not in err
    if what != "sweep folder":
        assert "sweep folder" not in err


def test_failed_run_leaves_existing_output_untouched(capsys, tmp_path):
    target = tmp_path / "log.parquet"
    target.write_bytes(b"previous results")
    code, _, _ = run(capsys, "simulate", "--pa", "2", "--out", str(target))
    assert code == 2 and target.read_bytes() == b"previous results"
    assert [p.name for p in tmp_path.iterdir()] == ["log.parquet"]


def test_console_script_exit_status_and_no_traceback():
    bad = subprocess.run([sys.executable, "-m", "persuasive", "simulate", "--pa", "-1"],
                         capture_output=True, text=True)
    assert bad.returncode == 2
    assert bad.stderr.strip().startswith("error: roles.p_a = -1.0 is out of range")
    assert "Traceback" not in bad.stderr and bad.stdout == ""
    good = subprocess.run([sys.executable, "-m", "persuasive", "simulate", "--json"],
                          capture_output=True, text=True)
    assert good.returncode == 0 and json.loads(good.stdout)["first_at_line"] == 1


OUTPUT_ERRORS = [
    ("x.csvx", "unsupported extension '.csvx'"),
    ("missing/dir/x.parquet", "does not exist"),
    ("afile/x.parquet", "is not a folder"),
]


@pytest.mark.parametrize("target, reason", OUTPUT_ERRORS, ids=[t for t, _ in OUTPUT_ERRORS])
def test_output_errors_are_one_line_exit_2_and_create_nothing(capsys, tmp_path, target, reason):
    (tmp_path / "afile").write_text("a file, not a folder")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    code, out, err = run(capsys, "simulate", "--out", str(tmp_path / target))
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and reason in err and str(tmp_path / target) in err
    assert ".tmp" not in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.rglob("*")) == before


@pytest.mark.skipif(not Path("/proc/self/mounts").exists(), reason="needs Linux's /proc")
@pytest.mark.parametrize("args, message", [
    (["simulate", "--out", "/proc/x.parquet"],
     "cannot write '/proc/x.parquet': '/proc' is on a virtual file system (proc) that cannot "
     "hold result files"),
    (["simulate", "--out", "/proc/x.csv"],
     "cannot write '/proc/x.csv': '/proc' is on a virtual file system (proc) that cannot hold "
     "result files"),
    (["compare", "--av", "cv", "--hv", "idm", "--seeds", "2", "--out", "/proc/foo"],
     "comparison folder '/proc/foo' cannot be written: '/proc' is on a virtual file system "
     "(proc) that cannot hold result files"),
    (["plot", "profile", "--single", "--out", "/sys/f.png"],
     "cannot write '/sys/f.png': '/sys' is on a virtual file system (sysfs) that cannot hold "
     "result files"),
], ids=["simulate-parquet", "simulate-csv", "compare", "plot"])
def test_outputs_on_a_virtual_file_system_say_so_before_any_work(capsys, args, message):
    """/proc answers "no such file or directory" even to root, whose permissions pass: the
    message must give the true reason, before the run (no compile notice, no bar)."""
    code, out, err = main(list(args)), *capsys.readouterr()
    assert (code, out, err) == (2, "", f"error: {message}\n")


def _precedence_runs(capsys, tmp_path, command, extra=()):
    """``command`` run four ways: p_a from the file, from --set over it, from --pa over both,
    and mode from each layer; returns the payloads (JSON of simulate, or the configuration
    the command recorded)."""
    toml = tmp_path / "c.toml"
    toml.write_text('mode = "corrected"\n[roles]\np_a = 0.5\n')
    layers = [
        ("--config", str(toml)),
        ("--config", str(toml), "--set", "roles.p_a=0.4", "--set", "mode=paper"),
        ("--config", str(toml), "--set", "roles.p_a=0.4", "--set", "mode=paper",
         "--pa", "0.3", "--mode", "corrected"),
    ]
    return [run(capsys, *command, *layer, *extra) for layer in layers]


def test_precedence_simulate(capsys, tmp_path):
    got = [json.loads(out) for _, out, _ in _precedence_runs(capsys, tmp_path,
                                                           ["simulate", "--json"])]
    assert [(g["pa"], g["mode"]) for g in got] == [(0.5, "corrected"), (0.4, "paper"),
                                                  (0.3, "corrected")]


@pytest.mark.parametrize("command", [["plot", "profile", "--single"],
                                     ["plot", "topview", "--single"], ["animate"]])
def test_precedence_figure_commands(capsys, tmp_path, monkeypatch, command):
    import persuasive.simulation as sim

    seen = []
    real = sim.simulate
    monkeypatch.setattr(sim, "simulate", lambda config, seed: seen.append(config) or
                        real(config.with_overrides({"simulation.n_steps": 3}), seed))
    ext = ".gif" if command == ["animate"] else ".png"
    runs = _precedence_runs(capsys, tmp_path, command, ("--out", str(tmp_path / f"f{ext}")))
    assert [code for code, _, _ in runs] == [0, 0, 0]
    assert [(c.roles.p_a, c.mode) for c in seen] == [(0.5, "corrected"), (0.4, "paper"),
                                                    (0.3, "corrected")]


def test_precedence_reproduce(capsys, tmp_path):
    toml = tmp_path / "c.toml"
    toml.write_text('mode = "corrected"\n[mpc]\nepsilon = 0.05\n')
    args = ["reproduce", "table1", "--seeds", "1", "--workers", "1", "--quiet", "--json"]
    modes = []
    for layer in [("--config", str(toml)), ("--config", str(toml), "--set", "mode=paper"),
                  ("--config", str(toml), "--set", "mode=paper", "--mode", "corrected")]:
        out_dir = tmp_path / f"r{len(modes)}"
        code, out, _ = run(capsys, *args, *layer, "--out", str(out_dir))
        assert code == 0
        summary = json.loads(out)
        modes.append(summary["mode"])
        written = tomllib.loads((out_dir / "config.toml").read_text())
        assert written["mode"] == summary["mode"] and written["mpc"]["epsilon"] == 0.05
    assert modes == ["corrected", "paper", "corrected"]


def _files(folder):
    """Every file under ``folder`` with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_reproduce_refuses_to_replace_other_settings(capsys, tmp_path):
    from persuasive import sweep

    args = ["reproduce", "table1", "--workers", "1", "--quiet", "--out", str(tmp_path / "r")]
    assert run(capsys, *args, "--seeds", "2")[0] == 0
    before = _files(tmp_path / "r")
    code, out, err = run(capsys, *args, "--seeds", "1")
    assert code == 2 and "other settings" in err and "--force" in err and out == ""
    assert _files(tmp_path / "r") == before
    assert run(capsys, *args, "--seeds", "2")[0] == 0  # same settings: taken up in place
    assert len(sweep.load(tmp_path / "r")) == 4
    code, _, _ = run(capsys, *args, "--seeds", "1", "--force")
    assert code == 0 and len(sweep.load(tmp_path / "r")) == 2
    assert json.loads((tmp_path / "r" / "summary.json").read_text())["seeds"] == 1


def test_reproduce_default_folder_names_the_settings(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    common = ["reproduce", "table1", "--workers", "1", "--quiet"]
    run(capsys, *common, "--seeds", "2")
    run(capsys, *common, "--seeds", "1")
    run(capsys, *common, "--seeds", "1", "--mode", "corrected")
    folders = sorted(p.name for p in (tmp_path / "results").iterdir())
    assert len(folders) == 3 and all(f.startswith("table1-") for f in folders)
    assert sum(f.startswith("table1-corrected-") for f in folders) == 1
    summaries = [json.loads((tmp_path / "results" / f / "summary.json").read_text())
                 for f in folders]
    assert {s["config_hash"] for s in summaries} == {f.rsplit("-", 1)[1] for f in folders}
    assert sorted(tuple(s["seed_range"]) for s in summaries) == [(1, 1), (1, 1), (1, 2)]


def test_reproduce_caps_workers_at_the_chunks_and_warns_above_the_cores(capsys, tmp_path):
    import os

    cores = os.cpu_count()
    code, out, err = run(capsys, "reproduce", "table1", "--seeds", "1", "--quiet",
                         "--workers", str(cores + 1), "--out", str(tmp_path / "r"))
    assert code == 0 and "warning:" in err and f"on {cores} cores" in err
    assert out.rstrip().endswith("with 2 workers")  # 2 rows of 1 seed: two chunks


def test_reproduce_json_and_files(capsys, tmp_path):
    code, out, _ = run(capsys, "reproduce", "all", "--seeds", "3", "--workers", "1", "--json",
                       "--quiet", "--out", str(tmp_path))
    assert code == 0
    payload = json.loads(out)
    assert set(payload) == {"table1", "table2"}
    t2 = payload["table2"]
    assert t2["table"] == "table2" and t2["mode"] == "paper" and t2["seeds"] == 3
    row = t2["rows"][0]
    for key in ("hv_role", "pa", "pa_hat", "runs", "av_first", "hv_first", "same_step",
                "neither", "av_first_pct", "hv_first_pct", "published_av_first_pct",
                "published_hv_first_pct", "collisions", "runs_with_infeasible",
                "violations_to_line", "violations_whole_run"):
        assert key in row
    assert payload["table1"]["rows"][0]["pa_hat"] is None
    from persuasive import sweep

    for t, rows in (("table1", 2), ("table2", 14)):
        # each table's folder is its sweep (manifest, runs; failed runs when any) with the
        # summary and configuration beside it
        names = {p.name for p in (tmp_path / t).iterdir()}
        assert {"manifest.json", "runs", "summary.json", "summary.md", "config.toml"} <= names
        assert names <= {"manifest.json", "runs", "failed", "summary.json", "summary.md",
                         "config.toml"}
        assert len(sweep.load(tmp_path / t)) == 3 * rows
        assert json.loads((tmp_path / t / "summary.json").read_text()) == payload[t]


def test_reproduce_text_table(capsys, tmp_path):
    code, out, _ = run(capsys, "reproduce", "table1", "--seeds", "2", "--workers", "1",
                       "--quiet", "--out", str(tmp_path))
    assert code == 0
    assert "| L | 1.00 | 0.0 | 100.0 | 0 | 0 |" in out
    assert "4 runs in" in out
    # a short run is not a failure to reproduce: the published values are for 1000 seeds,
    # so the table leaves them out and says so
    assert "NOT" not in out and "published values are for seeds 1..1000" in out
    assert "published AV/HV" not in out and "diff AV/HV" not in out


def test_a_resumed_reproduction_says_what_ran_now(capsys, tmp_path):
    args = ["reproduce", "all", "--seeds", "2", "--workers", "1", "--quiet", "--out",
            str(tmp_path)]
    code, out, _ = run(capsys, *args)
    assert code == 0 and out.rstrip().splitlines()[-1].startswith("32 runs in ")
    assert "finished earlier" not in out
    code, out, _ = run(capsys, *args)  # everything is there
    assert code == 0
    last = out.rstrip().splitlines()[-1]
    assert last.startswith("32 runs: 32 finished earlier, none to run, ") and "worker" not in last
    # table2 loses a part: its chunk runs again, the rest is read back
    parts = sorted((tmp_path / "table2" / "runs").glob("part-*.parquet"))
    parts[3].unlink()
    code, out, _ = run(capsys, *args)
    assert code == 0
    assert out.rstrip().splitlines()[-1].startswith(
        "32 runs: 31 finished earlier, 1 run now with 1 worker, ")  # chunks of 1 run


def test_bench_json(capsys):
    code, out, _ = run(capsys, "bench", "--json", "--runs", "1", "--repeats", "1")
    assert code == 0
    result = json.loads(out)
    for key in ("game_solve_us_median", "mpc_decision_ms_median", "mpc_decision_ms_p99",
                "mpc_run_ms_median"):
        assert result[key] > 0
    assert result["mpc_decision_ms_p99"] >= result["mpc_decision_ms_median"]
    assert result["samples"]["mpc_decisions"] == 61 and "reproduce_all_s" not in result


# -- options that only some kinds read (--pa, --pa-hat, --hv-role) ------------------------------

PA_HAT_USERS = "it is read only by the persuasive AV (its estimate of the human's p_a)"
PA_USERS = ("it is read only by the lfg, noisy humans and the lfg AV (their own p_a; the "
            "persuasive AV's estimate is --pa-hat)")
ROLE_USERS = ("it is read only by the lfg, stubborn, noisy humans and the lfg AV (the lfg AV "
              "starts in the other role)")
KIND_OPTION_ERRORS = [
    (["simulate", "--pa-hat", "online", "--av", "passive"],
     f"--pa-hat = online is not used by the lfg HV with the passive AV; {PA_HAT_USERS}"),
    (["simulate", "--pa-hat", "0.3", "--av", "yield"],
     f"--pa-hat = 0.3 is not used by the lfg HV with the yield AV; {PA_HAT_USERS}"),
    (["simulate", "--pa-hat", "0.3", "--set", "av.kind=cv"],  # the kind from --set counts
     f"--pa-hat = 0.3 is not used by the lfg HV with the cv AV; {PA_HAT_USERS}"),
    (["simulate", "--hv", "adversary", "--pa", "0.3", "--hv-role", "follower"],
     f"--pa = 0.3 is not used by the adversary HV with the persuasive AV; {PA_USERS}"),
    (["simulate", "--hv", "stubborn", "--pa", "0.3"],  # the stubborn human's p_a is 0
     f"--pa = 0.3 is not used by the stubborn HV with the persuasive AV; {PA_USERS}"),
    (["simulate", "--hv", "idm", "--hv-role", "follower"],
     f"--hv-role = follower is not used by the idm HV with the persuasive AV; {ROLE_USERS}"),
    (["simulate", "--hv", "idm", "--av", "lfg", "--set", "av.role=leader", "--hv-role",
      "follower"],  # an LFG AV with a role of its own ignores the human's
     f"--hv-role = follower is not used by the idm HV with the lfg AV; {ROLE_USERS}"),
    (["plot", "profile", "--single", "--av", "cv", "--pa-hat", "0.5"],
     f"--pa-hat = 0.5 is not used by the lfg HV with the cv AV; {PA_HAT_USERS}"),
    (["animate", "--hv", "random", "--pa", "0.5"],
     f"--pa = 0.5 is not used by the random HV with the persuasive AV; {PA_USERS}"),
]


@pytest.mark.parametrize("args, message", KIND_OPTION_ERRORS,
                         ids=[" ".join(a) for a, _ in KIND_OPTION_ERRORS])
def test_options_the_run_ignores_are_refused(capsys, tmp_path, args, message):
    ext = ".gif" if args[0] == "animate" else ".png" if args[0] == "plot" else ".parquet"
    target = tmp_path / f"out{ext}"
    code, out, err = run(capsys, *args, "--out", str(target))
    assert (code, out, err) == (2, "", f"error: {message}\n")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args", [
    ["simulate", "--av", "lfg", "--hv", "adversary", "--pa", "0.3", "--hv-role", "follower"],
    ["simulate", "--hv", "noisy", "--pa", "0.3", "--hv-role", "follower", "--pa-hat", "0.5"],
    ["simulate", "--hv", "stubborn", "--hv-role", "follower"],
], ids=["lfg-av", "noisy-human", "stubborn-role"])
def test_options_a_kind_reads_are_accepted(capsys, args):
    code, out, err = run(capsys, *args, "--json")
    assert code == 0 and err == ""


def test_fields_from_a_config_file_are_run_and_the_summary_names_those_ignored(capsys,
                                                                               tmp_path):
    """A configuration file is shared between kinds: its fields are never refused; the
    summary says which of them the run's kinds do not read."""
    toml = tmp_path / "c.toml"
    toml.write_text('[mpc]\np_a_hat = "online"\n[roles]\np_a = 0.4\n[hv]\nrole = "follower"\n')
    code, out, err = run(capsys, "simulate", "--config", str(toml), "--av", "yield",
                         "--hv", "idm")
    assert code == 0 and err == ""
    assert out.splitlines()[0] == (
        "yield AV, idm HV, intersection, seed 1, paper mode; ignored, as no kind here reads "
        "them: mpc.p_a_hat = online, roles.p_a = 0.4, hv.role = follower")
    # read by these kinds: named as values of the run, not as ignored
    code, out, _ = run(capsys, "simulate", "--config", str(toml), "--mode", "corrected")
    assert code == 0 and out.splitlines()[0] == (
        "persuasive AV, lfg HV starting as follower, p_a = 0.4, p_a_hat online (prior "
        "Beta(7, 3) on 21 points), intersection, seed 1, corrected mode")
    # roles.p_a is the persuasive AV's estimate when mpc.p_a_hat is unset: read, not ignored
    code, out, _ = run(capsys, "simulate", "--hv", "idm", "--set", "roles.p_a=0.4")
    assert code == 0 and out.splitlines()[0] == (
        "persuasive AV, idm HV, p_a_hat = 0.4, intersection, seed 1, paper mode")


def test_repeated_interactions_name_the_estimate_only_for_the_persuasive_av(capsys):
    code, out, _ = run(capsys, "simulate", "--av", "passive", "--interactions", "2",
                       "--set", "mpc.p_a_hat=0.6")
    assert code == 0 and out.splitlines()[0] == (
        "passive AV, lfg HV starting as leader, p_a = 1, seed 1, 2 interactions, paper mode; "
        "ignored, as no kind here reads them: mpc.p_a_hat = 0.6")


# -- every integer option names its range --------------------------------------------------------

COUNT_ERRORS = [
    (["highway", "--episodes", "1e9"], "--episodes = 1e9 is out of range; allowed: integer in "
     "[1, 10000]"),
    (["highway", "--episodes", "1000000000"], "--episodes = 1000000000 is out of range; "
     "allowed: integer in [1, 10000]"),
    (["highway", "--seed", "2147483646", "--episodes", "2"], "--seed = 2147483646 is out of "
     "range; allowed: integer in [0, 2147483645] for 2 episodes (every episode's seed below "
     "2147483647)"),
    (["simulate", "--seed", "1e3"], "--seed = 1e3 is out of range; allowed: integer in "
     "[0, 4294967295]"),
    (["simulate", "--interactions", "1001"], "--interactions = 1001 is out of range; allowed: "
     "integer in [1, 1000]"),
    (["compare", "--seeds", "x"], "--seeds = x is out of range; allowed: integer in "
     "[1, 4294967295]"),
    (["compare", "--timing-seeds", "1e9"], "--timing-seeds = 1e9 is out of range; allowed: "
     "integer in [1, 1000]"),
    (["sweep", "g.toml", "--chunk", "0"], "--chunk = 0 is out of range; allowed: integer in "
     "[1, 100000]"),
    (["bench", "--repeats", "1e9"], "--repeats = 1e9 is out of range; allowed: integer in "
     "[1, 100]"),
    (["animate", "--fps", "0"], "--fps = 0 is out of range; allowed: integer in [1, 120]"),
    (["drive", "--seed", "-1"], "--seed = -1 is out of range; allowed: integer in "
     "[0, 4294967295]"),
    (["drive", "--port", "70000"], "--port = 70000 is out of range; allowed: integer in "
     "[0, 65535]"),
]


@pytest.mark.parametrize("args, message", COUNT_ERRORS, ids=[" ".join(a) for a, _ in COUNT_ERRORS])
def test_integer_options_name_their_range(capsys, tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)  # a default results folder would go here
    code, out, err = run(capsys, *args)
    assert (code, out, err) == (2, "", f"error: {message}\n")
    assert list(tmp_path.iterdir()) == []


def test_workers_name_the_cores(capsys, tmp_path, monkeypatch):
    import os

    monkeypatch.chdir(tmp_path)
    cores = os.cpu_count() or 1
    for command in (["compare"], ["sweep", "g.toml"], ["bench", "--full"]):
        code, out, err = run(capsys, *command, "--workers", "1e3")
        assert (code, out) == (2, "")
        assert err == (f"error: --workers = 1e3 is out of range; allowed: integer in "
                       f"[1, {8 * cores}] (8 per core, {cores} cores)\n")


@pytest.mark.parametrize("value, message", [
    ("nan", 'mpc.p_a_hat = nan is out of range; allowed: a number in [0, 1] or "online"'),
    ("inf", 'mpc.p_a_hat = inf is out of range; allowed: a number in [0, 1] or "online"'),
    ("often", "--pa-hat = often is out of range; allowed: a number in [0, 1] or online"),
])
def test_pa_hat_names_its_range(capsys, value, message):
    code, out, err = run(capsys, "simulate", "--pa-hat", value)
    assert (code, out, err) == (2, "", f"error: {message}\n")


def test_json_summary_gives_no_value_for_what_no_kind_reads(capsys):
    """``--av yield`` reads no estimate of p_a: its JSON says null, not the default 0.7 it
    never used; a configuration that sets it is named as ignored."""
    from persuasive.cli import main

    assert main(["simulate", "--av", "yield", "--set", "mpc.p_a_hat=online", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["pa_hat"] is None and data["ignored_fields"] == ["mpc.p_a_hat = online"]
    assert data["pa"] == 1.0 and data["hv_role"] == "leader"  # the lfg human reads both
    assert main(["simulate", "--pa-hat", "0.9", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["pa_hat"] == 0.9 and "ignored_fields" not in data


def test_ctrl_c_silences_what_libraries_log_while_the_command_tears_down():
    """An interrupt mid-study can make Dask log a cancelled gather with a traceback (seen once
    in tests/test_processes.py): after Ctrl-C the user gets one line, so library logging is
    off until the command has ended, and on again afterwards."""
    import logging
    import os
    import signal

    from persuasive.cli import _interruptible

    noisy = logging.getLogger("distributed.scheduler")
    during = []
    with pytest.raises(KeyboardInterrupt):
        with _interruptible():
            assert noisy.isEnabledFor(logging.ERROR)
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(5)  # the handler raises here
            except KeyboardInterrupt:
                during.append(noisy.isEnabledFor(logging.ERROR))
                raise
    assert during == [False]  # off while the interrupted command tears down
    assert noisy.isEnabledFor(logging.ERROR)  # on again for the next one
