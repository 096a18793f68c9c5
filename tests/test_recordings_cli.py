"""``persuasive recordings`` as a user types it: the round trip simulate -> export -> read ->
pairs -> logs -> fit on our own runs, the figure, and every bad input in one line with exit
status 2, nothing written (through click's runner and through ``persuasive.cli.main``)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from _cli import run_cli as run
from persuasive import Config, simulate
from persuasive.cli import cli
from persuasive.fitting import load_logs
from persuasive.record import load_record
from persuasive.recordings.pairs import read_pairs

from test_recordings import HEADER, straight, write


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two corrected-mode runs at a 90-degree crossing, long enough for both to pass."""
    folder = tmp_path_factory.mktemp("runs")
    config = Config(mode="corrected").with_overrides({"scenario.kind": "crossing",
                                                      "simulation.n_steps": 120})
    paths = []
    for seed in (1, 2):
        path = folder / f"run{seed}.parquet"
        simulate(config, seed).save(path)
        paths.append(str(path))
    return paths




def test_round_trip_simulate_export_pairs_logs_fit(capsys, runs, tmp_path):
    tracks = tmp_path / "tracks"
    code, out, err = run(capsys, "recordings", "export", *runs, "--out", str(tracks),
                         "--noise-m", "0.05", "--noise-mps", "0.1", "--seed", "3")
    assert code == 0 and err == "", err
    assert "noise U(-0.05, 0.05) m, U(-0.1, 0.1) m/s on the speed, seed 3" in out
    assert sorted(p.name for p in tracks.iterdir()) == ["vehicle_tracks_000.csv",
                                                        "vehicle_tracks_001.csv"]
    # the exported centres are the scenario's positions plus noise within 0.05 m
    record = load_record(runs[0])
    exported = pd.read_csv(tracks / "vehicle_tracks_000.csv")
    assert list(exported.columns) == HEADER
    x, y, _ = record.scenario.positions("hv", record.states[:, 2])
    hv = exported[exported["track_id"] == 2]
    assert len(hv) == record.states.shape[0]
    assert np.max(np.abs(hv["x"].to_numpy() - x)) <= 0.0505
    assert np.max(np.abs(hv["y"].to_numpy() - y)) <= 0.0505
    assert 0.02 < np.max(np.abs(hv["y"].to_numpy() - y))  # noise was added
    speed = np.hypot(hv["vx"].to_numpy(), hv["vy"].to_numpy())
    assert np.max(np.abs(speed - record.states[:, 3])) <= 0.1 + 1e-3  # vx, vy: 3 decimals
    assert 0.05 < np.max(np.abs(speed - record.states[:, 3]))  # on the speed too

    pairs = tmp_path / "pairs.parquet"
    figure = tmp_path / "pair.png"
    code, out, err = run(capsys, "recordings", "pairs", str(tracks), "--out", str(pairs),
                         "--figure", str(figure), "--pair", "1", "--quiet")
    assert code == 0 and err == "", err
    assert "pairs found: 2 (2 crossing, 0 merge)" in out and "80-100: 2" in out
    assert figure.stat().st_size > 10_000
    frame, meta = read_pairs(pairs)
    # the pair's s is the simulator's (track 1 the AV), up to the noise and the smoothing
    # (relative to the paths' exact crossing, not to route_conflict's 0.25 m samples)
    first = frame[frame["pair"] == 0]
    steps = np.rint(first["t_s"].to_numpy() / 0.1).astype(int)
    assert steps[0] == 0 and np.array_equal(steps, first["step"].to_numpy())
    assert np.max(np.abs(first["s_1_m"].to_numpy() - record.states[steps, 0])) < 0.1
    assert np.max(np.abs(first["v_2_mps"].to_numpy() - record.states[steps, 3])) < 0.3
    # who passed first agrees with the simulator's outcome at the conflict point
    label = {1: "1", 2: "2"}[record.outcome.first_at_conflict_point]
    assert first["first"].iloc[0] == label
    assert set(frame["angle_deg"].round()) == {90.0}

    logs = tmp_path / "logs"
    code, out, err = run(capsys, "recordings", "logs", str(pairs), "--out", str(logs))
    assert code == 0 and err == "", err
    assert "4 logs of 2 pairs" in out and "crossing at 90 deg: 4 logs" in out
    names = sorted(p.name for p in logs.iterdir())
    assert names == ["crossing-90-p00000-hv1.parquet", "crossing-90-p00000-hv2.parquet",
                     "crossing-90-p00001-hv1.parquet", "crossing-90-p00001-hv2.parquet"]
    loaded = load_logs([str(logs / n) for n in names])
    log = loaded[1]  # pair 0, vehicle 2 (the simulator's HV) as the human
    assert log.config.scenario.kind == "crossing" and log.config.scenario.angle_deg == 90.0
    assert log.config.simulation.dt_s == 0.1 and log.config.mode == "corrected"
    np.testing.assert_allclose(log.states[:, 2], first["s_2_m"].to_numpy()[:-1])
    # the fit's measurement model: the tracks' filter and where the steps lie in the track
    rec = log.meta["recording"]
    assert rec["smoothing"] == {"window": 7, "order": 3, "min_track_s": 2.0, "speed": "file"}
    assert rec["human"] == 2 and rec["track_k0_2"] == 0
    assert rec["track_n_2"] == record.states.shape[0]
    back = load_record(logs / names[1])  # a full run record, outcome recomputed
    assert back.states.shape[0] == log.n_steps + 1
    code, out, err = run(capsys, "fit", *[str(logs / n) for n in names], "--model", "lfg",
                         "--intervals", "none")
    assert code == 0 and err == "", err
    assert "fit of 4 runs" in out and "| lfg | 3 |" in out


