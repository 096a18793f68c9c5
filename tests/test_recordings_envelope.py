"""The human envelope from recordings (``persuasive.recordings.envelope``, ``recordings
envelope``) and the replay's premise under each named envelope
(``persuasive.recordings.replay.premise_by_envelope``). Every fixture is written here, into
``tmp_path``: straight tracks whose speeds are linear in time (constant accelerations, known by
hand), a hand-made fcd file, and small replays.

Tolerances: the Savitzky-Golay filter keeps a linear speed exactly up to float rounding, so
step accelerations and speeds are compared to 1e-9; quantiles are on a grid of 0.001 and
rounded up to it (``RESOLUTION``), so a quantile is checked to lie in ``[exact - 1e-9, exact +
0.001]``; counts and shares are exact.
"""

from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pytest

from _cli import run_cli
from persuasive.config import Config
from persuasive.recordings.envelope import (ENVELOPES, RESOLUTION, VEHICLES, Envelope,
                                            candidate_envelopes, estimate_envelope,
                                            file_steps, grid_bins, hist_quantile,
                                            parse_bound, toml_snippet)
from persuasive.recordings.formats import RecordingError, read_tracks
from persuasive.recordings.tracks import SmoothingParams, smooth_tracks

from test_recordings import straight, write
from test_recordings_replay import fcd_file

N = 41  # samples per hand-made track (4 s)
TESTED = N - 1 - 2 * 3  # steps tested per track: the first and last 3 samples' steps left out


def ramp(v0: float, a: float, n: int = N) -> np.ndarray:
    """Speeds of a constant acceleration ``a`` [m/s^2] from ``v0``, one per 0.1 s frame."""
    return v0 + a * 0.1 * np.arange(n)


@pytest.fixture
def known(tmp_path):
    """Car 1 at +1.5 m/s^2 from 2 m/s, car 2 at -2.5 m/s^2 from 12 m/s, truck 3 at +0.5 m/s^2
    from 3 m/s; each 41 samples, 34 steps tested."""
    return write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (0.0, 0.0), 0.0, ramp(2.0, 1.5)),
                 straight(2, (0.0, 10.0), 0.0, ramp(12.0, -2.5)),
                 straight(3, (0.0, 20.0), 0.0, ramp(3.0, 0.5), agent="truck"))


def inverted_cdf(x, q):
    return float(np.quantile(np.asarray(x, float), q, method="inverted_cdf"))


def assert_quantile(got, exact):
    assert exact - 1e-9 <= got <= exact + RESOLUTION, (got, exact)


# -- the named envelopes ------------------------------------------------------------------------


def test_the_named_envelopes_and_their_sources():
    hv = Config().vehicle_of("hv")
    paper = ENVELOPES["paper"]
    assert (paper.u_min_mps2, paper.u_max_mps2, paper.v_max_mps) == (
        hv.u_min_mps2, hv.u_max_mps2, hv.v_max_mps)
    sumo = ENVELOPES["sumo"]
    assert (sumo.u_min_mps2, sumo.u_max_mps2) == (-4.5, 2.6)
    assert sumo.v_max_mps == pytest.approx(55.56, abs=0.01)  # 200 km/h
    assert "DEFAULT_VEHTYPE" in sumo.source and "Vehicle Type Parameter Defaults" in sumo.source
    real = ENVELOPES["real-driver"]
    assert (real.u_min_mps2, real.u_max_mps2, real.v_max_mps) == (-3.7, 3.5, 16.5)
    for words in ("INTERACTION", "DR_USA_Intersection_GL", "DR_USA_Intersection_MA",
                  "13,500 cars", "6.1 h", "p99.9", "16.1"):
        assert words in real.source
    with pytest.raises(TypeError):
        ENVELOPES["mine"] = paper  # a read-only registry


