"""The two post-encroachment times of recorded pairs (``persuasive.recordings.pairs``):
``pet_area_s`` at the conflict area, with the vehicles' lengths (Allen, Shin and Cooper 1978),
and ``pet_s`` on the occupancy intervals; the conflict area against a brute-force polygon
test; the pairs file, the summary and the command's printout with both, named.

Tolerances: straight noise-free tracks at constant speed are exact up to float rounding (the
Savitzky-Golay filter keeps cubics, the conflict point is the lines' exact crossing, times are
interpolated linearly in ``s``), so a PET worked out by hand is checked to 1e-9 s; a merge
point is found on the recorded samples, so a merge's PET is checked to 1e-9 s against the
pair's own steps and to 0.005 s against the hand figure from its passing times (the ramp's
smoothed corner bends its ``s``); the conflict area's extent against bisection over an exact
polygon-overlap test to 1e-9 m.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from test_recordings import pairs_of, straight, write

from persuasive.cli import cli
from persuasive.recordings.evaluate import pairs_of as eval_pairs_of
from persuasive.recordings.formats import RecordingError
from persuasive.recordings.pairs import (CROSSING, MERGE, PAIR_COLUMNS, conflict_area,
                                         post_encroachment, read_pairs, summary, write_pairs)


def crossing(tmp_path, t2_pass: float, *, v1: float = 10.0, v2: float = 10.0,
             size1=(4.5, 1.8), size2=(4.5, 1.8), angle_deg: float = 90.0, n1: int = 100,
             n2: int = 130):
    """The pair of vehicle 1 east along y = 0 at ``v1`` through the origin at 5 s and vehicle
    2 at ``angle_deg`` to it at ``v2`` through the origin at ``t2_pass`` [s]."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    d2 = v2 * t2_pass
    path = write(tmp_path / "vehicle_tracks_000.csv",
                 straight(1, (-5.0 * v1, 0.0), 0.0, [v1] * n1, length=size1[0],
                          width=size1[1]),
                 straight(2, (-d2 * c, -d2 * s), angle_deg, [v2] * n2, length=size2[0],
                          width=size2[1]))
    pairs = pairs_of(path).pairs
    assert len(pairs) == 1 and pairs[0].kind == CROSSING
    return pairs[0]


# -- the conflict area -----------------------------------------------------------------------


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two convex polygons (corners in order, ``(n, 2)``) overlap or touch: no edge
    normal of either separates them (the separating axis theorem)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        for nx, ny in np.stack([-edges[:, 1], edges[:, 0]], axis=1):
            pa, pb = a @ (nx, ny), b @ (nx, ny)
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


def _brute_area(angle_deg: float, lengths, widths) -> list[tuple[float, float]]:
    """Per vehicle, the centre positions where its footprint starts and stops overlapping the
    intersection of the two swept strips, by bisection over the polygon test."""
    th = math.radians(angle_deg)
    d = [np.array([1.0, 0.0]), np.array([math.cos(th), math.sin(th)])]
    n = [np.array([-u[1], u[0]]) for u in d]
    # the parallelogram: n_1 . p = +-w_1 / 2 and n_2 . p = +-w_2 / 2
    corners = [np.linalg.solve(np.stack([n[0], n[1]]), [e1 * widths[0] / 2, e2 * widths[1] / 2])
               for e1, e2 in ((1, 1), (1, -1), (-1, -1), (-1, 1))]
    area = np.array(corners)
    out = []
    for k in (0, 1):
        half_l, half_w = lengths[k] / 2, widths[k] / 2

        def touches(u, k=k, half_l=half_l, half_w=half_w):
            c = u * d[k]
            foot = np.array([c + sl * half_l * d[k] + sw * half_w * n[k]
                             for sl, sw in ((1, 1), (1, -1), (-1, -1), (-1, 1))])
            return _overlap(foot, area)

        def edge(inside, outside):
            for _ in range(200):
                mid = 0.5 * (inside + outside)
                inside, outside = (mid, outside) if touches(mid) else (inside, mid)
            return inside

        assert touches(0.0) and not touches(-500.0) and not touches(500.0)
        out.append((edge(0.0, -500.0), edge(0.0, 500.0)))
    return out