def _ok_tracks(tmp_path):
    return write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (-50.0, 0.0), 0.0, [10.0] * 100),
                 straight(2, (0.0, -60.0), 90.0, [8.0] * 120))


def _bad_files(tmp_path):
    """Each bad input of ``recordings pairs`` and the words its one line must hold."""
    good = pd.concat([straight(1, (-50.0, 0.0), 0.0, [10.0] * 100),
                      straight(2, (0.0, -60.0), 90.0, [8.0] * 120)], ignore_index=True)
    cases = {}
    (tmp_path / "notes.csv").write_text("a,b\n1,2\n")
    cases["notes.csv"] = "is not a track file"
    good.drop(columns=["psi_rad"]).to_csv(tmp_path / "vehicle_tracks_001.csv", index=False)
    cases["vehicle_tracks_001.csv"] = "missing columns psi_rad"
    fast = good.copy()
    fast.loc[5, "vx"] = 80.0
    fast[HEADER].to_csv(tmp_path / "vehicle_tracks_002.csv", index=False)
    cases["vehicle_tracks_002.csv"] = "speed: track 1 moves at 80.0 m/s"
    gap = good.drop(index=7)
    gap[HEADER].to_csv(tmp_path / "vehicle_tracks_003.csv", index=False)
    cases["vehicle_tracks_003.csv"] = "frame step: track 1 goes from timestamp_ms 600 to 800"
    nan = good.copy()
    nan.loc[3, "x"] = math.nan
    nan[HEADER].to_csv(tmp_path / "vehicle_tracks_004.csv", index=False)
    cases["vehicle_tracks_004.csv"] = "non-finite: x = nan"
    good[good["track_id"] == 1][HEADER].to_csv(tmp_path / "vehicle_tracks_005.csv",
                                                index=False)
    cases["vehicle_tracks_005.csv"] = "one vehicle: it holds one vehicle only (track 1)"
    follow = pd.concat([straight(1, (-50.0, 0.0), 0.0, [10.0] * 100),
                        straight(2, (-70.0, 0.0), 0.0, [10.0] * 100)])
    follow[HEADER].to_csv(tmp_path / "vehicle_tracks_006.csv", index=False)
    cases["vehicle_tracks_006.csv"] = "no crossing pair: 2 vehicle tracks"
    text = good[HEADER].to_csv(index=False).replace(",car,", ",car,", 1)
    (tmp_path / "vehicle_tracks_007.csv").write_text(text.replace("4.5", "x", 1))
    cases["vehicle_tracks_007.csv"] = "vehicle_tracks_007.csv"
    ind = tmp_path / "ind"
    ind.mkdir()
    pd.DataFrame({"recordingId": 1, "trackId": [1, 1, 1], "frame": [0, 1, 3],
                  "xCenter": 0.0, "yCenter": 0.0, "heading": 0.0, "width": 1.8,
                  "length": 4.5, "xVelocity": 1.0, "yVelocity": 0.0}).to_csv(
        ind / "01_tracks.csv", index=False)
    pd.DataFrame({"trackId": [1], "class": ["car"]}).to_csv(ind / "01_tracksMeta.csv",
                                                           index=False)
    cases["ind/01_tracks.csv"] = "frame step: track 1 goes from frame 1 to 3; allowed: " \
                                 "steps of exactly one frame (40 ms)"
    return cases


