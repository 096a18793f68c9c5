"""Real drivers from recordings (``persuasive.recordings``): the readers of both formats, the
pair labels on hand-made straight-line tracks, and the round trip simulate -> export -> read
-> pairs -> logs -> fit. Every fixture is written here, into ``tmp_path``.

Tolerances: positions and times of noise-free straight tracks at constant speed are exact up
to float rounding (the Savitzky-Golay filter keeps cubics), 1e-6; route_conflict samples its
lines every 0.25 m, so its occupancy intervals are checked to 0.3 m and a PET computed by hand
from the pair's own intervals to 1e-6 s.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from persuasive.recordings.formats import RecordingError, read_ind, read_interaction, read_tracks
from persuasive.recordings.pairs import PairParams, find_pairs, read_pairs, write_pairs
from persuasive.recordings.tracks import savgol, smooth_tracks

HEADER = ["track_id", "frame_id", "timestamp_ms", "agent_type", "x", "y", "vx", "vy",
          "psi_rad", "length", "width"]


def straight(track: int, start_xy, angle_deg: float, speeds, t0_ms: int = 0,
             length: float = 4.5, width: float = 1.8, agent: str = "car") -> pd.DataFrame:
    """A track along a straight line from ``start_xy`` at ``angle_deg``, one speed per 100 ms
    frame (the position integrates them: ``x_k = x_0 + sum_{j<k} v_j dt``)."""
    speeds = np.asarray(speeds, float)
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    dist = np.concatenate([[0.0], np.cumsum(speeds[:-1] * 0.1)])
    n = speeds.shape[0]
    return pd.DataFrame({"track_id": track, "frame_id": np.arange(1, n + 1),
                         "timestamp_ms": t0_ms + 100 * np.arange(n), "agent_type": agent,
                         "x": start_xy[0] + c * dist, "y": start_xy[1] + s * dist,
                         "vx": c * speeds, "vy": s * speeds,
                         "psi_rad": math.radians(angle_deg), "length": length,
                         "width": width})


def write(path, *tracks: pd.DataFrame) -> str:
    pd.concat(tracks, ignore_index=True)[HEADER].to_csv(path, index=False,
                                                          float_format="%.9f")
    return str(path)


def pairs_of(*paths, **params):
    return find_pairs(smooth_tracks(read_tracks(list(paths))), PairParams(**params))


# -- the readers -----------------------------------------------------------------------------


def test_interaction_reader_gives_the_tidy_table(tmp_path):
    path = write(tmp_path / "vehicle_tracks_007.csv",
                 straight(2, (0.0, 0.0), 90.0, [5.0] * 30, t0_ms=1000),
                 straight(1, (-10.0, 3.0), 0.0, [4.0] * 25, agent="truck"))
    table = read_interaction(path)
    assert list(table.columns) == ["recording", "track", "t_s", "x_m", "y_m", "speed_mps",
                                   "heading_rad", "length_m", "width_m", "agent_class"]
    assert len(table) == 55 and set(table["recording"]) == {"vehicle_tracks_007"}
    one = table[table["track"] == 1]  # sorted by track, then time
    assert list(table["track"].iloc[:25]) == [1] * 25 and one["agent_class"].iloc[0] == "truck"
    np.testing.assert_allclose(one["t_s"], np.arange(25) * 0.1, atol=1e-12)
    np.testing.assert_allclose(one["x_m"], -10.0 + 0.4 * np.arange(25), atol=1e-6)
    two = table[table["track"] == 2]
    assert two["t_s"].iloc[0] == pytest.approx(1.0)
    np.testing.assert_allclose(two["speed_mps"], 5.0)
    np.testing.assert_allclose(two["heading_rad"], math.pi / 2)


def test_prediction_split_tracks_are_case_and_track(tmp_path):
    a = straight(1, (0.0, 0.0), 0.0, [5.0] * 20)
    b = straight(2, (0.0, 5.0), 0.0, [5.0] * 20)
    frames = []
    for case in (3, 4):  # the same track IDs in two cases: four tracks
        for t in (a, b):
            frames.append(t.assign(case_id=float(case)))
    path = tmp_path / "DR_X_val.csv"
    pd.concat(frames)[["case_id", *HEADER]].to_csv(path, index=False)
    table = read_interaction(path)
    assert sorted(set(zip(table["recording"], table["track"]))) == [
        ("DR_X_val/case3", 1), ("DR_X_val/case3", 2), ("DR_X_val/case4", 1),
        ("DR_X_val/case4", 2)]


def _ind_files(folder, tracks: dict[int, tuple[np.ndarray, np.ndarray]], first_frame=None,
               classes=None):
    """inD NN_tracks.csv / NN_tracksMeta.csv with each track's (x, y) per 40 ms frame."""
    rows, meta = [], []
    for tid, (x, y) in tracks.items():
        n = x.shape[0]
        f0 = (first_frame or {}).get(tid, 0)
        rows.append(pd.DataFrame({
            "recordingId": 7, "trackId": tid, "frame": f0 + np.arange(n),
            "trackLifetime": np.arange(n), "xCenter": x, "yCenter": y, "heading": 30.0,
            "width": 1.9, "length": 4.6, "xVelocity": 3.0, "yVelocity": 4.0,
            "xAcceleration": 0.0, "yAcceleration": 0.0, "lonVelocity": 5.0,
            "latVelocity": 0.0, "lonAcceleration": 0.0, "latAcceleration": 0.0}))
        meta.append({"recordingId": 7, "trackId": tid, "initialFrame": f0,
                     "finalFrame": f0 + n - 1, "numFrames": n, "width": 1.9, "length": 4.6,
                     "class": (classes or {}).get(tid, "car")})
    pd.concat(rows).to_csv(folder / "07_tracks.csv", index=False)
    pd.DataFrame(meta).to_csv(folder / "07_tracksMeta.csv", index=False)
    return folder / "07_tracks.csv"


