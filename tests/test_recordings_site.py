"""A site-size recording made here (``persuasive.recordings.site``; issue 42): a tiny site (3
simulated minutes, 2 files) built by SUMO, read back by the INTERACTION reader, its map by
``lanelet_map``, its pairs by ``recordings pairs --map``; the same seed gives the same bytes;
the track numbering and the writer by hand; bad parameters in one line; an interrupted run
leaves nothing.

Tolerances: positions are written to the millimetre, so values read back are compared to
5e-4 m (half a millimetre); counts and bytes exactly.
"""

from __future__ import annotations

import filecmp
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lanelet2  # noqa: F401 - the map's writer and reader need it (installed with the tests)
import libsumo  # noqa: F401 - the site is run by SUMO in this process
import sumo  # noqa: F401 - netconvert builds its network

from _cli import run_cli as run
from persuasive.config import ConfigError
from persuasive.recordings.formats import (INTERACTION_COLUMNS, RecordingError,
                                           find_track_files, read_interaction,
                                           write_interaction)
from persuasive.recordings.lanelet_map import lanelets_at, read_map
from persuasive.recordings.pairs import read_pairs
from persuasive.recordings.site import (JSON_NAME, MAP_NAME, SiteParams, _Buffer, file_rows,
                                        make_site, write_tracks)

ROOT = Path(__file__).resolve().parents[1]
TINY = SiteParams(hours=0.05, files=2)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site") / "site"
    make_site(out, TINY)
    return out


def _meta(folder: Path) -> dict:
    return json.loads((folder / JSON_NAME).read_text())


def _arm(x: float, y: float) -> str:
    return ("W" if x < 0 else "E") if abs(x) >= abs(y) else ("S" if y < 0 else "N")


def test_every_file_reads_and_the_counts_are_site_json(site):
    meta = _meta(site)
    files = find_track_files([site])
    assert [f.path.name for f in files] == ["vehicle_tracks_000.csv", "vehicle_tracks_001.csv"]
    assert meta["files"] == 2 and meta["track_files"] == [f.path.name for f in files]
    assert meta["hours"] == 0.05 and meta["recorded_hours"] == pytest.approx(0.05, abs=1e-9)
    rows = 0
    for f, n in zip(files, meta["tracks_per_file"]):
        table = read_interaction(f.path)
        assert table["track"].nunique() == n
        assert sorted(table["track"].unique()) == list(range(1, n + 1))
        # each file is its own 90 s recording from 0, its centres in the view
        assert table["t_s"].min() == 0.0 and table["t_s"].max() == pytest.approx(89.9)
        assert (table[["x_m", "y_m"]].abs() <= TINY.view_m + 5e-4).all().all()
        assert set(table["agent_class"]) <= {"car", "truck"}
        rows += len(table)
    assert sum(meta["tracks_per_file"]) == meta["tracks"] and meta["samples"] == rows
    assert meta["tracks"] >= meta["vehicles_recorded"] > 100
    # SUMO's own judges: no collision, nobody stuck; its version recorded
    assert meta["sumo"]["collisions"] == 0 and meta["sumo"]["teleports"] == 0
    assert meta["sumo"]["collision_reports"] == []
    assert meta["sumo"]["version"].startswith("SUMO ")
    assert meta["seed"] == 1 and set(meta["flows_veh_h"]) == {
        f"{a}_{t}" for a in "WESN" for t in ("left", "straight", "right")}