def test_bounds_of_ones_own():
    env = parse_bound("-3,2")
    assert (env.u_min_mps2, env.u_max_mps2, env.v_max_mps) == (-3.0, 2.0, math.inf)
    assert parse_bound(" -3.5 , 2.5 , 15 ").v_max_mps == 15.0
    for bad in ("-3", "-3,2,1,0", "a,b", "3,2", "-3,-1", "-3,2,0", "-3,2,nan", "-inf,2", ""):
        with pytest.raises(RecordingError, match="--bound = .* allowed: U_MIN,U_MAX"):
            parse_bound(bad)
    names = [e.name for e in candidate_envelopes(["-3,2", "-3,2", "-2.5,1.5,12"])]
    assert names == ["paper", "sumo", "real-driver", "-3,2", "-2.5,1.5,12"]
    with pytest.raises(RecordingError, match="u_max = 0.0 is out of range"):
        Envelope("x", -1.0, 0.0, 10.0)


# -- quantiles ----------------------------------------------------------------------------------


def test_histogram_quantiles_bound_numpys_from_above_within_the_grid():
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.exponential(1.3, 5000), [0.0, 0.0, 1.5, 250.0]])
    hist = np.bincount(grid_bins(x), minlength=100_001)
    for q in (0.5, 0.9, 0.99, 0.999, 0.9999):
        got = hist_quantile(hist, q, x.max())
        exact = inverted_cdf(x, q)
        if exact > 100.0:  # the last bin: reported as the maximum
            assert got == x.max()
        else:
            assert_quantile(got, exact)
    assert hist_quantile(np.zeros(100_001, np.int64), 0.5, 0.0) is None
    # a value within ENVELOPE_TOL above a grid point counts at the point
    assert grid_bins(np.array([1.5 + 1e-12, 1.5 + 1e-6, 0.0])).tolist() == [1500, 1501, 0]


def test_quantiles_and_shares_known_by_hand(known):
    est = estimate_envelope([known], candidate_envelopes(["-2.4,1.4,11"]))
    assert sorted(est.classes) == ["car", "truck", VEHICLES]
    car, truck, veh = est.classes["car"], est.classes["truck"], est.classes[VEHICLES]
    assert (car.tracks, car.steps, car.edge_steps) == (2, 2 * TESTED, 2 * 6)
    assert (truck.tracks, truck.steps, veh.steps) == (1, TESTED, 3 * TESTED)
    # acceleration's positive part over the vehicles: 34 zeros, 34 of 0.5, 34 of 1.5
    acc = veh.quantiles("accel_mps2")
    assert acc["p50"] == 0.5 and acc["p90"] == 1.5 and acc["max"] == pytest.approx(1.5, abs=1e-9)
    # braking: 68 zeros, 34 of 2.5
    brake = veh.quantiles("braking_mps2")
    assert brake["p50"] == 0.0 and brake["p90"] == 2.5 and brake["p99.9"] == 2.5
    assert car.quantiles("accel_mps2")["p50"] == 0.0 and car.quantile("accel_mps2", 0.51) == 1.5
    # speeds at the steps' ends: samples 4..37 of each track
    j = np.arange(4, 38)
    speeds = {"car": np.concatenate([2.0 + 0.15 * j, 12.0 - 0.25 * j]),
              "truck": 3.0 + 0.05 * j}
    speeds[VEHICLES] = np.concatenate([speeds["car"], speeds["truck"]])
    for group, v in speeds.items():
        q = est.classes[group].quantiles("speed_mps")
        for name, p in (("p50", 0.5), ("p90", 0.9), ("p99", 0.99), ("p99.9", 0.999)):
            assert_quantile(q[name], inverted_cdf(v, p))
        assert q["max"] == pytest.approx(v.max(), abs=1e-9)
    # paper [-2, 1], v <= 10: car 2 brakes at 2.5 (34 steps), car 1 accelerates at 1.5 (34);
    # car 2 is above 10 m/s at samples 4..7 (12 - 0.25 j > 10: 4 steps, braking too)
    assert veh.beyond["paper"] == {"steps": 68, "braking": 34, "acceleration": 34, "speed": 4,
                                   "tracks": 2}
    assert veh.share_beyond("paper") == 68 / 102 and car.share_beyond("paper") == 1.0
    assert truck.beyond["paper"]["steps"] == 0
    for name in ("sumo", "real-driver"):
        assert veh.beyond[name] == dict.fromkeys(("steps", "braking", "acceleration", "speed",
                                                  "tracks"), 0)
    # the user's [-2.4, 1.4], v <= 11: car 2's 11.0 m/s at sample 4 is on the bound, not beyond
    assert veh.beyond["-2.4,1.4,11"] == {"steps": 68, "braking": 34, "acceleration": 34,
                                         "speed": 0, "tracks": 2}