def test_ind_is_averaged_over_three_frames_then_taken_at_multiples_of_100_ms(tmp_path):
    spike = np.zeros(100)
    spike[50] = 3.0  # frame 50 is t = 2.0 s
    line = 0.2 * np.arange(100)  # 5 m/s at 25 Hz
    path = _ind_files(tmp_path, {1: (spike, line), 2: (line, spike)}, first_frame={2: 3},
                      classes={2: "truck_bus"})
    table = read_ind(path)
    one = table[table["track"] == 1].reset_index(drop=True)
    # frames 0..99 cover 0..3.96 s: 10 Hz times 0.0 .. 3.9 s
    np.testing.assert_allclose(one["t_s"], np.arange(40) * 0.1, atol=1e-12)
    at = dict(zip(np.round(one["t_s"], 1), one["x_m"]))
    assert at[2.0] == pytest.approx(1.0)  # the spike averaged over 3 frames, on its frame
    assert at[1.9] == pytest.approx(0.0) and at[2.1] == pytest.approx(0.0)  # 1.5 frames off
    # a straight line stays on it in the interior (frames 47.5, 52.5: interpolated halfway)
    inner = one[(one["t_s"] > 0.1) & (one["t_s"] < 3.8)]
    np.testing.assert_allclose(inner["y_m"], 0.2 * inner["t_s"] / 0.04, atol=1e-9)
    assert one["heading_rad"].iloc[0] == pytest.approx(math.radians(30.0))
    assert one["speed_mps"].iloc[0] == pytest.approx(5.0)
    two = table[table["track"] == 2]
    # frames 3..102 are 0.12 .. 4.08 s: 10 Hz times 0.2 .. 4.0 s
    assert two["t_s"].iloc[0] == pytest.approx(0.2) and two["t_s"].iloc[-1] == pytest.approx(4.0)
    assert set(two["agent_class"]) == {"truck_bus"}


