"""The AV in a recorded driver's seat (``persuasive.recordings.replay``, ``recordings replay``)
and SUMO's floating-car data as a recording (``persuasive.recordings.sumo_fcd``, ``recordings
export FCD.xml``). Every fixture is written here, into ``tmp_path``: our own runs simulated and
exported, hand-made straight tracks, a tiny fcd file, and one short SUMO run.

Tolerances: straight noise-free tracks at constant speed are kept exactly by the
Savitzky-Golay filter (accelerations within 1e-9 of 0); the replay reproduces the recorded
speeds to 1e-9 m/s; fcd centres are exact up to the 3 decimals the writer keeps (1e-3 m).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from _cli import run_cli
from persuasive import Config, simulate
from persuasive.recordings.export import export_runs
from persuasive.recordings.formats import RecordingError, read_tracks
from persuasive.recordings.pairs import find_pairs, pairs_frame, write_pairs
from persuasive.recordings.replay import (ReplaySettings, envelope_excess,
                                          replay_accelerations, replay_pairs, run_seat)
from persuasive.recordings.tracks import smooth_tracks

from test_recordings import straight, write


def pairs_of(folder):
    return find_pairs(smooth_tracks(read_tracks([str(folder)])))


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """Three runs at a 90-degree crossing whose vehicles keep inside [-1.6, 0.8] m/s^2,
    exported without noise (their smoothed accelerations stay inside the replay's [-2, 1]),
    and their pairs file."""
    folder = tmp_path_factory.mktemp("simulated")
    config = Config(mode="corrected").with_overrides({
        "scenario.kind": "crossing", "simulation.n_steps": 100, "vehicle.u_max_mps2": 0.8,
        "vehicle.u_min_mps2": -1.6})
    runs = []
    for seed in (1, 2, 3):
        path = folder / f"run{seed}.parquet"
        simulate(config, seed).save(path)
        runs.append(str(path))
    tracks = folder / "tracks"
    tracks.mkdir()
    export_runs(runs, tracks, 0.0, 0)
    result = pairs_of(tracks)
    pairs = folder / "pairs.parquet"
    write_pairs(pairs, result, [str(tracks)])
    return pairs_frame(result.pairs), str(pairs)


@pytest.fixture(scope="module")
def hand_made(tmp_path_factory):
    """A right-angle crossing at constant speeds: vehicle 1 east at 8 m/s reaches the
    conflict point at 5.0 s, vehicle 2 north at 8 m/s at 5.5 s; neither reacts."""
    folder = tmp_path_factory.mktemp("hand")
    write(folder / "vehicle_tracks_000.csv", straight(1, (-40.0, 0.0), 0.0, [8.0] * 100),
          straight(2, (0.0, -44.0), 90.0, [8.0] * 100))
    return pairs_frame(pairs_of(folder).pairs)


def test_the_replay_reproduces_the_recorded_speeds():
    v = np.array([5.0, 5.3, 5.1, 4.0, 4.0])
    a = replay_accelerations(v, 0.1)
    np.testing.assert_allclose(a, [3.0, -2.0, -11.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(v[0] + np.cumsum(a) * 0.1, v[1:], atol=1e-9)


def test_within_the_envelope_the_worst_case_shield_has_no_av_caused_collision(simulated):
    frame, _ = simulated
    result = replay_pairs(frame, ReplaySettings())
    assert len(result.runs) == 2 * frame["pair"].nunique() == 6
    for r in result.runs:
        # the 100 replayed steps less the 6 that read a track's first or last 3 samples
        # (the filter's edge windows: extrapolations)
        assert r.within_envelope and r.excess_steps == 0 and r.envelope_steps == 94
        assert r.start_certified and r.uncertified_steps == 0 and r.guarantee_held
        assert not r.collision_caused_by_av
        assert r.steps == 100 + 100  # the recorded steps (101 states) and 10 s more
    info = result.summary()
    assert info["within_envelope_certified_start"] == {"runs": 6, "collisions": 0,
                                                       "av_caused": 0, "rear_end_by_human": 0}
    assert info["envelope"]["excess_steps"] == 0 and info["envelope"]["excess_share"] == 0.0
    # the recorded first passer: vehicle 1 (the simulated AV) in every run of these seeds
    assert {r.first_recorded for r in result.runs if r.seat == 1} == {"replaced"}
    assert sum(info["first_recorded"].values()) == info["valid"]


def test_the_replay_is_deterministic(simulated):
    frame, _ = simulated
    one = replay_pairs(frame, ReplaySettings(seats=(2,))).frame()
    two = replay_pairs(frame, ReplaySettings(seats=(2,))).frame()
    pd.testing.assert_frame_equal(one, two)


def test_a_non_reactive_driver_defeats_the_unshielded_planner_but_not_the_shield(hand_made):
    # the AV in vehicle 2's seat (second in the recording) meets vehicle 1 at constant speed
    off = replay_pairs(hand_made, ReplaySettings(shield="off", seats=(2,))).runs[0]
    assert off.within_envelope and off.valid  # the replayed driver went first: no reaction
    assert off.collision and off.collision_caused_by_av and off.first_replay == "AV"
    shielded = replay_pairs(hand_made, ReplaySettings(seats=(2,))).runs[0]
    assert shielded.within_envelope and shielded.start_certified and shielded.valid
    assert not shielded.collision and shielded.guarantee_held
    assert shielded.first_replay == "other" and shielded.min_gap_m > 0.0
    # its time to clear beside the recorded driver's own, on the same scenario path
    assert shielded.recorded_clear_s == pytest.approx(6.4, abs=1e-9)
    assert shielded.av_clear_s > shielded.recorded_clear_s


def test_the_invalidation_rule_and_the_times_on_valid_runs(hand_made):
    # the AV in vehicle 1's seat: in the recording the replayed vehicle 2 passed after it;
    # a yielding AV does not pass first, so the run is invalid
    result = replay_pairs(hand_made, ReplaySettings(av="yield"))
    by_seat = {r.seat: r for r in result.runs}
    assert by_seat[1].first_recorded == "replaced" and by_seat[1].first_replay == "other"
    assert not by_seat[1].valid and by_seat[1].invalid_reason == "yielded"
    assert by_seat[2].valid and by_seat[2].invalid_reason == ""
    info = result.summary()
    assert info["invalid"] == {"yielded": 1} and info["valid"] == 1
    assert info["av_clear_s_rmean"] == pytest.approx(by_seat[2].av_clear_s)
    assert info["recorded_clear_s_rmean"] == pytest.approx(by_seat[2].recorded_clear_s)


def test_a_driver_beyond_the_envelope_is_reported(tmp_path):
    # vehicle 2 brakes from 9 to 3 m/s in 1.5 s (-4 m/s^2, beyond u_min = -2), then crosses
    brake = np.concatenate([np.full(20, 9.0), np.linspace(9.0, 3.0, 16), np.full(150, 3.0)])
    write(tmp_path / "vehicle_tracks_000.csv", straight(1, (-50.0, 0.0), 0.0, [9.0] * 186),
          straight(2, (0.0, -60.0), 90.0, brake))
    frame = pairs_frame(pairs_of(tmp_path).pairs)
    run = replay_pairs(frame, ReplaySettings(seats=(1,))).runs[0]
    assert not run.within_envelope and run.excess_steps > 5
    assert run.accel_min_mps2 < -3.0 and run.u_min_mps2 == -2.0
    info = replay_pairs(frame, ReplaySettings(seats=(1,))).summary()
    assert info["beyond_envelope"]["runs"] == 1 and info["envelope"]["runs_beyond"] == 1
    assert info["envelope"]["excess_steps"] == run.excess_steps
    assert info["within_envelope_certified_start"]["runs"] == 0


def test_the_envelope_test_leaves_out_the_filters_edge_samples():
    """A pair's steps that read one of the track's first or last samples the edge windows
    reach (3 for the files' speeds, 6 for speeds from the positions, with the default window
    of 7 samples; 5 and 10 with 11) are not tested; a pairs file that does not say where its
    steps lie tests every step."""
    import pandas as pd

    from persuasive.recordings.replay import edge_steps
    from persuasive.recordings.tracks import SmoothingParams, edge_samples

    assert edge_samples() == 3 and edge_samples(SmoothingParams(speed="positions")) == 6
    assert edge_samples(SmoothingParams(window=11, speed="positions")) == 10
    rows = pd.DataFrame({"track_k0_2": [3] * 21, "track_n_2": [27] * 21})
    edge = edge_steps(rows, 2, 5)  # step k reads samples 3 + k, 4 + k; 22..26 are the end
    assert edge.tolist() == [True, True] + [False] * 16 + [True, True]
    assert not edge_steps(rows.drop(columns=["track_k0_2", "track_n_2"]), 2, 5).any()


def test_the_envelope_test_by_hand():
    from persuasive.config import VehicleParams

    veh = VehicleParams()  # u in [-2, 1], v in [0, 10]
    a = np.array([1.0, 1.0 + 1e-6, -2.0, -2.5, 0.0])
    v = np.array([5.0, 5.0, 5.0, 5.0, 5.0, 10.5])
    assert envelope_excess(a, v, veh).tolist() == [False, True, False, True, True]


def test_the_fitted_other_is_fitted_on_the_other_recordings(simulated):
    frame, _ = simulated
    result = replay_pairs(frame, ReplaySettings(other="fitted", seats=(1,)))
    assert sorted(result.fits) == sorted(frame["recording"].unique())
    for params in result.fits.values():
        assert params["fitted_runs"] == 4  # both views of the two other recordings' pairs
        assert 0.0 <= params["p_a"] <= 1.0 and params["role"] in ("leader", "follower")
    for r in result.runs:
        assert r.fitted == result.fits[r.recording] and r.valid
        assert not r.collision_caused_by_av
    one = frame[frame["recording"] == frame["recording"].iloc[0]]
    with pytest.raises(RecordingError, match="at least two recordings"):
        replay_pairs(one, ReplaySettings(other="fitted"))


def test_a_seat_run_starts_at_the_recorded_states(simulated):
    frame, _ = simulated
    rows = frame[frame["pair"] == 0].sort_values("step")
    run = run_seat(rows, 2, ReplaySettings(shield="off"), Config(mode="corrected"))
    assert run.seat == 2 and run.recorded_steps == len(rows)
    with pytest.raises(RecordingError, match="--other = 'nobody'"):
        ReplaySettings(other="nobody")
    with pytest.raises(RecordingError, match="--extra-s"):
        ReplaySettings(extra_s=-1.0)




def test_replay_command_prints_and_writes(capsys, simulated, tmp_path):
    _, pairs = simulated
    out = tmp_path / "runs.csv"
    code, text, err = run_cli(capsys, "recordings", "replay", pairs, "--seat", "1", "--out",
                              str(out), "--quiet")
    assert code == 0 and err == "", err
    assert "3 runs of 3 pairs: AV persuasive with shield worst-case" in text
    assert "collisions: 0 of 3 runs (AV-caused 0" in text
    assert "driver within the envelope, start certified: 3 runs, 0 collisions" in text
    assert "invalid runs: 0; rule:" in text and "time to clear" in text
    table = pd.read_csv(out)
    assert len(table) == 3 and set(table["seat"]) == {1}


@pytest.mark.parametrize("args, words", [
    (["--other", "nobody"], "--other = 'nobody' is not allowed"),
    (["--model", "idm"], "--model idm is read with --other fitted only"),
    (["--shield", "thick"], "--shield = 'thick' is not allowed"),
    (["--extra-s", "-3"], "--extra-s = -3.0 is out of range"),
    (["--pet-max", "0"], "--pet-max = 0.0 is out of range; allowed: (0, inf] s"),
    (["--pet-max", "-1"], "--pet-max = -1.0 is out of range; allowed: (0, inf] s"),
    (["--pet-max", "nan"], "--pet-max = nan is out of range; allowed: (0, inf] s"),
    (["--out", "runs.txt"], "runs.txt"),
])
def test_bad_replay_input_is_one_line_and_exit_2(capsys, simulated, tmp_path, args, words):
    _, pairs = simulated
    args = [str(tmp_path / a) if a.endswith(".txt") else a for a in args]
    code, out, err = run_cli(capsys, "recordings", "replay", pairs, *args)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0], err
    assert list(tmp_path.iterdir()) == []


def test_the_pairs_that_interact_are_replayed_and_the_rest_counted(capsys, simulated):
    """The command replays the pairs whose PET at the conflict area is at most ``--pet-max``
    (4 s by default) or unknown, and says how many it left out and why; ``inf`` replays
    every pair; the library replays a frame whole unless told."""
    from persuasive.recordings.replay import DEFAULT_PET_AREA_MAX_S, select_pairs

    frame, _ = simulated
    pet = frame.groupby("pair")["pet_area_s"].first()
    assert len(pet) == 3 and (pet < DEFAULT_PET_AREA_MAX_S).all()  # three crossings, ~1.4 s
    # by hand: PETs 1, 4 (kept: "at most"), 4.01 and 7 (left out), unknown (kept)
    rows = pd.DataFrame({"pair": [0, 0, 1, 2, 3, 4, 4],
                         "pet_area_s": [1.0, 1.0, 4.0, 4.01, 7.0, np.nan, np.nan]})
    rows.attrs = {"smoothing": None}
    kept, info = select_pairs(rows, 4.0)
    assert sorted(kept["pair"].unique()) == [0, 1, 4] and kept.attrs == rows.attrs
    assert info == {"pet_area_max_s": 4.0, "pairs": 5, "replayed": 3,
                    "left_out": {"pet_area_s > 4 s": 2}, "unknown_pet": 1}
    whole, info = select_pairs(rows, math.inf)
    assert whole is rows and info["replayed"] == 5 and info["pet_area_max_s"] is None
    assert select_pairs(rows.drop(columns="pet_area_s"), 4.0)[1]["unknown_pet"] == 5
    # through the command: a bound below every pair's PET leaves them all out
    code, text, err = run_cli(capsys, "recordings", "replay", simulated[1], "--seat", "1",
                              "--pet-max", "1", "--quiet")
    assert code == 0, err
    assert "pairs replayed: 0 of 3 (PET at the conflict area at most 1 s, or unknown; 0 " \
           "without a PET at the area); left out: 3, 3 with pet_area_s > 1 s (no " \
           "interaction); --pet-max inf replays every pair" in text
    assert "0 runs of 0 pairs" in text
    code, text, _ = run_cli(capsys, "recordings", "replay", "--help")
    assert "--pet-max" in text and "[default: 4.0]" in text
    assert DEFAULT_PET_AREA_MAX_S == 4.0


def test_replay_of_a_file_that_is_not_a_pairs_file(capsys, tmp_path):
    bad = tmp_path / "notes.parquet"
    bad.write_text("hello")
    code, out, err = run_cli(capsys, "recordings", "replay", str(bad))
    assert code == 2 and "is not a Parquet file" in err and len(err.strip().splitlines()) == 1


# -- SUMO's floating-car data -------------------------------------------------------------------

FCD = """<?xml version="1.0" encoding="UTF-8"?>
<fcd-export>
{steps}
</fcd-export>
"""


def fcd_file(path, steps: list[tuple[float, list[str]]]) -> str:
    body = "\n".join(f'  <timestep time="{t:.2f}">\n' + "\n".join(f"    {v}" for v in vs)
                     + "\n  </timestep>" for t, vs in steps)
    path.write_text(FCD.format(steps=body))
    return str(path)


def test_fcd_is_read_at_100_ms_frames_with_the_centre_behind_the_front(tmp_path):
    from persuasive.recordings.export import export_fcd

    types = tmp_path / "types.rou.xml"
    types.write_text('<routes><vType id="lorry" vClass="truck"/>'
                     '<vType id="small" length="4.0" width="1.7"/></routes>')
    steps = []
    for k in range(6):  # 0.05 s steps: frames at 0.0, 0.1, 0.2
        t = 0.05 * k
        steps.append((t, [f'<vehicle id="east" x="{10.0 * t:.3f}" y="0.0" angle="90.00" '
                          f'type="small" speed="10.0"/>',
                          f'<vehicle id="north" x="0.0" y="{-20.0 + 5.0 * t:.3f}" '
                          f'angle="0.00" type="lorry" speed="5.0"/>',
                          '<person id="p" x="1" y="1" angle="0" speed="1"/>']))
    fcd = fcd_file(tmp_path / "fcd.xml", steps)
    out = tmp_path / "out"
    out.mkdir()
    names = export_fcd([fcd], out, 0.0, 0, [types])
    assert names == ["vehicle_tracks_000.csv"]
    table = pd.read_csv(out / names[0])
    east = table[table["track_id"] == 1]
    assert list(east["frame_id"]) == [1, 2, 3] and list(east["timestamp_ms"]) == [0, 100, 200]
    # the centre is half the length (4 m / 2) behind the front, heading east (psi = 0)
    np.testing.assert_allclose(east["x"], [-2.0, -1.0, 0.0], atol=1e-3)
    np.testing.assert_allclose(east[["psi_rad", "vy"]].to_numpy(), 0.0, atol=1e-3)
    assert east["vx"].iloc[0] == pytest.approx(10.0) and east["length"].iloc[0] == 4.0
    north = table[table["track_id"] == 2]  # a truck: SUMO's default 7.1 x 2.4, heading north
    assert north["agent_type"].iloc[0] == "truck" and north["width"].iloc[0] == 2.4
    np.testing.assert_allclose(north["y"], [-23.55, -23.05, -22.55], atol=1e-3)
    assert north["psi_rad"].iloc[0] == pytest.approx(math.pi / 2, abs=1e-3)
    ids = pd.read_csv(out / "vehicle_ids_000.csv")
    assert list(ids["sumo_id"]) == ["east", "north"]
    # noise: uniform within the stated half-width
    noisy = tmp_path / "noisy"
    noisy.mkdir()
    export_fcd([fcd], noisy, 0.05, 1, [types])
    diff = pd.read_csv(noisy / names[0])["x"] - table["x"]
    assert 0.0 < diff.abs().max() <= 0.0505


def test_bad_fcd_files_are_one_line_and_exit_2(capsys, tmp_path):
    cases = {
        "unknown.xml": ([(0.0, ['<vehicle id="a" x="0" y="0" angle="0" type="odd" '
                                'speed="1"/>'])], "vehicle 'a' is of type 'odd'"),
        "gap.xml": ([(0.0, ['<vehicle id="a" x="0" y="0" angle="0" speed="1"/>']),
                     (0.2, ['<vehicle id="a" x="0" y="0.2" angle="0" speed="1"/>'])],
                    "frame step: vehicle 'a' goes from t = 0 s to 0.2 s"),
        "nan.xml": ([(0.0, ['<vehicle id="a" x="nan" y="0" angle="0" speed="1"/>'])],
                    "non-finite: vehicle 'a' at time 0.00 has x = 'nan'"),
    }
    for name, (steps, words) in cases.items():
        fcd = fcd_file(tmp_path / name, steps)
        out = tmp_path / f"out-{name}"
        code, text, err = run_cli(capsys, "recordings", "export", fcd, "--out", str(out))
        assert code == 2 and text == "" and len(err.strip().splitlines()) == 1, err
        assert words in err and not out.exists()
    (tmp_path / "routes.xml").write_text("<routes/>")
    code, _, err = run_cli(capsys, "recordings", "export", str(tmp_path / "routes.xml"),
                           "--out", str(tmp_path / "o"))
    assert code == 2 and "is not an fcd file: its root element is <routes>" in err
    code, _, err = run_cli(capsys, "recordings", "export", str(tmp_path / "gap.xml"),
                           "run.parquet", "--out", str(tmp_path / "o"))
    assert code == 2 and "not both in one export" in err


def test_a_sumo_run_round_trips_into_pairs(capsys, tmp_path):
    from persuasive.envs.sumo import NETWORKS, build_network, spawn_tied, sumo_binaries

    build_network(NETWORKS["intersection"], tmp_path)
    (tmp_path / "routes.rou.xml").write_text(
        '<routes><vType id="car" length="4.5" width="1.8"/>'
        '<route id="we" edges="W2C C2E"/><route id="sn" edges="S2C C2N"/>'
        '<vehicle id="we0" type="car" route="we" depart="0" departSpeed="desired"/>'
        '<vehicle id="sn0" type="car" route="sn" depart="1" departSpeed="desired"/>'
        '</routes>')
    sumo = f"{sumo_binaries()['home']}/bin/sumo"
    proc = spawn_tied([sumo, "--net-file", str(tmp_path / "net.net.xml"), "--route-files",
                       str(tmp_path / "routes.rou.xml"), "--fcd-output",
                       str(tmp_path / "fcd.xml"), "--step-length", "0.1", "--end", "40",
                       "--no-step-log", "true", "--seed", "1"])
    assert proc.wait(timeout=60) == 0
    tracks = tmp_path / "tracks"
    code, out, err = run_cli(capsys, "recordings", "export", str(tmp_path / "fcd.xml"),
                             "--types", str(tmp_path / "routes.rou.xml"), "--out", str(tracks),
                             "--noise-m", "0.05")
    assert code == 0 and "1 track file (INTERACTION format, from SUMO fcd, noise" in out, err
    result = pairs_of(tracks)
    assert len(result.pairs) == 1
    p = result.pairs[0]
    assert p.kind == "crossing" and p.angle_deg == pytest.approx(90.0, abs=1.0)
    # the conflict point is the junction's centre, where the two centre lines cross
    assert np.hypot(*p.conflict_xy) < 2.5
    assert p.lengths_m == (4.5, 4.5)


def test_replay_on_worker_processes_is_the_same_bit_for_bit(capsys, simulated, tmp_path):
    """The pairs on two worker processes give the same runs as one process, in pair order;
    the command shows a progress bar over the pairs unless --quiet."""
    frame, pairs = simulated
    seen = []
    one = replay_pairs(frame, ReplaySettings()).frame()
    two = replay_pairs(frame, ReplaySettings(), workers=2,
                       progress=lambda done, total: seen.append((done, total))).frame()
    pd.testing.assert_frame_equal(one, two)
    assert seen == [(1, 3), (2, 3), (3, 3)]
    code, _, err = run_cli(capsys, "recordings", "replay", pairs, "--workers", 2)
    assert code == 0 and "3/3" in err and "pair" in err, err


def test_the_real_driver_envelope_is_what_the_shield_and_the_premise_read(tmp_path, capsys):
    """``--envelope real-driver`` (``hv.envelope``): the driver who brakes at -4 m/s^2 is
    beyond the paper's envelope and beyond real drivers' -3.7 only while it brakes; the
    human's limits the run and the premise read are the named envelope's."""
    brake = np.concatenate([np.full(20, 9.0), np.linspace(9.0, 3.0, 16), np.full(150, 3.0)])
    write(tmp_path / "vehicle_tracks_000.csv", straight(1, (-50.0, 0.0), 0.0, [9.0] * 186),
          straight(2, (0.0, -60.0), 90.0, brake))
    frame = pairs_frame(pairs_of(tmp_path).pairs)
    paper = replay_pairs(frame, ReplaySettings(seats=(1,))).runs[0]
    real = replay_pairs(frame, ReplaySettings(seats=(1,), envelope="real-driver")).runs[0]
    assert (paper.u_min_mps2, paper.u_max_mps2) == (-2.0, 1.0)
    assert (real.u_min_mps2, real.u_max_mps2) == (-3.7, 3.5)
    assert 0 < real.excess_steps < paper.excess_steps  # only the hardest braking is beyond
    # the same, through the command line; a name that is not an envelope is one line, exit 2
    pairs = tmp_path / "pairs.parquet"
    write_pairs(pairs, pairs_of(tmp_path), [str(tmp_path)])
    # --pet-max inf: vehicle 2 reaches the area seconds after vehicle 1 has left it
    code, text, err = run_cli(capsys, "recordings", "replay", pairs, "--seat", "1",
                              "--envelope", "real-driver", "--json", "--quiet",
                              "--pet-max", "inf")
    assert code == 0, err
    import json

    info = json.loads(text)
    assert info["human_envelope"] == "real-driver"
    assert info["envelope"]["excess_steps"] == real.excess_steps
    code, text, err = run_cli(capsys, "recordings", "replay", pairs, "--envelope", "moon")
    assert code == 2 and "--envelope = 'moon' is not allowed" in err
    assert len(err.strip().splitlines()) == 1