def test_edge_samples_are_left_out(tmp_path):
    """A driver that brakes hard in its last 0.4 s: the steps that read its last 3 samples
    brake harder than any other; counting them would change the maximum."""
    brake = np.concatenate([np.full(36, 8.0), [7.4, 6.4, 5.0, 3.2, 1.0]])
    path = write(tmp_path / "vehicle_tracks_000.csv", straight(1, (0.0, 0.0), 0.0, brake),
                 straight(2, (0.0, 10.0), 0.0, ramp(8.0, 0.0)))
    tracks = smooth_tracks(read_tracks([path]))
    v = tracks.v[tracks.rows(0)]
    a = np.diff(v) / 0.1
    k = np.arange(a.size)
    inner = (k >= 3) & (k + 1 <= v.size - 1 - 3)
    assert -a.min() > -a[inner].min() + 0.5  # the edge steps brake harder
    est = estimate_envelope([path])
    car = est.classes["car"]
    assert car.steps == 2 * TESTED and car.edge_steps == 12
    assert car.maxima["braking_mps2"] == pytest.approx(-a[inner].min(), abs=1e-9)
    steps = file_steps(read_tracks([path]), SmoothingParams())
    np.testing.assert_allclose(steps.a[steps.track == 0], a[inner], atol=1e-9)
    np.testing.assert_allclose(steps.v[steps.track == 0], v[1:][inner], atol=1e-9)
    # speeds from the positions: twice the edge
    far = file_steps(read_tracks([path]), SmoothingParams(speed="positions"))
    assert far.a.size == 2 * (N - 1 - 2 * 6) and far.edge.tolist() == [24]


def test_classes_are_split_and_only_vehicles_pooled(tmp_path):
    path = write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (0.0, 0.0), 0.0, ramp(5.0, 1.0)),
                 straight(2, (0.0, 5.0), 0.0, ramp(9.0, -1.0), agent="truck"),
                 straight(3, (0.0, 10.0), 0.0, ramp(3.0, 2.0), agent="bicycle"),
                 straight(4, (0.0, 15.0), 0.0, ramp(1.2, 0.0), agent="pedestrian"),
                 straight(5, (0.0, 20.0), 0.0, [5.0] * 15))  # 1.4 s: too short
    est = estimate_envelope([path])
    assert sorted(est.classes) == ["bicycle", "car", "pedestrian", "truck", VEHICLES]
    c = est.classes
    assert (c["car"].tracks, c["car"].short_tracks) == (1, 1)
    assert c[VEHICLES].steps == c["car"].steps + c["truck"].steps == 2 * TESTED
    assert c[VEHICLES].tracks == 2 and c[VEHICLES].short_tracks == 1
    assert c["bicycle"].quantiles("accel_mps2")["p50"] == 2.0  # its own, not pooled
    assert c[VEHICLES].maxima["accel_mps2"] == pytest.approx(1.0, abs=1e-9)
    assert c["pedestrian"].quantiles("speed_mps")["max"] == pytest.approx(1.2, abs=1e-9)
    assert c[VEHICLES].beyond["paper"]["acceleration"] == 0
    assert c["bicycle"].beyond["paper"]["acceleration"] == TESTED