def test_savgol_of_every_track_at_once_is_scipys():
    from scipy.signal import savgol_filter

    rng = np.random.default_rng(3)
    x = rng.normal(size=50)
    starts = np.array([0, 23, 50])
    for deriv in (0, 1, 2):
        ours = savgol(x, starts, 11, 3, deriv, 0.1)
        ref = np.concatenate([savgol_filter(x[a:b], 11, 3, deriv=deriv, delta=0.1,
                                            mode="interp") for a, b in ((0, 23), (23, 50))])
        np.testing.assert_allclose(ours, ref, atol=1e-9)


# -- pairs and their labels, by hand ---------------------------------------------------------


def test_a_right_angle_crossing_by_hand(tmp_path):
    # vehicle 1 east at 10 m/s from x = -50: at the origin at t = 5.0 s; vehicle 2 north at
    # 8 m/s from y = -60: at the origin at 7.5 s
    path = write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (-50.0, 0.0), 0.0, [10.0] * 100),
                 straight(2, (0.0, -60.0), 90.0, [8.0] * 120))
    result = pairs_of(path)
    assert len(result.pairs) == 1
    p = result.pairs[0]
    assert (p.kind, p.tracks, p.first) == ("crossing", (1, 2), "1")
    assert p.angle_deg == pytest.approx(90.0, abs=1e-6)
    # the conflict point is the lines' exact crossing (route_conflict's samples are 0.25 m
    # apart: its own closest pair of samples would be up to 0.125 m off on each line)
    assert p.conflict_xy == pytest.approx((0.0, 0.0), abs=1e-6)
    assert p.t_pass_s == pytest.approx((5.0, 7.5), abs=0.02)
    # route_conflict: footprints touch within W = (1.8 + 1.8) / 2 + 0.5 of the other line,
    # widened by l / 2 + step / 2 + 0.05
    half = 1.8 + 0.5 + 2.25 + 0.125 + 0.05
    for lo, hi in p.occupancy:
        assert lo == pytest.approx(-half, abs=0.3) and hi == pytest.approx(half, abs=0.3)
    # PET: vehicle 1 leaves its interval at 5 + hi_1 / 10, vehicle 2 enters at 7.5 + lo_2 / 8
    pet = (p.t_pass_s[1] + p.occupancy[1][0] / 8.0) - (p.t_pass_s[0] + p.occupancy[0][1] / 10.0)
    assert p.pet_s == pytest.approx(pet, abs=1e-6) and 1.3 < p.pet_s < 1.5  # 2.5 - 0.61 - 0.49
    assert p.second_slowed is False and p.second_speed_drop_mps == pytest.approx(0.0, abs=1e-6)
    # steps: both present from 0 to 9.9 s, where they lie in the tracks; s relative to the
    # exact conflict point, exact speeds (the files' own)
    assert p.n_steps == 100 and p.t[0] == 0.0 and p.t[-1] == 9.9
    assert p.track_k0 == (0, 0) and p.track_n == (100, 120)
    np.testing.assert_allclose(p.s[0], 10.0 * p.t - 50.0, atol=1e-6)
    np.testing.assert_allclose(p.s[1], 8.0 * p.t - 60.0, atol=1e-6)
    np.testing.assert_allclose(p.v, np.array([[10.0], [8.0]]) * np.ones((2, 100)), atol=1e-6)
    np.testing.assert_allclose(p.a, 0.0, atol=1e-6)


def test_the_second_vehicle_passes_first_brakes_and_the_angle_is_read(tmp_path):
    # vehicle 2 crosses 60 degrees off vehicle 1's heading and passes first; vehicle 1 brakes
    # from 10 to 6 m/s on its way (a drop of 4 m/s) and passes later
    brake = np.concatenate([np.full(20, 10.0), np.linspace(10.0, 6.0, 21), np.full(80, 6.0)])
    c, s = math.cos(math.radians(60.0)), math.sin(math.radians(60.0))
    path = write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (-45.0, 0.0), 0.0, brake),
                 straight(2, (-30.0 * c, -30.0 * s), 60.0, [10.0] * 80))
    p = pairs_of(path).pairs[0]
    assert p.kind == "crossing" and p.first == "2"
    assert p.angle_deg == pytest.approx(60.0, abs=0.01)
    assert p.t_pass_s[1] == pytest.approx(3.0, abs=0.02)
    assert p.second_slowed is True and p.second_speed_drop_mps == pytest.approx(4.0, abs=0.1)
    # PET measured from the first to enter (vehicle 2) leaving to vehicle 1 entering
    t1, s1 = p.t, p.s[0]
    enter_1 = np.interp(p.occupancy[0][0], s1, t1)
    leave_2 = p.t_pass_s[1] + p.occupancy[1][1] / 10.0
    assert p.pet_s == pytest.approx(enter_1 - leave_2, abs=0.01)
    # the angle range is a filter of crossings: 60 degrees is out of [70, 110]
    with pytest.raises(IndexError):
        pairs_of(path, angle_range_deg=(70.0, 110.0)).pairs[0]