def test_the_map_reads_back_in_the_tracks_frame(site):
    meta = _meta(site)
    road = read_map(site / MAP_NAME)
    assert road.n_lanelets == meta["map"]["lanelets"]
    # one right-of-way element per minor approach: the major road's lanes over its lanes
    elements = {e for roles in road.right_of_way.values() for e, _ in roles}
    assert len(elements) == meta["map"]["right_of_way"] == 2
    table = read_interaction(site / "vehicle_tracks_000.csv")
    pick = np.random.default_rng(0).choice(len(table), 400, replace=False)
    inside = [bool(lanelets_at(road, [x], [y])) for x, y in
              zip(table["x_m"].to_numpy()[pick], table["y_m"].to_numpy()[pick])]
    assert np.mean(inside) >= 0.99
    roles = {}
    for (x, y) in ((-30.0, -4.8), (30.0, 4.8), (1.6, -30.0), (-1.6, 30.0)):  # lanes 30 m out
        found = lanelets_at(road, [x], [y])
        assert len(found) == 1
        roles[_arm(x, y)] = {r for ll in found for _, r in road.right_of_way.get(ll, ())}
    assert roles == {"W": {"right_of_way"}, "E": {"right_of_way"}, "S": {"yield"},
                     "N": {"yield"}}


@pytest.mark.slow
def test_pairs_with_the_map_give_the_major_road_the_right_of_way(capsys, site, tmp_path):
    out = tmp_path / "pairs.parquet"
    code, text, err = run(capsys, "recordings", "pairs", site, "--map", site / MAP_NAME,
                          "--out", out, "--quiet")
    assert code == 0 and err == "", err
    assert "the map's rule: right of way" in text
    frame, meta = read_pairs(out)
    assert meta["vehicle_tracks"] <= _meta(site)["tracks"]
    pairs = frame.groupby("pair").first()
    assert (pairs["kind"] == "crossing").any()
    start = {}
    for f in find_track_files([site]):
        t = read_interaction(f.path)
        firsts = t.groupby("track").first()
        for track, row in firsts.iterrows():
            if max(abs(row.x_m), abs(row.y_m)) > 20.0:  # seen arriving on an arm
                start[(t["recording"].iloc[0], track)] = _arm(row.x_m, row.y_m)
    checked = 0
    for _, p in pairs.iterrows():
        arms = (start.get((p.recording, p.track_1)), start.get((p.recording, p.track_2)))
        if None in arms:
            continue
        major = [a in "WE" for a in arms]
        if p.control == "right_of_way":
            # the map gives it only between the roads, and always to the major road's vehicle
            assert major[0] != major[1]
            assert major[p.priority - 1], (p.recording, p.track_1, p.track_2)
            checked += p.kind == "crossing"
        elif major[0] == major[1]:
            assert p.control == "none" and p.priority == 0
    assert checked >= 1


def test_the_same_seed_gives_the_same_files_byte_for_byte(site, tmp_path):
    again = tmp_path / "again"
    make_site(again, TINY)
    names = sorted(p.name for p in site.iterdir())
    assert names == sorted(p.name for p in again.iterdir())
    match, mismatch, errors = filecmp.cmpfiles(site, again, names, shallow=False)
    assert mismatch == [] and errors == [] and len(match) == 6


def test_track_numbering_view_and_centre_by_hand():
    """Vehicle 0 heads east, front at x = 10 + k, seen at frames 0-4 and 6-7 (a gap: a new
    track); vehicle 1 first seen at frame 2; vehicle 2 outside the view. Centre: 2 m (half of
    4 m) behind the front; psi 0 east; tracks numbered by first appearance."""
    buf = _Buffer()
    seen = [(0, f) for f in range(5)] + [(1, f) for f in range(2, 8)] + [(2, f) for f in
                                                                        range(8)]
    seen += [(0, 6), (0, 7)]
    seen.sort(key=lambda vf: (vf[1], vf[0]))
    for v, f in seen:
        buf.vehicle.append(v)
        buf.frame.append(f)
        buf.x.append({0: 10.0 + f, 1: -1.6, 2: 500.0}[v])
        buf.y.append({0: -1.6, 1: -20.0 + f, 2: 0.0}[v])
        buf.angle.append({0: 90.0, 1: 0.0, 2: 90.0}[v])
        buf.speed.append(10.0)
        buf.vtype.append(0 if v == 0 else 1)
    rows, veh = file_rows(buf, [(4.0, 1.8, "car"), (9.0, 2.5, "truck")], 60.0)
    assert list(rows) == list(INTERACTION_COLUMNS)
    assert rows["track_id"].tolist() == [1] * 5 + [2] * 6 + [3] * 2
    assert veh.tolist() == [0] * 5 + [1] * 6 + [0] * 2
    assert rows["frame_id"].tolist() == [1, 2, 3, 4, 5, 3, 4, 5, 6, 7, 8, 7, 8]
    assert rows["timestamp_ms"].tolist() == [(f - 1) * 100 for f in rows["frame_id"]]
    np.testing.assert_allclose(rows["x"][:5], [8.0, 9.0, 10.0, 11.0, 12.0], atol=1e-12)
    np.testing.assert_allclose(rows["y"][5:11], np.arange(2, 8) - 20.0 - 4.5, atol=1e-12)
    np.testing.assert_allclose(rows["psi_rad"][:5], 0.0, atol=1e-12)
    np.testing.assert_allclose(rows["psi_rad"][5:11], math.pi / 2, atol=1e-12)
    np.testing.assert_allclose(rows["vx"][:5], 10.0, atol=1e-12)
    assert rows["agent_type"][5:11].tolist() == ["truck"] * 6
    assert rows["length"][5] == 9.0 and rows["width"][5] == 2.5


