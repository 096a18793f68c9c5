"""``persuasive fit`` as a user types it: estimates and comparison, the report and the runs'
files, per participant, and bad input in one line with exit status 2, nothing written."""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import numpy as np
import pytest

from _cli import run_cli as run
from persuasive import Config, simulate
from persuasive.config import ConfigError
from persuasive.fitting import load_fitted_run, load_logs




@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Six logs of a human with p_a = 0.5, against the persuasive and the passive AV."""
    folder = tmp_path_factory.mktemp("logs")
    paths = []
    for j in range(6):
        config = Config(mode="corrected").with_overrides({
            "roles.p_a": 0.5, "mpc.p_a_hat": 1.0,
            "av.kind": "persuasive" if j % 2 == 0 else "passive"})
        path = folder / f"run{j}.parquet"
        simulate(config, 1 + j).save(path)
        paths.append(str(path))
    return paths


def test_fit_prints_estimates_with_intervals_and_the_comparison(capsys, logs):
    code, out, err = run(capsys, "fit", *logs, "--intervals", "selected")
    assert code == 0 and err == ""
    assert "fit of 6 runs, 366 steps" in out
    assert "| model | parameters | log-likelihood | AIC | BIC | delta BIC | exact |" in out
    for model in ("lfg", "stubborn", "noisy", "idm"):
        assert f"| {model} |" in out
    assert "selected (smallest BIC): lfg" in out
    line = next(x for x in out.splitlines() if x.startswith("lfg: "))
    assert "p_a = " in line and "(profile" in line and "sigma = 0.001 [" in line
    assert "exact data" in out  # simulated without noise: sigma on its floor
    assert "roles smoothed under lfg" in out


def test_the_json_report_and_the_json_file_agree(capsys, logs, tmp_path):
    target = tmp_path / "fit.json"
    code, out, err = run(capsys, "fit", *logs, "--model", "lfg", "--json", "--out", str(target))
    assert code == 0 and err == ""
    payload = json.loads(out)
    assert payload == json.loads(target.read_text())
    assert payload["selected"] == "lfg" and payload["runs"] == 6 and payload["steps"] == 366
    p_a = payload["models"]["lfg"]["params"]["p_a"]
    assert p_a["ci95"][0] <= p_a["estimate"] <= p_a["ci95"][1]
    assert [r["source"] for r in payload["run_details"]] == logs
    assert len(payload["models"]["lfg"]["profile"]["p_a"]) == 26


def test_the_runs_file_is_drawn_by_plot_profile(capsys, logs, tmp_path):
    target = tmp_path / "fit.parquet"
    code, out, _ = run(capsys, "fit", *logs, "--model", "lfg", "--out", str(target))
    assert code == 0 and f"written to {target}" in out
    rec = load_fitted_run(target, 2)
    assert rec.seed == 3 and "hv_fit_p_leader" in rec.log
    assert np.all((rec.log["hv_fit_p_leader"] >= 0) & (rec.log["hv_fit_p_leader"] <= 1))
    figure = tmp_path / "profile.png"
    code, out, err = run(capsys, "plot", "profile", "--from", str(target), "--run", "2",
                         "--out", str(figure))
    assert code == 0 and err == "" and figure.stat().st_size > 0
    # --run reads a fit's file only
    code, _, err = run(capsys, "plot", "profile", "--from", logs[0], "--run", "1", "--out",
                       str(tmp_path / "x.png"))
    assert code == 2 and err.count("\n") == 1 and "--run applies only" in err
    code, _, err = run(capsys, "plot", "profile", "--from", str(target), "--run", "9", "--out",
                       str(tmp_path / "x.png"))
    assert code == 2 and "out of range" in err and not (tmp_path / "x.png").exists()


def _drive_trials(folder, participants=("P01", "P02")):
    """Trials of the built-in study as the drive page records them, driven by a keyboard
    pattern (throttle, coast, brake)."""
    from persuasive.web.human import HumanInput
    from persuasive.web.session import Trial
    from persuasive.web.study import default_study

    study = default_study()
    for n, participant in enumerate(participants):
        _, order = study.order_for(participant)
        for index, condition in enumerate(order[:2], start=1):
            trial = Trial(index, condition, False, participant, folder, index, 2)
            trial.build()
            for k in range(trial.n):
                phase = (k + 7 * n) % 30
                trial.human.input = HumanInput(up=phase < 15, down=phase >= 25,
                                               source="keyboard", received_s=time.monotonic())
                trial.world.step()
            trial.save(complete=True)
    return sorted(str(p) for p in folder.glob("*.parquet"))


def test_per_participant_fits_group_the_drive_trials(capsys, tmp_path, logs):
    trials = _drive_trials(tmp_path)
    assert len(trials) == 4
    code, out, err = run(capsys, "fit", *trials, "--per-participant", "--model", "lfg",
                         "--json")
    assert code == 0 and err == ""
    groups = json.loads(out)["groups"]
    assert [g["participant"] for g in groups] == ["P01", "P02"]
    for g in groups:
        assert g["runs"] == 2
        assert all(r["participant"] == g["participant"] and r["hv_kind"] == "person"
                   for r in g["run_details"])
    code, _, err = run(capsys, "fit", logs[0], "--per-participant")
    assert code == 2 and "is not a drive trial" in err and err.count("\n") == 1


def _write(tmp_path, name, frame, meta=True):
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pandas(frame, preserve_index=False)
    if meta:
        rec = simulate(Config(), 1)
        payload = json.dumps({"config_toml": rec.config.to_toml(), "seed": 1,
                              "final_state": [float(x) for x in rec.states[-1]]})
        table = table.replace_schema_metadata({b"persuasive.run": payload})
    path = tmp_path / name
    pq.write_table(table, path)
    return str(path)


def test_bad_input_is_one_line_exit_2_and_nothing_written(capsys, tmp_path, logs):
    frame = simulate(Config(), 1).frame()
    csv = tmp_path / "run.csv"
    frame.to_csv(csv, index=False)
    merge = tmp_path / "merge.parquet"
    simulate(Config().with_overrides({"scenario.kind": "merge"}), 1).save(merge)
    nan = frame.copy()
    nan.loc[4, "hv_accel_mps2"] = np.nan
    cases = [
        ([str(csv)], "is a CSV log"),
        ([str(tmp_path / "none.parquet")], "cannot be read"),
        ([_write(tmp_path, "cols.parquet", frame.drop(columns=["av_meas_s_m"]))],
         "lacks the columns a fit needs: av_meas_s_m"),
        ([_write(tmp_path, "nan.parquet", nan)], "non-finite value (nan) in hv_accel_mps2 at "
                                                 "step 4"),
        ([_write(tmp_path, "empty.parquet", frame.iloc[:0])], "is empty"),
        ([_write(tmp_path, "bare.parquet", frame, meta=False)], "holds no run record"),
        ([logs[0], str(merge)], "is of scenario 'merge', not the model's 'intersection'"),
        ([logs[0], "--scenario", "merge"], "not the model's 'merge' (--scenario)"),
    ]
    out_file = tmp_path / "fit.json"
    for args, words in cases:
        code, out, err = run(capsys, "fit", *args, "--out", str(out_file))
        assert code == 2, args
        assert err.startswith("error: ") and err.count("\n") == 1 and words in err, err
        assert "Traceback" not in err and out == ""
        assert not out_file.exists()
    # the output is checked before anything is read
    code, _, err = run(capsys, "fit", logs[0], "--out", str(tmp_path / "fit.txt"))
    assert code == 2 and "unsupported extension '.txt'" in err
    code, _, err = run(capsys, "fit", logs[0], "--out", str(tmp_path / "no" / "fit.json"))
    assert code == 2 and "does not exist" in err
    code, _, err = run(capsys, "fit", logs[0], "--model", "ddm")
    assert code == 2 and err.count("\n") == 1
    code, _, err = run(capsys, "fit", logs[0], "--sigma-min", "0")
    assert code == 2 and "--sigma-min" in err
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".json") == []


def test_a_fit_is_deterministic(capsys, logs):
    reports = []
    for _ in range(2):
        code, out, _ = run(capsys, "fit", *logs[:4], "--model", "all", "--intervals",
                           "selected", "--json")
        assert code == 0
        payload = json.loads(out)
        payload.pop("seconds")
        reports.append(payload)
    assert reports[0] == reports[1]


# -- issue 23: --sigma-min's range, intervals within their bounds, each run once, participants --


@pytest.mark.parametrize("value", ["nan", "inf", "1e308", "1e-320", "1e200", "0", "-1",
                                   "1e-10", "1.5"])
def test_sigma_min_outside_its_range_is_one_line_exit_2(capsys, tmp_path, logs, value):
    out_file = tmp_path / "fit.json"
    code, out, err = run(capsys, "fit", logs[0], "--sigma-min", value, "--out", str(out_file))
    assert code == 2 and out == "" and not out_file.exists()
    assert err.startswith("error: --sigma-min = ") and err.count("\n") == 1, err
    assert "allowed: [1e-09, 1] m/s^2" in err and "Traceback" not in err


def test_sigma_min_at_the_ends_of_its_range_fits(capsys, logs):
    code, out, _ = run(capsys, "fit", "--help")
    assert code == 0 and "[1e-9, 1] m/s^2" in " ".join(out.split())
    for value in ("1e-9", "1"):
        code, out, err = run(capsys, "fit", *logs[:2], "--sigma-min", value, "--model", "lfg",
                             "--json")
        assert code == 0 and err == ""
        fit = json.loads(out)["models"]["lfg"]
        assert math.isfinite(fit["loglik"])
        for e in fit["params"].values():
            assert e["ci95"][0] <= e["estimate"] <= e["ci95"][1]
        assert fit["params"]["sigma"]["ci95"][0] == float(value)


def test_a_log_given_twice_is_refused(capsys, tmp_path, logs, monkeypatch):
    src = Path(logs[0])
    link = tmp_path / "link.parquet"
    link.symlink_to(src)
    hard = tmp_path / "hard.parquet"
    os.link(src, hard)
    monkeypatch.chdir(src.parent)
    cases = [[logs[0], logs[0]], [src.name, f"./{src.name}"], [logs[0], logs[1], str(link)],
             [str(hard), logs[0]], [f"../{src.parent.name}/{src.name}", logs[0]]]
    out_file = tmp_path / "fit.json"
    for args in cases:
        code, out, err = run(capsys, "fit", *args, "--out", str(out_file))
        assert code == 2 and out == "" and not out_file.exists(), args
        assert err.startswith("error: log file ") and err.count("\n") == 1, err
        assert "is the same file as" in err and "Traceback" not in err
    with pytest.raises(ConfigError, match="is the same file as"):
        load_logs([str(link), logs[0]])
    assert len(load_logs(logs[:2])) == 2


@pytest.fixture(scope="module")
def trials(tmp_path_factory):
    """Two participants' two trials each, saved as the drive page saves them."""
    return _drive_trials(tmp_path_factory.mktemp("trials"))