def test_a_merge_and_pairs_that_are_none(tmp_path):
    # vehicle 7 on the lane (east, y = 0); track 3 comes up a ramp at 20 degrees from below,
    # reaching the lane at the origin, then drives on along it
    ramp_s = np.arange(0.0, 90.0, 0.9)  # 9 m/s
    c, s = math.cos(math.radians(20.0)), math.sin(math.radians(20.0))
    along = ramp_s - 50.0
    ramp = straight(3, (0.0, 0.0), 0.0, np.full(ramp_s.shape, 9.0))
    ramp["x"] = np.where(along < 0, along * c, along)
    ramp["y"] = np.where(along < 0, along * s, 0.0)
    lane = straight(7, (-70.0, 0.0), 0.0, [10.0] * 100)
    follower = straight(8, (-90.0, 0.0), 0.0, [10.0] * 130)  # 2 s behind 7: no pair of them
    far = straight(9, (-50.0, 40.0), 0.0, [10.0] * 100)  # a parallel road 40 m away: none
    path = write(tmp_path / "vehicle_tracks_000.csv", ramp, lane, follower, far)
    result = pairs_of(path)
    merges = [p for p in result.pairs if p.kind == "merge"]
    assert {p.tracks for p in result.pairs} == {(3, 7), (3, 8)}
    p = next(q for q in merges if q.tracks == (3, 7))  # the merging vehicle is vehicle 1
    assert p.angle_deg == pytest.approx(20.0, abs=1.0)
    assert p.occupancy[0][1] == 0.0  # the ramp's interval ends at the merge point
    # the merge point: where the ramp's centre comes within 1 m of the lane's centre line
    assert p.conflict_xy[1] == pytest.approx(-1.0, abs=0.35)
    # the lane vehicle is at the merge point (x = -2.75 m) at 6.725 s, the ramp at 5.2 s
    assert p.first == "1"


def test_every_approaching_pair_is_kept_whatever_its_pet(tmp_path):
    # the same crossing with vehicle 2 ten seconds later: a PET of about 9 s is still a pair,
    # as long as both are within near_m of the point at one time
    path = write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (-50.0, 0.0), 0.0, [10.0] * 200),
                 straight(2, (0.0, -60.0), 90.0, [4.0] * 160))
    p = pairs_of(path).pairs[0]
    assert p.pet_s > 5.0
    assert pairs_of(path, near_m=10.0).pairs == []  # never both within 10 m at one time


def test_the_pairs_file_holds_one_row_per_pair_and_step(tmp_path):
    path = write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (-50.0, 0.0), 0.0, [10.0] * 100),
                 straight(2, (0.0, -60.0), 90.0, [8.0] * 120))
    result = pairs_of(path)
    out = tmp_path / "pairs.parquet"
    write_pairs(out, result, [path])
    frame, meta = read_pairs(out)
    assert len(frame) == 100 and set(frame["pair"]) == {0}
    assert set(frame["track_n_1"]) == {100} and set(frame["track_n_2"]) == {120}
    assert meta["params"]["angle_range_deg"] == [20.0, 160.0] and meta["n_pairs"] == 1
    # the tracks' filter, which the fit's measurement model needs, travels with the pairs
    assert meta["smoothing"] == {"window": 7, "order": 3, "min_track_s": 2.0, "speed": "file"}
    assert frame.attrs["smoothing"] == meta["smoothing"]
    assert frame["first"].iloc[0] == "1" and bool(frame["second_slowed"].iloc[0]) is False
    np.testing.assert_allclose(frame["s_1_m"], result.pairs[0].s[0])