def test_the_tracks_writer_writes_what_write_interaction_writes(tmp_path):
    rng = np.random.default_rng(3)
    n = 2000
    rows = {"track_id": np.repeat(np.arange(1, 21), 100),
            "frame_id": np.tile(np.arange(1, 101), 20),
            "timestamp_ms": np.tile(np.arange(100) * 100, 20),
            "agent_type": np.array(["car", "truck"] * (n // 2), dtype=object)}
    for c in ("x", "y", "vx", "vy", "psi_rad", "length", "width"):
        v = rng.normal(0.0, 40.0, n)
        rows[c] = np.where(np.abs(v) < 0.001, 0.5, v)  # away from "-0.000"
    write_tracks(tmp_path / "a.csv", rows)
    write_interaction(tmp_path / "b.csv", rows)
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()
    # a value that rounds to zero from below is written 0.000, not -0.000
    rows["x"][0] = -0.0002
    write_tracks(tmp_path / "c.csv", rows)
    assert (tmp_path / "c.csv").read_text().splitlines()[1].split(",")[4] == "0.000"


@pytest.mark.parametrize("kwargs,words", [
    ({"hours": 0.0}, "hours = 0.0 is out of range; allowed: (0, 24] hours"),
    ({"hours": 0.01, "files": 4}, "files = 4 is out of range; allowed: an integer in [1, 3]"),
    ({"lanes": 4}, "lanes = 4 is out of range; allowed: an integer in [1, 3]"),
    ({"seed": -1}, "seed = -1 is out of range"),
    ({"view_m": 290.0}, "view_m = 290.0 is out of range; allowed: [20, arm_m - 20 = 280] m"),
    ({"red_s": 50.0}, "red_s = 50.0 is out of range; allowed: [5, cycle_s - 13 = 47] s"),
    ({"minor_turns": (0.5, 0.5, 0.5)}, "minor_turns = (0.5, 0.5, 0.5) is out of range"),
])
def test_bad_parameters_are_refused_in_one_line(kwargs, words):
    with pytest.raises(RecordingError) as info:
        SiteParams(**kwargs)
    assert words in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("args,words", [
    (["--hours", "x"], "--hours = 'x' is not a number"),
    (["--hours", "30"], "--hours = 30.0 is out of range; allowed: (0, 24] hours"),
    (["--files", "1.5"], "--files = '1.5' is not an integer"),
    (["--lanes", "0"], "--lanes = 0 is out of range; allowed: an integer in [1, 3]"),
    (["--view-m", "5"], "--view-m = 5.0 is out of range"),
])
def test_the_benchmark_refuses_bad_arguments_in_one_line(tmp_path, args, words):
    out = tmp_path / "never"
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "site_recording.py"),
                           str(out), *args], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("site_recording.py")]
    assert len(lines) == 1 and words in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr and not out.exists()