def _copy(src, dst, drop_trial: bool = False) -> str:
    """``src`` under another name; ``drop_trial``: without the trial record, as trials were
    saved before they stored their participant."""
    import pyarrow.parquet as pq

    table = pq.read_table(src)
    if drop_trial:
        meta = dict(table.schema.metadata)
        record = json.loads(meta[b"persuasive.run"])
        del record["trial"]
        meta[b"persuasive.run"] = json.dumps(record).encode()
        table = table.replace_schema_metadata(meta)
    pq.write_table(table, dst)
    return str(dst)


def test_a_trial_is_its_participants_whatever_its_file_is_called(capsys, tmp_path, trials):
    import pyarrow.parquet as pq

    p01a, p01b, p02a, p02b = trials
    record = json.loads(pq.read_schema(p01a).metadata[b"persuasive.run"])
    assert record["trial"] == {"participant": "P01", "session": "P01", "index": 1,
                               "condition": Path(p01a).stem.split("-t01-")[1],
                               "practice": False, "complete": True}
    files = [_copy(p01a, tmp_path / "P02-t07-renamed.parquet"),  # P01's, named as P02's
             _copy(p01b, tmp_path / "P01-t02-x.parquet"),
             _copy(p02a, tmp_path / "session-a.parquet"),  # no trial name at all
             _copy(p02b, tmp_path / "P03-t02-old.parquet", drop_trial=True)]  # old: its name
    code, out, err = run(capsys, "fit", *files, "--per-participant", "--model", "stubborn",
                         "--intervals", "none", "--json")
    assert code == 0 and err == ""
    groups = {g["participant"]: sorted(r["source"] for r in g["run_details"])
              for g in json.loads(out)["groups"]}
    assert groups == {"P01": sorted(files[:2]), "P02": [files[2]], "P03": [files[3]]}
    # an old trial without a trial name has no participant at all
    old = _copy(p02b, tmp_path / "old.parquet", drop_trial=True)
    code, _, err = run(capsys, "fit", old, "--per-participant")
    assert code == 2 and "is not a drive trial" in err and err.count("\n") == 1