def test_one_vehicle_and_pedestrians_make_no_pair(tmp_path):
    path = write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (-50.0, 0.0), 0.0, [10.0] * 100),
                 straight(2, (0.0, -6.0), 90.0, [1.5] * 100, agent="pedestrian/bicycle"))
    with pytest.raises(RecordingError, match="one vehicle: it holds one vehicle only"):
        read_tracks([path])


# -- the measurement model: what a recorded acceleration is ----------------------------------


def exact_track(track: int, accel, v0: float = 8.0, x0: float = -60.0) -> pd.DataFrame:
    """A track east along y = 0 driving the accelerations ``accel`` (held over each 0.1 s
    frame) by the exact kinematics, its speed in ``vx``."""
    a = np.asarray(accel, float)
    v = v0 + np.concatenate([[0.0], np.cumsum(a) * 0.1])
    x = x0 + np.concatenate([[0.0], np.cumsum(v[:-1] * 0.1 + 0.5 * a * 0.01)])
    n = v.shape[0]
    return pd.DataFrame({"track_id": track, "frame_id": np.arange(1, n + 1),
                         "timestamp_ms": 100 * np.arange(n), "agent_type": "car", "x": x,
                         "y": 0.0, "vx": v, "vy": 0.0, "psi_rad": 0.0, "length": 4.5,
                         "width": 1.8})


@pytest.mark.parametrize("window", [7, 11])
@pytest.mark.parametrize("speed", ["file", "positions"])
@pytest.mark.parametrize("steps", [84, 30])
def test_the_acceleration_filter_is_what_the_pipeline_records(tmp_path, speed, steps, window):
    """A driver whose acceleration jumps (-2, +1, 0.3, ...) on a long and on a short track:
    at every sample, the track's ends included, its smoothed acceleration is the band applied
    to the true one, to rounding (a stretch of the track alike); away from the ends the band
    is the kernel, whose weights sum to 1; the recorded jump is spread over the window (the
    default window, 7 samples, and 11)."""
    from persuasive.recordings.tracks import (SmoothingParams, acceleration_band,
                                              acceleration_kernel)

    rng = np.random.default_rng(5)
    accel = np.repeat(rng.choice([-2.0, -0.5, 0.0, 0.3, 1.0], 12), 7)[:steps]
    other = straight(2, (0.0, -60.0), 90.0, [8.0] * 40)
    path = write(tmp_path / "vehicle_tracks_000.csv", exact_track(1, accel), other)
    params = SmoothingParams(window=window, speed=speed)
    tracks = smooth_tracks(read_tracks([path]), params)
    recorded = tracks.a[tracks.rows(0)]
    n = recorded.shape[0]
    truth = np.concatenate([accel, [0.0]])  # the last sample's acceleration is never driven

    def apply(first, count):
        offsets, w = acceleration_band(params, n, first, count)
        ks = first + np.arange(count)
        idx = ks[:, None] + offsets[None, :]
        return np.sum(w * truth[np.clip(idx, 0, n - 1)] * ((idx >= 0) & (idx < n)), axis=1)

    np.testing.assert_allclose(apply(0, n), recorded, atol=1e-6)
    np.testing.assert_allclose(apply(3, n - 7), recorded[3:n - 4], atol=1e-6)
    kernel = acceleration_kernel(params)
    assert sum(kernel.values()) == pytest.approx(1.0, abs=1e-9)
    if steps == 84:  # a long track has an interior, where the band is the kernel
        reach = max(abs(d) for d in kernel)
        ks = np.arange(2 * reach, n - 2 * reach)
        expected = np.array([sum(w * truth[k + d] for d, w in kernel.items()) for k in ks])
        np.testing.assert_allclose(recorded[ks], expected, atol=1e-6)
        assert np.max(np.abs(recorded[ks] - truth[ks])) > 0.5  # not the identity
        shifted = np.array([sum(w * truth[k + d + 1] for d, w in kernel.items()) for k in ks])
        assert np.max(np.abs(recorded[ks] - shifted)) > 0.1  # one step off is wrong
    # the interior kernel at the ends would be wrong: the edge windows extrapolate (the
    # first jump, at sample 7, is within the 11-sample edge windows' reach)
    interior = acceleration_band(params, 0, 0, n)
    idx = np.arange(n)[:, None] + interior[0][None, :]
    naive = np.sum(interior[1] * truth[np.clip(idx, 0, n - 1)], axis=1)
    if window == 11:
        assert np.max(np.abs(naive[:3] - recorded[:3])) > 0.05