def test_a_folder_in_use_is_refused_and_an_interrupted_run_leaves_nothing(tmp_path):
    used = tmp_path / "used"
    used.mkdir()
    (used / "notes.txt").write_text("mine\n")
    with pytest.raises(ConfigError, match="holds other files"):
        make_site(used, TINY)
    assert sorted(p.name for p in used.iterdir()) == ["notes.txt"]

    def stop(k, n):
        raise KeyboardInterrupt

    out = tmp_path / "interrupted"
    with pytest.raises(KeyboardInterrupt):
        make_site(out, TINY, progress=stop)
    assert not out.exists() and list(tmp_path.iterdir()) == [used]


def test_the_site_paired_file_by_file_is_the_site_paired_at_once(site, tmp_path):
    """``recordings pairs`` pairs each file on its own (on worker processes) and copies the
    parts into one file: the same rows, IDs, labels, metadata and summary as pairing every
    track at once (``find_pairs`` on the whole site, then ``write_pairs``), floats to
    rounding; one worker or two, the same file."""
    from dataclasses import asdict, replace

    import pandas as pd

    from persuasive.recordings.formats import read_tracks
    from persuasive.recordings.lanelet_map import annotate_pairs, read_map
    from persuasive.recordings.pairs import PairParams, find_pairs, summary, write_pairs
    from persuasive.recordings.streaming import pair_and_tracks, site_pairs
    from persuasive.recordings.tracks import SmoothingParams, smooth_tracks

    params, smoothing = PairParams(), SmoothingParams()
    road = read_map(site / MAP_NAME)
    whole = find_pairs(smooth_tracks(read_tracks([site]), smoothing), params)
    whole = replace(whole, pairs=annotate_pairs(whole.pairs, road),
                    road_map={"path": str(site / MAP_NAME), "origin": list(road.origin)})
    at_once = tmp_path / "at-once.parquet"
    write_pairs(at_once, whole, [site])
    frame_0, meta_0 = read_pairs(at_once)
    assert len(whole.pairs) > 10 and len(find_track_files([site])) == 2
    for workers in (1, 2):
        out = tmp_path / f"by-file-{workers}.parquet"
        got = site_pairs([site], params, smoothing, (str(site / MAP_NAME), (0.0, 0.0)), out,
                         workers)
        frame, meta = read_pairs(out)
        # the same rows; floats to rounding (the whole site's arc lengths are summed over
        # more tracks): s within 1e-10 m, times and PETs within 1e-12 s
        pd.testing.assert_frame_equal(frame, frame_0, check_exact=False, rtol=0, atol=1e-10)
        for col in frame.columns:
            if frame[col].dtype.kind not in "f":
                assert frame[col].equals(frame_0[col]), col
        assert meta == meta_0
        info, info_0 = got.summary, summary(whole)
        for key in ("pet_quantiles_s", "pet_area_quantiles_s"):
            assert info.pop(key) == pytest.approx(info_0.pop(key), rel=0, abs=1e-9)
        assert info == info_0
        assert list(tmp_path.iterdir()).count(out) == 1 and not [
            p for p in tmp_path.iterdir() if p.name.endswith(".parts")]  # scratch removed
    # a pair of the second file, found again for a figure, is the site's pair
    last = len(whole.pairs) - 1
    pair, tracks = pair_and_tracks(got, find_track_files([site]), last, params, smoothing,
                                   (str(site / MAP_NAME), (0.0, 0.0)))
    assert pair.pair == last and pair.tracks == whole.pairs[last].tracks
    assert asdict(pair)["pet_area_s"] == pytest.approx(asdict(whole.pairs[last])["pet_area_s"],
                                                       rel=0, abs=1e-9)
    # one worker or two: the same file, bit for bit
    one, _ = read_pairs(tmp_path / "by-file-1.parquet")
    two, _ = read_pairs(tmp_path / "by-file-2.parquet")
    pd.testing.assert_frame_equal(one, two, check_exact=True)
    assert tracks.n_tracks < whole.tracks.n_tracks