def test_every_interval_lies_within_its_parameters_range(capsys, trials):
    from persuasive.fitting.estimate import BETA_MIN, SIGMA_MAX
    from persuasive.fitting.idm import FITTED

    code, out, err = run(capsys, "fit", *trials, "--json")
    assert code == 0 and err == ""
    payload = json.loads(out)
    ranges = {"p_a": (0.0, 1.0), "pi0": (0.0, 1.0), "beta": (BETA_MIN, math.inf),
              **{name: (lo, hi) for name, lo, hi, _ in FITTED}}
    on_bound = 0
    for model, fit in payload["models"].items():
        # the IDM's sigma is in closed form, without the role models' upper bound
        ranges["sigma"] = (payload["sigma_min"], math.inf if model == "idm" else SIGMA_MAX)
        for name, e in fit["params"].items():
            if e["method"] == "fixed":
                continue
            lo, hi = ranges[name]
            value, low, high = (math.inf if x == "inf" else x
                                for x in (e["estimate"], *e["ci95"]))
            assert lo <= low <= value <= high <= hi, (model, name, e)
            # an estimate on a bound says so, and the bound is its interval's end
            side = "lower" if value == lo else "upper" if value == hi else None
            if side is None:
                assert "on the" not in e["method"], (model, name, e)
            else:
                on_bound += 1
                assert e["method"].endswith(f"one-sided: on the {side} bound"), (model, name)
                assert (low if side == "lower" else high) == value
    assert on_bound >= 5  # these keyboard trials put several estimates on their bounds