def test_observe_through_filters_each_run_within_its_own_steps():
    from persuasive.fitting.evidence import observe_through

    arr = np.array([[1.0], [2.0], [4.0], [10.0], [20.0]])
    starts = np.array([0, 3, 5])
    offsets = np.array([-1, 0, 1])
    out = arr.copy()
    observe_through(out, starts, np.array([0]), offsets, np.tile([0.25, 0.5, 0.25], (3, 1)))
    # run 0's ends repeat its own first and last rows; run 1 is left as it was
    np.testing.assert_allclose(out[:, 0], [1.25, 2.25, 3.5, 10.0, 20.0])
    both = arr.copy()
    weights = np.array([[0.25, 0.5, 0.25]] * 3 + [[0.0, 1.0, 0.0], [0.5, 0.5, 0.0]])
    observe_through(both, starts, np.array([0, 1]), offsets, weights)
    np.testing.assert_allclose(both[3:, 0], [10.0, 15.0])  # a row's own weights


def test_a_recorded_log_is_fitted_through_its_filter_and_a_simulated_one_is_not():
    """``evidence_of``: the same steps, once with the tracks' filter in the log's metadata
    (``recording.smoothing``, as ``recordings logs`` writes it) and once without: the model's
    accelerations are the filter's view of the plain ones; the states, the beliefs and the
    recorded accelerations are the same."""
    from persuasive import Config, simulate
    from persuasive.fitting import evidence_of
    from persuasive.fitting.evidence import observe_through, run_log_of
    from persuasive.recordings.tracks import acceleration_band

    config = Config(mode="corrected").with_overrides({"scenario.kind": "crossing",
                                                      "simulation.n_steps": 60})
    plain = run_log_of(simulate(config, 4), "run")
    smoothing = {"window": 7, "order": 3, "min_track_s": 2.0, "speed": "file"}
    recorded = type(plain)(plain.source, plain.config, plain.seed, None, plain.states,
                           plain.accel, {"recording": {"smoothing": smoothing}})
    ev = evidence_of([plain, recorded])
    a, b = ev.starts[1], ev.starts[2]
    expected = ev.a_role[:a].copy()
    offsets, weights = acceleration_band(None, 0, 0, a)  # no track given: all interior
    observe_through(expected, np.array([0, a]), np.array([0]), offsets, weights)
    np.testing.assert_allclose(ev.a_role[a:b], expected, atol=1e-12)
    assert np.max(np.abs(ev.a_role[a:b] - ev.a_role[:a])) > 0.1
    np.testing.assert_array_equal(ev.belief[a:b], ev.belief[:a])
    np.testing.assert_array_equal(ev.accel[a:b], ev.accel[:a])
    with pytest.raises(Exception, match="recording.smoothing"):
        evidence_of([type(plain)(plain.source, plain.config, plain.seed, None, plain.states,
                                 plain.accel, {"recording": {"smoothing": {"window": 4}}})])


