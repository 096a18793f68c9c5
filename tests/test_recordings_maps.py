"""Lanelet2 maps (``persuasive.recordings.lanelet_map``): our scenarios written as maps with a
rule, read back through the lanelet2 package, each pair's rule from its approach, and the
right-of-way baseline reading it; bad maps and options in one line with exit status 2."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from _cli import run_cli as run
from test_recordings_cli import runs  # noqa: F401 - the module's fixture: two crossing runs
from persuasive import Config, simulate
from persuasive.record import load_record
from persuasive.recordings.baselines import Features, right_of_way, sumo_rule
from persuasive.recordings.evaluate import PairData, features_of, pairs_of, stop_arrival
from persuasive.recordings.formats import RecordingError
from persuasive.recordings.lanelet_map import (lanelets_at, pair_rule, read_map, stop_line_s,
                                               write_map)
from persuasive.recordings.pairs import read_pairs

#: Pairs of two small recordings in this process: starting worker processes took 13 of the
#: 19 s of each call; the other pairs tests (tests/test_recordings_cli.py) run them with the
#: default workers.
ONE_PROCESS = ("--workers", "1")

try:
    import lanelet2  # noqa: F401 - the maps' reader and writer need it
except ImportError:  # no wheel for this Python (3.14): skipped, but never in CI
    if os.environ.get("CI"):
        raise
    pytest.skip("lanelet2 has wheels for Python 3.11-3.13", allow_module_level=True)


@pytest.mark.parametrize("rule", ["av", "hv", "all-way-stop"])
def test_a_written_map_reads_back_with_its_rule(runs, tmp_path, rule):
    scene = load_record(runs[0]).scenario
    path = tmp_path / "map.osm"
    write_map(path, scene, rule)
    road = read_map(path)
    assert road.n_lanelets == 2
    # each path's centre before its occupancy lies in exactly its own lanelet
    lanes = {}
    for who in ("av", "hv"):
        x, y, _ = scene.positions(who, np.array([-30.0, -20.0]))
        found = lanelets_at(road, x, y)
        assert len(found) == 1
        lanes[who] = found.pop()
    assert lanes["av"] != lanes["hv"]
    if rule == "all-way-stop":
        assert road.right_of_way == {}
        for who in ("av", "hv"):
            ((_, line),) = road.all_way_stop[lanes[who]]
            # the stop line is across the lanelet at the path's yield line, lane-wide
            sx, sy, _ = scene.positions(who, np.array([getattr(scene, who).yield_s]))
            np.testing.assert_allclose(line.mean(axis=0), [sx[0], sy[0]], atol=1e-6)
            assert np.hypot(*(line[1] - line[0])) == pytest.approx(scene.lane_width_m)
    else:
        winner, loser = (("av", "hv") if rule == "av" else ("hv", "av"))
        assert [r for _, r in road.right_of_way[lanes[winner]]] == ["right_of_way"]
        assert [r for _, r in road.right_of_way[lanes[loser]]] == ["yield"]
        assert road.all_way_stop == {}


@pytest.mark.parametrize("rule,control,priority,expected", [
    ("av", "right_of_way", 1, ["av", "hv"]), ("hv", "right_of_way", 2, ["hv", "av"]),
    ("all-way-stop", "all_way_stop", 0, ["", ""])])
def test_export_pairs_and_replay_carry_the_maps_rule(capsys, runs, tmp_path, monkeypatch, rule,
                                                     control, priority, expected):
    """Exported with a map, every pair is labelled with the map's rule, the evaluation's
    baselines read it, and the replay gives it to the responsibility shield of each seat: the
    replaced vehicle's priority is the AV's (vehicle 1, the exported AV, has it under rule
    "av"). One export and one pairs file per rule for all three (each costs seconds)."""
    from persuasive.recordings import replay as rp

    tracks, pairs = tmp_path / "tracks", tmp_path / "pairs.parquet"
    code, out, err = run(capsys, "recordings", "export", *runs, "--out", str(tracks),
                         "--noise-m", "0.05", "--map-rule", rule)
    assert code == 0 and err == "", err
    assert f"the map ({rule}) in map.osm" in out
    assert sorted(p.name for p in tracks.iterdir()) == ["map.osm", "vehicle_tracks_000.csv",
                                                        "vehicle_tracks_001.csv"]
    code, out, err = run(capsys, "recordings", "pairs", str(tracks), "--map",
                         str(tracks / "map.osm"), "--out", str(pairs), "--quiet",
                         *ONE_PROCESS)
    assert code == 0 and err == "", err
    assert f"the map's rule: {control.replace('_', ' ')} 2" in out
    frame, meta = read_pairs(pairs)
    assert meta["map"] == {"path": str(tracks / "map.osm"), "origin": [0.0, 0.0]}
    per_pair = frame.groupby("pair").first()
    # track 1 is the AV, and vehicle 1 of a crossing is the lower track ID
    assert (per_pair["track_1"] == 1).all()
    assert (per_pair["control"] == control).all()
    assert (per_pair["priority"] == priority).all()
    if control == "all_way_stop":
        line = load_record(runs[0]).scenario.av.yield_s
        np.testing.assert_allclose(per_pair[["stop_1_m", "stop_2_m"]].to_numpy(), line,
                                   atol=0.05)
    else:
        assert per_pair[["stop_1_m", "stop_2_m"]].isna().all().all()
    # the evaluation's pairs carry the rule into the baselines' features
    data = pairs_of(frame, "site", False)
    assert {(p.control, p.priority) for p in data} == {(control, priority)}
    f = features_of(data, [10] * len(data))
    if control == "right_of_way":
        np.testing.assert_array_equal(right_of_way(f), [1 if priority == 1 else 0] * len(data))

    # the replay: each seat's responsibility shield gets the map's right of way
    seen = []

    def spy(config, x0, hv_prm=None, seed=0):
        seen.append(config.responsibility.right_of_way)
        return original(config, x0, hv_prm, seed)

    original = rp.run_from
    monkeypatch.setattr(rp, "run_from", spy)
    result = rp.replay_pairs(frame, rp.ReplaySettings(shield="responsibility"))
    n = frame["pair"].nunique()
    assert n == 2 and [r.seat for r in result.runs] == [1, 2] * n
    assert [r.right_of_way for r in result.runs] == expected * n
    assert seen == [x or None for x in expected] * n
    counts = result.summary()["right_of_way"]
    assert counts == {"av": expected.count("av") * n, "hv": expected.count("hv") * n,
                      "neither": expected.count("") * n}
    monkeypatch.undo()
    code, out, err = run(capsys, "recordings", "replay", str(pairs), "--shield",
                         "responsibility", "--quiet")
    assert code == 0 and err == "", err
    line = f"the map's right of way: the AV's in {n} runs, the other's in {n}, neither in 0"
    assert (line in out) == (rule != "all-way-stop")


def test_pairs_without_a_map_are_unknown_and_keep_the_approach_rule(capsys, runs, tmp_path):
    tracks, pairs = tmp_path / "tracks", tmp_path / "pairs.parquet"
    assert run(capsys, "recordings", "export", *runs, "--out", str(tracks))[0] == 0
    code, out, err = run(capsys, "recordings", "pairs", str(tracks), "--out", str(pairs),
                         *ONE_PROCESS)
    assert code == 0 and "the map's rule" not in out
    frame, meta = read_pairs(pairs)
    assert meta["map"] is None and (frame["control"] == "unknown").all()
    # a pairs file written before the map columns existed reads as unknown too
    old = frame.drop(columns=["control", "priority", "stop_1_m", "stop_2_m"])
    data = pairs_of(old, "site", False)
    assert {p.control for p in data} == {"unknown"}
    f = features_of(data, [10] * len(data))
    assert f.priority is None and f.all_way is None


def test_seat_right_of_way_reads_only_a_right_of_way_rule():
    import pandas as pd

    from persuasive.recordings.replay import seat_right_of_way

    def rows(control, priority):
        return pd.DataFrame({"control": [control], "priority": [priority]})

    assert [seat_right_of_way(rows("right_of_way", 2), s) for s in (1, 2)] == ["hv", "av"]
    for control, priority in (("all_way_stop", 0), ("none", 0), ("unknown", 0),
                              ("right_of_way", 0)):
        assert seat_right_of_way(rows(control, priority), 1) is None
    assert seat_right_of_way(pd.DataFrame({"pair": [3]}), 1) is None  # a file before maps


def _features(priority=None, all_way=None, arrival=None):
    # pair 0: vehicle 1 heads west, vehicle 2 north (1 comes from 2's right); pair 1: east
    return Features(s=np.array([[-20.0, -10.0], [-10.0, -20.0]]),
                    v=np.array([[10.0, 2.0], [5.0, 10.0]]), a=np.zeros((2, 2)),
                    direction=np.array([[math.pi, math.pi / 2], [0.0, math.pi / 2]]),
                    occ_lo=np.full((2, 2), -3.0), occ_hi=np.full((2, 2), 3.0),
                    merge=np.array([False, False]), priority=priority, all_way=all_way,
                    stop_arrival=arrival)


def test_the_maps_right_of_way_overrides_the_approach_and_arrival_order_rules_all_way_stops():
    assert right_of_way(_features()).tolist() == [1, 0]  # right before left
    # the map gives pair 0 to vehicle 2 and pair 1 to vehicle 1
    f = _features(np.array([2, 1]), np.array([False, False]), np.zeros((2, 2)))
    assert right_of_way(f).tolist() == [0, 1]
    # no rule in the map for pair 1: the approach decides there
    f = _features(np.array([2, 0]), np.array([False, False]), np.zeros((2, 2)))
    assert right_of_way(f).tolist() == [0, 0]
    # all-way stops: vehicle 2 reached its line 1 s ago, vehicle 1 will in 0.5 s (pair 0);
    # pair 1: vehicle 1 was there 2 s ago, vehicle 2 0.5 s ago
    f = _features(np.zeros(2, np.int64), np.array([True, True]),
                  np.array([[0.5, -1.0], [-2.0, -0.5]]))
    assert right_of_way(f).tolist() == [0, 1]
    # SUMO's rule takes the map's major road. Pair 0: the minor (vehicle 1) leaves at 23 / 10
    # s, the major enters at 7 / 2 s, 1.2 s later: the minor goes first. Pair 1: the major
    # (vehicle 1) enters at 7 / 5 s, before the minor leaves (23 / 10 s): it goes first (from
    # the approach alone vehicle 2 is the major there and goes first)
    assert sumo_rule(_features()).tolist() == [1, 0]
    f = _features(np.array([2, 1]), np.array([False, False]), np.zeros((2, 2)))
    assert sumo_rule(f).tolist() == [1, 1]
    # a subset keeps the map's columns
    assert right_of_way(f.take([1])).tolist() == [1]


def test_stop_arrival_reads_the_past_and_extrapolates_the_rest():
    t = np.arange(6) * 0.1
    s = np.array([[-12.0, -10.0, -8.0, -6.0, -4.0, -2.0],   # reaches -8 (line -6 - 2) at 0.2 s
                  [-30.0, -29.0, -28.0, -27.0, -26.0, -25.0]])
    v = np.array([[20.0] * 6, [10.0] * 6])
    p = PairData("site", "f", 0, "crossing", 90.0, ("car", "car"), (5.0, 5.0), (2.0, 2.0),
                 np.array([[-5.0, 5.0], [-4.0, 4.0]]), t=t, s=s, v=v, a=np.zeros((2, 6)),
                 x=np.zeros((2, 6)), y=np.zeros((2, 6)), control="all_way_stop",
                 stop_s=(-6.0, math.nan))
    got = stop_arrival(p, 4)
    assert got[0] == pytest.approx(0.2 - 0.4)
    # vehicle 2 has no stop line: the start of its occupancy, -4 m; from -26 m at 10 m/s
    assert got[1] == pytest.approx((-4.0 - 2.0 + 26.0) / 10.0)
    # the steps after the moment are not read: at step 1 vehicle 1 is 2 m short at 20 m/s
    assert stop_arrival(p, 1)[0] == pytest.approx((-8.0 + 10.0) / 20.0)


def test_pair_rule_contradictions_and_vehicles_off_the_map(runs, tmp_path):
    from dataclasses import replace

    scene = load_record(runs[0]).scenario
    path = tmp_path / "map.osm"
    write_map(path, scene, "av")
    road = read_map(path)
    s = np.array([np.linspace(-40.0, 10.0, 51)] * 2)
    xa, ya, _ = scene.positions("av", s[0])
    xh, yh, _ = scene.positions("hv", s[1])
    x, y = np.stack([xa, xh]), np.stack([ya, yh])
    occ = np.array([[-5.0, 5.0], [-5.0, 5.0]])
    control, priority, stops = pair_rule(road, s, x, y, occ)
    assert (control, priority) == ("right_of_way", 1) and all(map(math.isnan, stops))
    # the other way round (vehicle 1 on the HV's lanelet): vehicle 2 has it
    assert pair_rule(road, s, x[::-1], y[::-1], occ)[:2] == ("right_of_way", 2)
    # both on one lanelet (no element relates a lanelet with itself): none
    assert pair_rule(road, s, np.stack([xa, xa]), np.stack([ya, ya]), occ)[:2] == ("none", 0)
    # far off every lanelet: none
    assert pair_rule(road, s, x + 500.0, y + 500.0, occ)[:2] == ("none", 0)
    # a map where each lanelet has the right of way over the other contradicts itself: none
    lane_av = lanelets_at(road, xa[:5], ya[:5]).pop()
    lane_hv = lanelets_at(road, xh[:5], yh[:5]).pop()
    both = replace(road, right_of_way={lane_av: [(1, "right_of_way"), (2, "yield")],
                                       lane_hv: [(1, "yield"), (2, "right_of_way")]})
    assert pair_rule(both, s, x, y, occ)[:2] == ("none", 0)


def test_stop_line_s_is_where_the_path_crosses_the_line():
    s = np.array([-10.0, -5.0, 0.0, 5.0])
    x, y = s.copy(), np.zeros(4)
    assert stop_line_s(s, x, y, np.array([[-6.5, -2.0], [-6.5, 2.0]])) == pytest.approx(-6.5)
    assert math.isnan(stop_line_s(s, x, y, np.array([[-6.5, 1.0], [-6.5, 2.0]])))


def test_bad_maps_and_map_options_end_in_one_line_and_exit_2(capsys, runs, tmp_path):
    tracks = tmp_path / "tracks"
    assert run(capsys, "recordings", "export", *runs, "--out", str(tracks))[0] == 0
    empty = tmp_path / "empty.osm"
    empty.write_text('<?xml version="1.0"?>\n<osm version="0.6" generator="test"></osm>\n')
    text = tmp_path / "notes.osm"
    text.write_text("a map, honestly\n")
    out = tmp_path / "pairs.parquet"
    cases = [
        (["recordings", "pairs", str(tracks), "--map", str(empty), "--out", str(out)],
         "holds no lanelet"),
        (["recordings", "pairs", str(tracks), "--map", str(text), "--out", str(out)],
         "is not a Lanelet2 map"),
        (["recordings", "pairs", str(tracks), "--map", str(tmp_path / "none.osm"), "--out",
          str(out)], "no such file"),
        (["recordings", "pairs", str(tracks), "--map", str(empty), "--map-origin", "91,0",
          "--out", str(out)], "map origin = 91,0 is out of range"),
        (["recordings", "pairs", str(tracks), "--map", str(empty), "--map-origin", "north",
          "--out", str(out)], "--map-origin = 'north' is out of range"),
        (["recordings", "export", *runs, "--out", str(tmp_path / "t2"), "--map-rule", "left"],
         "--map-rule = 'left' is not allowed; allowed: av, hv, all-way-stop"),
    ]
    for args, words in cases:
        code, o, err = run(capsys, *args)
        assert code == 2, args
        assert words in err and len(err.strip().splitlines()) == 1, err
        assert "Traceback" not in err
        assert not out.exists() and not (tmp_path / "t2").exists()


def test_one_map_needs_one_scenario(capsys, runs, tmp_path):
    other = tmp_path / "merge.parquet"
    config = Config(mode="corrected").with_overrides({"scenario.kind": "crossing",
                                                      "scenario.angle_deg": 60.0,
                                                      "simulation.n_steps": 20})
    simulate(config, 1).save(other)
    code, out, err = run(capsys, "recordings", "export", runs[0], str(other), "--out",
                         str(tmp_path / "t"), "--map-rule", "av")
    assert code == 2 and "draws one map" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "t").exists()
    with pytest.raises(RecordingError, match="map rule = 'x' is out of range"):
        write_map(tmp_path / "m.osm", load_record(runs[0]).scenario, "x")