def test_bad_track_files_end_in_one_line_and_exit_2_writing_nothing(capsys, tmp_path):
    cases = _bad_files(tmp_path)
    runner = CliRunner()
    for name, words in cases.items():
        out = tmp_path / "pairs.parquet"
        code, stdout, err = run(capsys, "recordings", "pairs", str(tmp_path / name), "--out",
                                str(out))
        assert code == 2 and stdout == "", name
        assert err.startswith("error: ") and err.count("\n") == 1 and words in err, err
        assert not out.exists()
        result = runner.invoke(cli, ["recordings", "pairs", str(tmp_path / name), "--out",
                                     str(out)])
        assert result.exit_code == 2 and words in result.stderr, result.stderr
        assert result.stderr.count("\n") == 1 and "Traceback" not in result.output
        assert not out.exists()


@pytest.mark.parametrize("args, words", [
    (["pairs", "{tracks}", "--figure", "{tmp}/p.png"], "--figure and --pair go together"),
    (["pairs", "{tracks}", "--figure", "{tmp}/p.png", "--pair", "5"], "--pair = 5 is out of "
                                                                        "range"),
    (["pairs", "{tracks}", "--figure", "{tmp}/p.gif", "--pair", "0"], "unsupported extension"),
    (["pairs", "{tracks}", "--out", "{tmp}/p.csv"], "unsupported extension '.csv'"),
    (["pairs", "{tracks}", "--out", "{tmp}/p.parquet", "--angle-min", "170"],
     "angle range = [170, 160] is out of range"),
    (["pairs", "{tmp}/missing.csv"], "does not exist"),
    (["logs", "{tracks}", "--out", "{tmp}/logs"], "is not a Parquet file"),
    (["logs", "{tmp}/p.parquet", "--out", "{tmp}/logs", "--angle-step", "-1"],
     "--angle-step = -1 is out of range"),
    (["export", "{tracks}", "--out", "{tmp}/out"], "is not a Parquet file"),
    (["export", "{tmp}/p.parquet", "--out", "{tmp}/out", "--noise-m", "-0.1"],
     "--noise-m = -0.1 is out of range"),
    (["export", "{tmp}/p.parquet", "--out", "{tmp}/out", "--noise-mps", "nan"],
     "--noise-mps = nan is out of range"),
    (["pairs", "{tracks}", "--speed-from", "radar"],
     "--speed-from = 'radar' is not allowed; allowed: file, positions"),
])
def test_bad_options_end_in_one_line_and_exit_2_writing_nothing(args, words, tmp_path):
    tracks = _ok_tracks(tmp_path)
    before = set(tmp_path.iterdir())
    argv = ["recordings", *[a.format(tracks=tracks, tmp=tmp_path) for a in args]]
    result = CliRunner().invoke(cli, argv)
    assert result.exit_code == 2, result.output
    assert words in result.stderr and result.stderr.count("\n") == 1, result.stderr
    assert set(tmp_path.iterdir()) == before


def test_the_json_summary_counts_the_pairs(capsys, tmp_path):
    code, out, err = run(capsys, "recordings", "pairs", _ok_tracks(tmp_path), "--json")
    assert code == 0 and err == ""
    import json

    info = json.loads(out)
    assert (info["pairs"], info["crossing"], info["merge"]) == (1, 1, 0)
    assert info["first"]["1"] == 1 and info["angle_histogram"] == {"80-100": 1}