def test_the_speed_limit_of_a_view_is_the_recorded_one_not_the_next_whole_m_s(tmp_path):
    """A pair driven at 10.3 m/s: the view's limit is 10.3 m/s (the LFG's library eases its
    acceleration near its limit; rounded up to 11 it would predict full throttle where the
    driver was at its top speed)."""
    from persuasive import Config
    from persuasive.recordings.logs import view_log
    from persuasive.recordings.pairs import pairs_frame

    path = write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (-50.0, 0.0), 0.0, [10.3] * 100),
                 straight(2, (0.0, -60.0), 90.0, [8.0] * 120))
    frame = pairs_frame(pairs_of(path).pairs)
    config, _, meta = view_log(frame, 2, Config(mode="corrected"))
    assert config.vehicle_of("av").v_max_mps == pytest.approx(10.3, abs=1e-6)
    assert "smoothing" not in meta["recording"]  # none given: no measurement model
    _, _, meta = view_log(frame, 2, Config(mode="corrected"), smoothing={"window": 11})
    assert meta["recording"]["smoothing"] == {"window": 11}


def roundtrip_fixture(tmp_path, d: int, p_a: float, role: str, measurement: bool = True):
    """One fixture of ``benchmarks/recordings_roundtrip.py``: 20 runs of an ``lfg`` human,
    exported with 5 cm and 0.1 m/s of noise, read, paired, the human's views fitted."""
    from dataclasses import asdict

    from persuasive import Config, simulate
    from persuasive.fitting import evidence_of, fit_models
    from persuasive.fitting.evidence import RunLog
    from persuasive.recordings.export import export_runs
    from persuasive.recordings.logs import view_log
    from persuasive.recordings.pairs import pairs_frame
    from persuasive.recordings.tracks import SmoothingParams

    base = {"scenario.kind": "crossing", "simulation.n_steps": 120, "hv.kind": "lfg",
            "roles.p_a": p_a, "hv.role": role, "mpc.p_a_hat": 1.0, "av.shield": "off"}
    configs = [Config(mode="corrected").with_overrides({**base, "av.kind": av})
               for av in ("persuasive", "passive")]
    folder = tmp_path / f"fixture{d}"
    tracks = folder / "tracks"
    tracks.mkdir(parents=True)
    runs = []
    for j in range(20):
        runs.append(str(folder / f"run{j:02d}.parquet"))
        simulate(configs[j % 2], 1 + 20 * d + j).save(runs[-1])
    export_runs(runs, tracks, 0.05, d, 0.1)
    smoothing = SmoothingParams()
    result = find_pairs(smooth_tracks(read_tracks([str(tracks)]), smoothing))
    logs = []
    for pair_id, rows in pairs_frame(result.pairs).groupby("pair", sort=True):
        config, log, meta = view_log(rows.sort_values("step"), 2, Config(mode="corrected"),
                                     smoothing=asdict(smoothing) if measurement else None)
        states = log[["av_meas_s_m", "av_meas_v_mps", "hv_meas_s_m",
                      "hv_meas_v_mps"]].to_numpy(float)
        logs.append(RunLog(f"pair {pair_id}", config, int(pair_id), None, states,
                           log["hv_accel_mps2"].to_numpy(float), meta))
    return fit_models(evidence_of(logs), intervals=["lfg"])


@pytest.mark.slow
def test_the_round_trip_recovers_p_a_and_selects_the_lfg(tmp_path):
    """Two fixtures of the replicated round trip (the benchmark's 0 and 2: ``p_a`` 0.3 and
    0.7, the human starting as leader): the 95 % interval covers the generating ``p_a`` and BIC
    selects the generating kind. Fitted without the measurement model (the models'
    accelerations compared as they are with the filtered recorded ones), the first selects
    the Boltzmann human instead (docs/guide/recordings.md, "The round trip, replicated")."""
    for d, p_a in ((0, 0.3), (2, 0.7)):
        report = roundtrip_fixture(tmp_path, d, p_a, "leader")
        e = report.fits["lfg"].params["p_a"]
        assert e.low <= p_a <= e.high, (d, e)
        assert report.selected == "lfg", d
    plain = roundtrip_fixture(tmp_path / "plain", 0, 0.3, "leader", measurement=False)
    assert plain.selected == "noisy"