@pytest.mark.parametrize("angle_deg", [20.0, 45.0, 60.0, 90.0, 117.0, 160.0])
@pytest.mark.parametrize("lengths, widths", [((4.5, 4.5), (1.8, 1.8)),
                                             ((4.2, 12.0), (1.7, 2.55))])
def test_the_conflict_area_is_where_a_footprint_overlaps_both_swept_strips(angle_deg, lengths,
                                                                          widths):
    got = conflict_area(CROSSING, angle_deg, lengths, widths)
    want = _brute_area(angle_deg, lengths, widths)
    np.testing.assert_allclose(np.array(got), np.array(want), atol=1e-9)


def test_the_conflict_area_by_hand():
    def close(got, want):
        np.testing.assert_allclose(np.array(got), np.array(want), rtol=0.0, atol=1e-12)

    # right angles: the other's half width plus half the own length, each side
    close(conflict_area(CROSSING, 90.0, (4.5, 5.0), (1.8, 2.0)),
          ((-1.0 - 2.25, 1.0 + 2.25), (-0.9 - 2.5, 0.9 + 2.5)))
    # 60 degrees: (w_o / 2 + cos 60 w_k / 2) / sin 60, then half the length
    a1, a2 = (1.25 + 0.45) / math.sin(math.pi / 3), (0.9 + 0.625) / math.sin(math.pi / 3)
    want = ((-a1 - 2.25, a1 + 2.25), (-a2 - 6.0, a2 + 6.0))
    close(conflict_area(CROSSING, 60.0, (4.5, 12.0), (1.8, 2.5)), want)
    # 120 degrees (obtuse) reaches as far as 60
    close(conflict_area(CROSSING, 120.0, (4.5, 12.0), (1.8, 2.5)), want)
    # a merge: the merge point, a line across the lane; only the lengths count
    assert conflict_area(MERGE, 20.0, (4.5, 5.0), (1.8, 2.5)) == ((-2.25, 2.25), (-2.5, 2.5))
    # parallel strips: unbounded, never entered
    for angle in (0.0, 180.0):
        assert conflict_area(CROSSING, angle, (4.5, 4.5), (1.8, 1.8))[0] == (-math.inf, math.inf)


@pytest.mark.parametrize("args, words", [
    (("follow", 90.0, (4.5, 4.5), (1.8, 1.8)), "kind = 'follow' is not allowed; allowed: "
                                               "crossing, merge"),
    ((CROSSING, 200.0, (4.5, 4.5), (1.8, 1.8)), "angle_deg = 200.0 is out of range; allowed: "
                                                "[0, 180] degrees"),
    ((CROSSING, 90.0, (-4.5, 4.5), (1.8, 1.8)), "lengths_m = (-4.5, 4.5) is out of range"),
    ((MERGE, 20.0, (4.5, 4.5), (1.8, math.nan)), "widths_m = (1.8, nan) is out of range"),
])
def test_the_conflict_area_refuses_bad_input_in_one_line(args, words):
    with pytest.raises(RecordingError) as info:
        conflict_area(*args)
    assert words in str(info.value) and "\n" not in str(info.value)


# -- the PET of hand-made pairs --------------------------------------------------------------


def test_a_right_angle_crossing_clearing_the_area_2_s_before_the_other_arrives(tmp_path):
    # vehicle 1 (4.5 x 1.8 m) at 10 m/s: its rear leaves the area (1.0 m, vehicle 2's half
    # width, each side) at s = 1.0 + 2.25, at 5.325 s; vehicle 2 (5.0 x 2.0 m) at 8 m/s
    # through the point at 7.75 s: its front reaches the area (0.9 m each side) at s = -0.9 -
    # 2.5, at 7.75 - 3.4 / 8 = 7.325 s
    p = crossing(tmp_path, 7.75, v2=8.0, size2=(5.0, 2.0))
    assert p.angle_deg == pytest.approx(90.0, abs=1e-9)
    assert p.pet_area_s == pytest.approx(2.0, abs=1e-9)
    # wrong ones read otherwise: centres 2.75, own widths 1.9975, lengths swapped 2.00625
    # the occupancy intervals are wider than the area (both widths, margins): a smaller PET
    pet = (p.t_pass_s[1] + p.occupancy[1][0] / 8.0) - (5.0 + p.occupancy[0][1] / 10.0)
    assert p.pet_s == pytest.approx(pet, abs=1e-6) and p.pet_s < p.pet_area_s - 0.3