def test_files_are_counted_one_at_a_time_and_add_up(tmp_path, known):
    other = write(tmp_path / "vehicle_tracks_001.csv",
                  straight(1, (0.0, 0.0), 0.0, ramp(4.0, -1.0)),
                  straight(7, (0.0, 5.0), 0.0, ramp(6.0, 3.0)))
    both = estimate_envelope([known, other])
    one, two = estimate_envelope([known]), estimate_envelope([other])
    for group in ("car", VEHICLES):
        b, x, y = both.classes[group], one.classes[group], two.classes[group]
        assert b.steps == x.steps + y.steps and b.tracks == x.tracks + y.tracks
        for key in b.hists:
            np.testing.assert_array_equal(b.hists[key], x.hists[key] + y.hists[key])
            assert b.maxima[key] == max(x.maxima[key], y.maxima[key])
        for name in b.beyond:
            assert b.beyond[name] == {k: x.beyond[name][k] + y.beyond[name][k]
                                      for k in b.beyond[name]}
    # the same file twice (or its folder and itself) is read once
    assert estimate_envelope([known, known, str(tmp_path / "vehicle_tracks_000.csv")]
                             ).files == (known,)


def test_the_envelope_at_a_quantile_leaves_at_most_the_rest_beyond_each_side(tmp_path):
    rng = np.random.default_rng(7)
    tracks = []
    for i in range(12):
        a = np.repeat(rng.uniform(-3.0, 2.5, 8), 10)  # piecewise constant, 1 s each
        v = np.maximum(6.0 + np.concatenate([[0.0], np.cumsum(a[:-1]) * 0.1]), 0.3)
        tracks.append(straight(i + 1, (0.0, 6.0 * i), 0.0, v))
    path = write(tmp_path / "vehicle_tracks_000.csv", *tracks)
    for q in (0.7, 0.9, 0.99):  # both sides of a nonzero (at 0.5 the braking's part is 0)
        env = estimate_envelope([path]).envelope_at(q)
        veh = estimate_envelope([path], [env]).classes[VEHICLES]
        counts = veh.beyond[env.name]
        for side in ("braking", "acceleration", "speed"):
            assert counts[side] <= (1.0 - q) * veh.steps + 1e-9, (q, side, counts)


def test_the_estimate_as_configuration_overrides(known):
    est = estimate_envelope([known])
    env = est.envelope_at(0.9)
    assert (env.u_min_mps2, env.u_max_mps2) == (-2.5, 1.5)
    text = toml_snippet(env)
    data = tomllib.loads(text)
    assert data == {"hv": {"vehicle": {"u_min_mps2": -2.5, "u_max_mps2": 1.5,
                                       "v_max_mps": math.ceil(env.v_max_mps * 100) / 100}}}
    hv = Config.from_dict(data).vehicle_of("hv")
    assert (hv.u_min_mps2, hv.u_max_mps2) == (-2.5, 1.5)
    # rounded outward
    odd = Envelope("x", -3.7012, 3.4901, 16.1001, "s")
    assert tomllib.loads(toml_snippet(odd))["hv"]["vehicle"] == {
        "u_min_mps2": -3.71, "u_max_mps2": 3.5, "v_max_mps": 16.11}
    # the truck alone never brakes: no envelope (u_min must be negative)
    assert est.envelope_at(0.9, "truck") is None and est.envelope_at(0.9, "nobody") is None


def test_sumo_fcd_files_are_read_with_their_classes(tmp_path):
    steps = []
    for k in range(40):
        t = 0.1 * k
        v = 4.0 + 2.0 * t  # 2 m/s^2
        steps.append((t, [f'<vehicle id="c" x="{50.0 + 4.0 * t + t * t:.6f}" y="0.0" '
                          f'angle="90.00" speed="{v:.6f}"/>',
                          f'<vehicle id="b" x="0.0" y="{3.0 * t:.6f}" angle="0.00" '
                          'type="DEFAULT_BIKETYPE" speed="3.0"/>']))
    fcd = fcd_file(tmp_path / "fcd.xml", steps)
    est = estimate_envelope([fcd])
    assert sorted(est.classes) == ["bicycle", "car", VEHICLES]
    car = est.classes["car"]
    assert car.steps == 40 - 1 - 6 and car.quantiles("accel_mps2")["p50"] == 2.0
    assert car.beyond["paper"]["acceleration"] == car.steps and car.beyond["sumo"]["steps"] == 0
    assert est.classes["bicycle"].quantiles("speed_mps")["max"] == pytest.approx(3.0)


