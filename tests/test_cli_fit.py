"""``persuasive fit`` as a user types it: estimates and comparison, the report and the runs'
files, per participant, and bad input in one line with exit status 2, nothing written."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from persuasive import Config, simulate
from persuasive.cli import main
from persuasive.fitting import load_fitted_run


def run(capsys, *args):
    """Exit code, stdout and stderr of one command (without the first-compilation notice)."""
    code = main(list(args))
    out, err = capsys.readouterr()
    err = "".join(line for line in err.splitlines(keepends=True)
                  if not line.startswith("compiling the numerical kernels once"))
    return code, out, err


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