def test_an_oblique_crossing_reads_the_corners_of_the_own_width(tmp_path):
    # 60 degrees; vehicle 2, a 12 x 2.5 m bus, passes first at 3.0 s; vehicle 1 at 5.0 s
    p = crossing(tmp_path, 3.0, size2=(12.0, 2.5), angle_deg=60.0, n2=90)
    assert p.first == "2" and p.angle_deg == pytest.approx(60.0, abs=1e-9)
    sin = math.sin(math.pi / 3)
    a1, a2 = (1.25 + 0.5 * 0.9) / sin, (0.9 + 0.5 * 1.25) / sin
    leave_2 = 3.0 + (a2 + 6.0) / 10.0
    enter_1 = 5.0 - (a1 + 2.25) / 10.0
    assert p.pet_area_s == pytest.approx(enter_1 - leave_2, abs=1e-9)  # 0.8027 s
    # without the corners' term (the centre line within the other's half width) it would be
    # 0.134 s longer
    assert enter_1 - leave_2 == pytest.approx(0.8027, abs=1e-4)
    assert 0.0 < p.pet_s < p.pet_area_s


@pytest.mark.parametrize("t2_pass, pet_area", [(5.75, 0.12), (5.64, 0.01), (5.5, 0.0),
                                               (5.0, 0.0)])
def test_side_by_side_passages_read_zero_only_when_both_were_in_the_area(tmp_path, t2_pass,
                                                                          pet_area):
    # both 4.5 x 1.8 m at 10 m/s at right angles, vehicle 2 through the point t2_pass - 5 s
    # after vehicle 1: each is in the area while its centre is within 0.9 + 2.25 m of the
    # point, 0.315 s either side of its passing, so the area PET is t2_pass - 5 - 0.63 (0
    # below); the occupancy intervals (about 4.7 m each side) read 0 for all of them
    p = crossing(tmp_path, t2_pass)
    assert p.pet_area_s == pytest.approx(pet_area, abs=1e-9)
    assert p.pet_s == 0.0
    if pet_area > 0.0:
        # the centres stayed metres apart, never closer than 10 (t2_pass - 5) / sqrt(2)
        gap = np.hypot(p.x[0] - p.x[1], p.y[0] - p.y[1]).min()
        assert gap >= 10.0 * (t2_pass - 5.0) / math.sqrt(2.0) - 1e-9 and gap > 4.5


def test_a_first_vehicle_whose_track_ends_in_the_area(tmp_path):
    # vehicle 1's track ends at x = 1.0 (5.1 s), inside the area (up to 3.15): vehicle 2
    # arrives at 7.0 - 0.315 s, after that, so nobody saw it leave: NaN
    p = crossing(tmp_path, 7.0, n1=52)
    assert math.isnan(p.pet_area_s) and math.isnan(p.pet_s)
    # vehicle 2 arriving at 5.4 - 0.315 s, while vehicle 1 is still recorded inside: 0
    p = crossing(tmp_path, 5.4, n1=52)
    assert p.pet_area_s == 0.0 and p.pet_s == 0.0
    # vehicle 1's track ends at x = 4.0 (5.4 s): out of the area (its rear left at 5.315 s),
    # still in its occupancy interval: the area PET is known, the interval one is not
    p = crossing(tmp_path, 7.0, n1=55)
    assert p.pet_area_s == pytest.approx(2.0 - 0.63, abs=1e-9)
    assert math.isnan(p.pet_s)