# -- the command --------------------------------------------------------------------------------


def test_envelope_command_prints_the_tables(capsys, known):
    code, out, err = run_cli(capsys, "recordings", "envelope", known, "--bound=-2.4,1.4,11",
                             "--quantile", "0.9")
    assert code == 0 and err == "", err
    assert "| car | p50 | p90 | p99 | p99.9 | max | q = 0.9 |" in out
    assert "| braking [m/s^2] | 0.00 | 2.50 | 2.50 | 2.50 | 2.50 | 2.50 |" in out
    assert "| paper | u in [-2, 1] m/s^2, v <= 10 m/s | vehicles | 68 of 102 | 66.67 % | 34 | " \
           "34 | 4 | 2 of 3 |" in out
    assert "| -2.4,1.4,11 | u in [-2.4, 1.4] m/s^2, v <= 11 m/s | vehicles | 68 of 102 |" in out
    assert "real-driver: the p99.9 of real drivers in the INTERACTION dataset" in out
    toml = out[out.rindex("[hv.vehicle]"):]
    assert tomllib.loads(toml)["hv"]["vehicle"]["u_min_mps2"] == -2.5


def test_envelope_command_json_and_out(capsys, known, tmp_path):
    code, out, err = run_cli(capsys, "recordings", "envelope", known, "--json")
    assert code == 0 and err == ""
    info = json.loads(out)
    assert info["quantile"] == 0.999 and info["edge_samples"] == 3
    assert info["envelopes"]["real-driver"]["u_min_mps2"] == -3.7
    veh = info["classes"][VEHICLES]
    assert veh["steps"] == 102 and veh["beyond"]["paper"]["share"] == 68 / 102
    assert veh["braking_mps2"]["p90"] == 2.5 and info["estimate"]["u_max_mps2"] == 1.5
    target = tmp_path / "envelope.json"
    code, out, err = run_cli(capsys, "recordings", "envelope", known, "--out", target)
    assert code == 0 and f"written: {target}" in out
    assert json.loads(target.read_text()) == info
    assert sorted(p.name for p in tmp_path.iterdir()) == ["envelope.json",
                                                          "vehicle_tracks_000.csv"]


@pytest.mark.parametrize("args, words", [
    (["nothing.csv"], "track file 'nothing.csv' does not exist"),
    (["notes.csv"], "is not a track file"),
    (["gone.xml"], "fcd file 'gone.xml' does not exist"),
    (["KNOWN", "--quantile", "1.5"], "--quantile = 1.5 is out of range; allowed: (0, 1)"),
    (["KNOWN", "--quantile", "0"], "--quantile = 0 is out of range; allowed: (0, 1)"),
    (["KNOWN", "--bound", "2,3"], "--bound = '2,3' is out of range; allowed: U_MIN,U_MAX"),
    (["KNOWN", "--bound=-3"], "--bound = '-3' is not allowed; allowed: U_MIN,U_MAX"),
    (["KNOWN", "--window", "4"], "smoothing window = 4 is out of range"),
    (["KNOWN", "--speed-from", "radar"], "--speed-from = 'radar' is not allowed"),
    (["KNOWN", "--types", "t.rou.xml"], "--types is read with SUMO fcd files (.xml) only"),
    (["KNOWN", "--out", "env.txt"], "unsupported extension '.txt'"),
])
def test_bad_envelope_input_is_one_line_and_exit_2(capsys, known, tmp_path, monkeypatch, args,
                                                   words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.csv").write_text("a,b\n1,2\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    args = [known if a == "KNOWN" else a for a in args]
    code, out, err = run_cli(capsys, "recordings", "envelope", *args)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_ctrl_c_exits_130_and_writes_nothing(capsys, known, tmp_path, monkeypatch):
    import persuasive.recordings.envelope as E

    other = write(tmp_path / "vehicle_tracks_001.csv",
                  straight(1, (0.0, 0.0), 0.0, ramp(4.0, -1.0)),
                  straight(2, (0.0, 5.0), 0.0, ramp(6.0, 1.0)))
    real = E.file_steps
    calls = []

    def interrupted(table, params):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(table, params)

    monkeypatch.setattr(E, "file_steps", interrupted)
    target = tmp_path / "envelope.json"
    code, out, err = run_cli(capsys, "recordings", "envelope", known, other, "--out", target,
                             "--quiet")
    assert code == 130 and err.strip() == "error: interrupted" and out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["vehicle_tracks_000.csv",
                                                          "vehicle_tracks_001.csv"]


# -- the replay's premise under each envelope ---------------------------------------------------


@pytest.fixture(scope="module")
def three_drivers(tmp_path_factory):
    """Three recordings of one crossing: vehicle 1 east at 9 m/s; vehicle 2 north braking at
    -2.5 m/s^2 (9 to 5.25 m/s), at -4 m/s^2 (9 to 3 m/s), or at 12 m/s throughout."""
    from persuasive.recordings.pairs import find_pairs, pairs_frame, write_pairs

    folder = tmp_path_factory.mktemp("three")
    drivers = {0: np.concatenate([np.full(20, 9.0), np.linspace(9.0, 5.25, 16),
                                  np.full(150, 5.25)]),
               1: np.concatenate([np.full(20, 9.0), np.linspace(9.0, 3.0, 16),
                                  np.full(150, 3.0)]),
               2: np.full(186, 12.0)}
    for i, v in drivers.items():
        write(folder / f"vehicle_tracks_00{i}.csv",
              straight(1, (-50.0, 0.0), 0.0, [9.0] * 186),
              straight(2, (0.0, -60.0), 90.0, v))
    result = find_pairs(smooth_tracks(read_tracks([str(folder)])))
    pairs = folder / "pairs.parquet"
    write_pairs(pairs, result, [str(folder)])
    return pairs_frame(result.pairs), str(pairs)


def test_the_premise_under_each_envelope_by_hand(three_drivers):
    from persuasive.recordings.replay import (ReplaySettings, edge_steps, envelope_excess,
                                              replay_accelerations, replay_pairs)

    frame, _ = three_drivers
    result = replay_pairs(frame, ReplaySettings(seats=(1,)))
    runs = {r.recording: r for r in result.runs}
    assert len(runs) == 3
    info = result.summary()
    premise = info["premise_by_envelope"]
    assert list(premise) == ["configured", "paper", "sumo", "real-driver"]
    # the configured envelope's counts are today's
    assert premise["configured"]["runs"] == info["within_envelope_certified_start"]["runs"]
    assert premise["configured"]["within_envelope"] == info["runs"] - info["envelope"][
        "runs_beyond"]
    # by hand: each run's tested steps against each envelope
    for name, env in ENVELOPES.items():
        within = held = 0
        for pair_id, rows in frame.groupby("pair"):
            rows = rows.sort_values("step")
            v = rows["v_2_mps"].to_numpy(float)
            tested = ~edge_steps(rows, 2, 3)
            inside = not (envelope_excess(replay_accelerations(v), v, env) & tested).any()
            run = runs[str(rows["recording"].iloc[0])]
            within += inside
            held += inside and run.start_certified
        assert premise[name]["within_envelope"] == within
        assert premise[name]["runs"] == held and premise[name]["share"] == held / 3
        assert (premise[name]["u_min_mps2"], premise[name]["u_max_mps2"]) == (
            env.u_min_mps2, env.u_max_mps2)
    # what that gives here: -2.5 is within the real drivers' and SUMO's envelopes, -4 only
    # within SUMO's; 12 m/s is beyond the paper's 10 m/s but within the configured envelope,
    # whose v_max is raised to the pair's highest speed
    assert all(r.start_certified for r in runs.values())
    within = {name: [name == "configured" and r.within_envelope
                     or name != "configured" and _within(r, ENVELOPES[name])
                     for _, r in sorted(runs.items())] for name in premise}
    assert within == {"configured": [False, False, True], "paper": [False, False, False],
                      "sumo": [True, True, True], "real-driver": [True, False, True]}
    assert [premise[k]["runs"] for k in premise] == [1, 0, 3, 2]


def _within(run, env):
    from persuasive.recordings.replay import within

    return within(run, env)


def test_replay_command_prints_the_premise_per_envelope(capsys, three_drivers):
    _, pairs = three_drivers
    # --pet-max inf: the fixture's drivers pass seconds apart (no interaction by the default)
    code, out, err = run_cli(capsys, "recordings", "replay", pairs, "--seat", "1", "--quiet",
                             "--pet-max", "inf")
    assert code == 0 and err == "", err
    lines = out.splitlines()
    i = lines.index("premise held (the driver within the envelope on every tested step, the "
                    "start certified), by envelope:")
    assert lines[i + 1:i + 5] == [
        "  configured (u in [-2, 1] m/s^2, v up to the pair's highest speed): 1 of 3 runs "
        "(33.3 %); driver within in 1",
        "  paper (u in [-2, 1] m/s^2, v <= 10 m/s): 0 of 3 runs (0.0 %); driver within in 0",
        "  sumo (u in [-4.5, 2.6] m/s^2, v <= 55.56 m/s): 3 of 3 runs (100.0 %); driver "
        "within in 3",
        "  real-driver (u in [-3.7, 3.5] m/s^2, v <= 16.5 m/s): 2 of 3 runs (66.7 %); driver "
        "within in 2"]
    code, out, _ = run_cli(capsys, "recordings", "replay", pairs, "--seat", "1", "--json",
                           "--pet-max", "inf")
    assert json.loads(out)["premise_by_envelope"]["real-driver"]["runs"] == 2


def test_a_named_envelope_is_a_configuration_choice_the_shield_reads(capsys):
    """``hv.envelope`` sets the human's braking, acceleration and top speed from the same
    table the recordings measure against; the shield's human limits are those; unset, every
    configuration keeps its text and digest."""
    from persuasive import packing as slot
    from persuasive.config import HUMAN_ENVELOPES, ConfigError
    from persuasive.record import static_setup
    from persuasive.safety import shield as sh

    from _cli import run_cli

    base = Config(mode="corrected")
    real = base.with_overrides({"hv.envelope": "real-driver"})
    hv = real.vehicle_of("hv")
    assert (hv.u_min_mps2, hv.u_max_mps2, hv.v_max_mps) == HUMAN_ENVELOPES["real-driver"][:3]
    assert real.vehicle_of("av") == base.vehicle_of("av")
    assert hv.length_m == base.vehicle_of("hv").length_m
    for name, env in ENVELOPES.items():
        if name != "paper":
            assert (env.u_min_mps2, env.u_max_mps2, env.v_max_mps, env.source) == \
                HUMAN_ENVELOPES[name]
    assert "envelope" not in base.to_toml() and "envelope" in real.to_toml()
    import tomllib

    assert Config.from_dict(tomllib.loads(real.to_toml())) == real
    # the shield's conflict row carries the envelope (widened by the acceleration noise)
    _, P_av, P_hv, _ = static_setup(real)
    row = np.zeros(sh.N_CONFLICT)
    sh.conflict_vector(P_av, P_hv, row)
    w = P_av[slot.ACCEL_NOISE]
    assert (row[sh.C_H_UMIN], row[sh.C_H_UMAX], row[sh.C_H_VMAX]) == (-3.7 - w, 3.5 + w, 16.5)
    # refused: a name not in the table; the envelope with the fields it sets
    with pytest.raises(ConfigError, match=r"hv.envelope = 'moon'.*sumo \| real-driver"):
        base.with_overrides({"hv.envelope": "moon"})
    with pytest.raises(ConfigError, match="hv.vehicle.u_min_mps2, which is set too"):
        base.with_overrides({"hv.envelope": "sumo", "hv.vehicle.u_min_mps2": -3.0})
    base.with_overrides({"hv.envelope": "sumo", "hv.vehicle.length_m": 4.0})  # not its field
    code, out, err = run_cli(capsys, "simulate", "--set", "hv.envelope=moon")
    assert code == 2 and "hv.envelope" in err and len(err.strip().splitlines()) == 1