def test_post_encroachment_by_hand():
    t = np.arange(0.0, 3.01, 0.1)
    s1, s2 = 10.0 * t - 10.0, 10.0 * t - 25.0  # at 0 at 1.0 s and at 2.5 s
    span = (-3.0, 3.0)
    # vehicle 1 leaves at 1.3 s, vehicle 2 enters at 2.2 s
    assert post_encroachment(t, s1, span, t, s2, span) == pytest.approx(0.9, abs=1e-12)
    assert post_encroachment(t, s2, span, t, s1, span) == pytest.approx(0.9, abs=1e-12)
    # one never enters while recorded: NaN, whoever it is
    assert math.isnan(post_encroachment(t, s1, span, t, s2 - 30.0, span))
    assert math.isnan(post_encroachment(t, s1 - 30.0, span, t, s2, span))
    # inside at its first sample: its entry is not seen, NaN
    assert math.isnan(post_encroachment(t, s1 + 8.0, span, t, s2, span))
    # both in at once: 0
    assert post_encroachment(t, s1, span, t, s1 - 2.0, span) == 0.0


def _merge_tracks(lane_at_merge_s: float):
    """The merge of test_recordings (a ramp at 20 degrees reaching the lane y = 0 at the
    origin, 9 m/s, 4.5 m long; its merge point, 1 m from the lane's centre line, at about
    5.2 s), with a 5 m lane vehicle at 10 m/s at about x = -2.75 at ``lane_at_merge_s``."""
    ramp_s = np.arange(0.0, 90.0, 0.9)
    c, s = math.cos(math.radians(20.0)), math.sin(math.radians(20.0))
    along = ramp_s - 50.0
    ramp = straight(3, (0.0, 0.0), 0.0, np.full(ramp_s.shape, 9.0))
    ramp["x"] = np.where(along < 0, along * c, along)
    ramp["y"] = np.where(along < 0, along * s, 0.0)
    lane = straight(7, (-2.75 - 10.0 * lane_at_merge_s, 0.0), 0.0, [10.0] * 130, length=5.0)
    return ramp, lane


@pytest.mark.parametrize("lane_at_merge_s, first", [(6.725, "1"), (3.5, "2"), (5.4, None)])
def test_a_merge_reads_the_merge_point_with_the_lengths(tmp_path, lane_at_merge_s, first):
    path = write(tmp_path / "vehicle_tracks_000.csv", *_merge_tracks(lane_at_merge_s))
    p = next(q for q in pairs_of(path).pairs if q.tracks == (3, 7))
    assert p.kind == MERGE
    # from the first one's rear passing the merge point (s = L / 2) to the other's front
    # reaching it (s = -L / 2), on the pair's own steps
    rear = [float(np.interp(length / 2.0, row, p.t)) for length, row in zip(p.lengths_m, p.s)]
    front = [float(np.interp(-length / 2.0, row, p.t)) for length, row in zip(p.lengths_m, p.s)]
    k = 0 if front[0] <= front[1] else 1
    assert p.pet_area_s == pytest.approx(max(front[1 - k] - rear[k], 0.0), abs=1e-9)
    # by hand from the passing times: the ramp's 4.5 m at 9 m/s and the lane vehicle's 5 m at
    # 10 m/s each take 0.25 s from the centre to the rear or the front (the centres' own gap
    # is 0.5 s longer; the ramp's smoothed corner, 2 m past its merge point, bends its s)
    if first is None:  # alongside at the merge point: both footprints on it at once
        assert p.pet_area_s == 0.0 and p.pet_s == 0.0
        return
    assert p.first == first
    t_first, t_second = sorted(p.t_pass_s)
    assert p.pet_area_s == pytest.approx(t_second - t_first - 0.5, abs=0.005)
    assert p.pet_area_s > 0.9 and p.pet_s < p.pet_area_s


# -- the file, the summary, the command -------------------------------------------------------


def _two_pairs(tmp_path):
    """Two recordings: a crossing with both PETs defined and one with neither."""
    a = write(tmp_path / "vehicle_tracks_000.csv",
              straight(1, (-50.0, 0.0), 0.0, [10.0] * 100),
              straight(2, (0.0, -62.0), 90.0, [8.0] * 120, length=5.0, width=2.0))
    b = write(tmp_path / "vehicle_tracks_001.csv",
              straight(1, (-50.0, 0.0), 0.0, [10.0] * 52),
              straight(2, (0.0, -70.0), 90.0, [10.0] * 130))
    return a, b


def test_the_pairs_file_carries_both_pets_and_reads_old_files(tmp_path):
    a, b = _two_pairs(tmp_path)
    result = pairs_of(a, b)
    assert [p.pet_area_s for p in result.pairs][0] == pytest.approx(2.0, abs=1e-9)
    assert math.isnan(result.pairs[1].pet_area_s)
    out = tmp_path / "pairs.parquet"
    write_pairs(out, result, [a, b])
    frame, _ = read_pairs(out)
    assert "pet_area_s" in PAIR_COLUMNS and list(frame.columns).index("pet_area_s") == \
        list(frame.columns).index("pet_s") + 1
    per_pair = frame.groupby("pair")[["pet_s", "pet_area_s"]].first()
    np.testing.assert_array_equal(per_pair["pet_area_s"].to_numpy(),
                                  [p.pet_area_s for p in result.pairs])
    np.testing.assert_array_equal(per_pair["pet_s"].to_numpy(), [p.pet_s for p in result.pairs])
    # the evaluation carries both, named
    data = eval_pairs_of(frame, "site", False)
    assert data[0].pet_area_s == pytest.approx(2.0, abs=1e-9)
    assert data[0].pet_s == result.pairs[0].pet_s
    # a file written before the column: read, the column NaN in its place
    table = pq.read_table(out)
    old = tmp_path / "old.parquet"
    pq.write_table(table.drop(["pet_area_s"]), old)
    frame_old, _ = read_pairs(old)
    assert list(frame_old.columns) == list(frame.columns)
    assert frame_old["pet_area_s"].isna().all()
    assert math.isnan(eval_pairs_of(frame_old, "site", False)[0].pet_area_s)


def test_the_summary_and_the_command_give_both_pets_named(tmp_path):
    a, b = _two_pairs(tmp_path)
    info = summary(pairs_of(a, b))
    assert info["pet_area_defined"] == 1 and info["pet_defined"] == 1
    assert info["pet_area_quantiles_s"]["50%"] == pytest.approx(2.0, abs=1e-9)
    assert info["pet_quantiles_s"]["50%"] < 2.0 - 0.3
    runner = CliRunner()
    result = runner.invoke(cli, ["recordings", "pairs", a, b])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    area = next(x for x in lines if x.startswith("PET at the conflict area (pet_area_s)"))
    assert area == "PET at the conflict area (pet_area_s) [s] over 1 pairs: 5% 2.00, " \
                   "25% 2.00, 50% 2.00, 75% 2.00, 95% 2.00"
    assert any(x.startswith("PET on the occupancy intervals (pet_s) [s] over 1 pairs: ")
               for x in lines)
    result = runner.invoke(cli, ["recordings", "pairs", b])
    assert "PET at the conflict area (pet_area_s): defined for no pair" in result.output
    assert "PET on the occupancy intervals (pet_s): defined for no pair" in result.output
    info = json.loads(runner.invoke(cli, ["recordings", "pairs", a, "--json"]).output)
    assert info["pet_area_quantiles_s"]["5%"] == pytest.approx(2.0, abs=1e-9)


def test_the_pair_figure_names_both_pets(tmp_path):
    from persuasive.plots.recordings import pair_figure
    from persuasive.recordings.formats import read_tracks
    from persuasive.recordings.tracks import smooth_tracks

    p = crossing(tmp_path, 7.75, v2=8.0, size2=(5.0, 2.0))
    tracks = smooth_tracks(read_tracks([str(tmp_path)]))
    title = pair_figure(p, tracks).axes[0].get_title()
    assert f"PET at the area {p.pet_area_s:.2f} s" in title
    assert f"on the intervals {p.pet_s:.2f} s" in title and "2.00 s" in title
