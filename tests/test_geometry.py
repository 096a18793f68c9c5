"""Paths, conflicts and scenarios (``persuasive.geometry``, ``persuasive.scenarios``).

Hand-computed path positions; distance invariants; the distance of every scenario equal to an
independent computation from the logged positions; the crossing at 90 degrees equal to the
paper's intersection per step, bit for bit, also through the euclidean kernels; footprint
collisions; occupancy intervals and zones equal to the plain all-pairs computation, bit for
bit; known games in the merge; each scenario's closed loop equal to the plain NumPy
reference, bit for bit.

Tolerances: path positions 1e-12 m (trigonometry); everything else exact.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive import Config, ConfigError, reference, simulate
from persuasive import packing as slot
from persuasive.game import full_prediction
from persuasive.geometry import (Path, VehicleShape, _first_hit, _radius, _samples,
                                 _straight_occupancy, footprints_overlap, occupancy_interval,
                                 unit, zone_interval)
from persuasive.packing import discounts, pack
from persuasive.scenarios import SCENARIOS, build_scenario, crossing

CAR = VehicleShape(5.0, 2.5, 0.0, 10.0, -2.0, 1.0)
SCENARIO_CONFIGS = {
    "intersection": Config(),
    "crossing": Config().with_overrides({"scenario.kind": "crossing", "scenario.angle_deg": 60.0}),
    "left-turn": Config().with_overrides({"scenario.kind": "left-turn"}),
    "merge": Config().with_overrides({"scenario.kind": "merge"}),
}


# -- paths by hand ------------------------------------------------------------------------------


def test_straight_path_is_exact_on_the_axes():
    path = Path.straight(CAR, (0.0, 0.0), (0.0, 1.0))
    x, y = path.xy(np.array([-20.0, -6.5, 0.0, 3.25]))
    np.testing.assert_array_equal(x, 0.0)
    np.testing.assert_array_equal(y, [-20.0, -6.5, 0.0, 3.25])
    np.testing.assert_array_equal(path.heading([-1.0, 5.0]), math.pi / 2)


def test_bend_changes_direction_at_its_point():
    ramp = Path.bend(CAR, (0.0, 0.0), unit(30.0), (1.0, 0.0))
    x, y = ramp.xy(np.array([-10.0, 0.0, 10.0]))
    np.testing.assert_allclose(x, [-10 * math.cos(math.radians(30)), 0.0, 10.0], atol=1e-12)
    np.testing.assert_allclose(y, [-5.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(ramp.heading([-1.0, 1.0]), [math.radians(30), 0.0], atol=1e-12)


def test_left_turn_arc_by_hand():
    # heading north at (2, -4), radius 6, a quarter turn left: centre (-4, -4)
    path = Path.turn(CAR, (2.0, -4.0), math.pi / 2, 6.0, math.pi / 2, s_start=-5.0)
    quarter = 6.0 * math.pi / 2
    x, y = path.xy(np.array([-7.0, -5.0, -5.0 + quarter / 2, -5.0 + quarter, -5.0 + quarter + 3]))
    r = 6.0 / math.sqrt(2)
    np.testing.assert_allclose(x, [2.0, 2.0, -4.0 + r, -4.0, -7.0], atol=1e-12)
    np.testing.assert_allclose(y, [-6.0, -4.0, -4.0 + r, 2.0, 2.0], atol=1e-12)
    ux, uy = path.direction(np.array([-6.0, -5.0 + quarter / 2, 100.0]))
    np.testing.assert_allclose(ux, [0.0, -1 / math.sqrt(2), -1.0], atol=1e-12)
    np.testing.assert_allclose(uy, [1.0, 1 / math.sqrt(2), 0.0], atol=1e-12)


def test_unit_is_exact_at_right_angles():
    assert [unit(a) for a in (0.0, 90.0, 180.0, 270.0)] == [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0),
                                                           (0.0, -1.0)]


# -- distances ----------------------------------------------------------------------------------


@settings(max_examples=60)
@given(st.floats(-40, 40), st.floats(-40, 40), st.sampled_from(list(SCENARIO_CONFIGS)))
def test_distance_is_symmetric_in_the_vehicles_and_never_negative(s_a, s_b, kind):
    scene = build_scenario(SCENARIO_CONFIGS[kind])
    d = scene.distance(s_a, s_b)
    assert d >= 0.0
    # the same geometry seen with the roles of the paths swapped
    if scene.conflict == slot.CONFLICT_ALONG_PATHS:
        assert d == math.sqrt(s_b * s_b + s_a * s_a)
    else:
        xa, ya = scene.av.xy(s_a)
        xh, yh = scene.hv.xy(s_b)
        assert d == math.sqrt((xh - xa) ** 2 + (yh - ya) ** 2)


@settings(max_examples=60)
@given(st.floats(-40, 40), st.floats(-40, 40), st.floats(15.0, 165.0))
def test_a_crossing_is_at_distance_zero_only_at_its_conflict_point(s_a, s_b, angle):
    scene = build_scenario(Config().with_overrides({"scenario.kind": "crossing",
                                                    "scenario.angle_deg": angle}))
    d = float(scene.distance(s_a, s_b))
    # two straight lines through the origin at an angle: |d| >= |s_a| sin(angle) etc.
    bound = max(abs(s_a), abs(s_b)) * math.sin(math.radians(angle))
    assert d >= bound - 1e-9
    assert scene.distance(0.0, 0.0) == 0.0


@pytest.mark.parametrize("kind", list(SCENARIO_CONFIGS))
def test_logged_distance_equals_the_logged_positions(kind):
    for seed in (1, 2):
        r = simulate(SCENARIO_CONFIGS[kind], seed)
        log = r.log
        if r.scenario.conflict == slot.CONFLICT_ALONG_PATHS:
            expected = np.sqrt(log["av_s_m"] ** 2 + log["hv_s_m"] ** 2)
        else:
            expected = np.hypot(log["av_x_m"] - log["hv_x_m"], log["av_y_m"] - log["hv_y_m"])
        np.testing.assert_allclose(log["distance_m"], expected, rtol=0, atol=1e-12)
        # the headings are the paths' directions at the logged positions
        for who in ("av", "hv"):
            path = getattr(r.scenario, who)
            np.testing.assert_array_equal(log[f"{who}_heading_rad"], path.heading(log[f"{who}_s_m"]))


@pytest.mark.parametrize("kind", ["crossing", "merge"])
def test_zone_is_conservative(kind):
    scene = build_scenario(SCENARIO_CONFIGS[kind])
    for who, other in (("av", "hv"), ("hv", "av")):
        path, opath = getattr(scene, who), getattr(scene, other)
        lo, hi = path.zone
        s = np.concatenate([np.linspace(end, end + 30 * side, 300)
                            for end, side in ((lo, -1), (hi, 1)) if math.isfinite(end)])
        pts = opath.polyline(-150, 150, 0.005)
        x, y = path.xy(s)
        d = np.min(np.hypot(x[:, None] - pts[None, :, 0], y[:, None] - pts[None, :, 1]), axis=1)
        assert np.all(d >= scene.min_dist_m - 0.005), who  # outside the zone: never too close


def test_zone_interval_of_a_right_angle_is_min_dist_wide():
    a = Path.straight(CAR, (0.0, 0.0), (1.0, 0.0))
    b = Path.straight(CAR, (0.0, 0.0), (0.0, 1.0))
    lo, hi = zone_interval(a, b, 7.5)
    assert -7.6 < lo < -7.5 and 7.5 < hi < 7.6


# -- the crossing at 90 degrees is the paper's intersection --------------------------------------


@pytest.mark.parametrize("mode", ["paper", "corrected"])
def test_crossing_at_90_is_the_intersection_bit_for_bit(mode, monkeypatch):
    base = Config(mode=mode)
    at_90 = base.with_overrides({"scenario.kind": "crossing", "scenario.angle_deg": 90.0})
    for seed in (1, 7, 24):
        ref = simulate(base, seed)
        np.testing.assert_array_equal(simulate(at_90, seed).states, ref.states)
    # and through the euclidean kernels (distances between centres on the paths)
    monkeypatch.setitem(SCENARIOS, "crossing",
                        lambda c: crossing.build(c, perpendicular_at_90=False))
    import persuasive.record as sim

    sim.static_setup.cache_clear()
    try:
        assert build_scenario(at_90).conflict == slot.CONFLICT_EUCLIDEAN
        for seed in (1, 7, 24):
            ref = simulate(base, seed)
            got = simulate(at_90, seed)
            np.testing.assert_array_equal(got.states, ref.states)
            for key in ("av_trajectory", "av_feasible", "av_p_safe_min", "hv_trajectory"):
                np.testing.assert_array_equal(got.log[key], ref.log[key])
    finally:
        sim.static_setup.cache_clear()


# -- footprints ---------------------------------------------------------------------------------


@settings(max_examples=100)
@given(st.floats(-10, 10), st.floats(-10, 10))
def test_footprint_test_at_the_intersection_is_the_papers(s_av, s_hv):
    scene = build_scenario(Config())
    paper = abs(s_av) <= 3.75 and abs(s_hv) <= 3.75
    assert bool(scene.collides(s_av, s_hv)) == paper


def test_oriented_rectangles_by_hand():
    one = (np.array(1.0), np.array(0.0))
    diag = (np.array(math.sqrt(0.5)), np.array(math.sqrt(0.5)))
    # a 5 x 2.5 box along x at the origin and one rotated by 45 degrees
    # centred 4.5 m away along x: its nearest corner reaches 4.5 - 2.652 = 1.848 < 2.5
    assert footprints_overlap(0.0, 0.0, one, 5.0, 2.5, 4.5, 0.0, diag, 5.0, 2.5)
    assert not footprints_overlap(0.0, 0.0, one, 5.0, 2.5, 5.2, 0.0, diag, 5.0, 2.5)
    # the same pair the other way round
    assert footprints_overlap(4.5, 0.0, diag, 5.0, 2.5, 0.0, 0.0, one, 5.0, 2.5)
    # side by side in parallel lanes 2.5 m apart touch; 2.6 m apart do not
    assert footprints_overlap(0.0, 0.0, one, 5.0, 2.5, 0.0, 2.5, one, 5.0, 2.5)
    assert not footprints_overlap(0.0, 0.0, one, 5.0, 2.5, 0.0, 2.6, one, 5.0, 2.5)


# -- occupancy intervals ------------------------------------------------------------------------


def _occupancy_reference(path, other, other_range=(-math.inf, math.inf), step_m=0.05,
                         reach_m=150.0):
    """:func:`occupancy_interval` the straightforward way (its code at db4acd3): every pair
    of samples within reach tested, the hull of the own positions found."""
    from scipy.spatial import cKDTree

    if path.is_straight and other.is_straight and other_range == (-math.inf, math.inf):
        return _straight_occupancy(path, other)
    s_own = _samples(path, -reach_m, reach_m, step_m)
    lo_o, hi_o = max(other_range[0], -reach_m), min(other_range[1], reach_m)
    s_oth = _samples(other, lo_o, hi_o, step_m)
    m_own = step_m / 2 * (1.0 + path.half_diagonal_m / _radius(path))
    m_oth = step_m / 2 * (1.0 + other.half_diagonal_m / _radius(other))
    reach = path.half_diagonal_m + other.half_diagonal_m + m_own + m_oth
    xo, yo = path.xy(s_own)
    xt, yt = other.xy(s_oth)
    own_pts, oth_pts = np.stack([xo, yo], axis=1), np.stack([xt, yt], axis=1)
    keep_o = cKDTree(oth_pts).query(own_pts, distance_upper_bound=reach)[0] <= reach
    keep_t = cKDTree(own_pts).query(oth_pts, distance_upper_bound=reach)[0] <= reach
    if not keep_o.any() or not keep_t.any():
        return (math.inf, math.inf)
    edge_lo, edge_hi = bool(keep_o[0]), bool(keep_o[-1])
    s_own, xo, yo = s_own[keep_o], xo[keep_o], yo[keep_o]
    s_oth, xt, yt = s_oth[keep_t], xt[keep_t], yt[keep_t]
    near = cKDTree(np.stack([xt, yt], axis=1)).query_ball_point(np.stack([xo, yo], axis=1),
                                                                reach)
    counts = np.fromiter((len(n) for n in near), dtype=np.int64, count=len(near))
    if counts.sum() == 0:
        return (math.inf, math.inf)
    i = np.repeat(np.arange(s_own.size), counts)
    j = np.concatenate([np.asarray(n, dtype=np.int64) for n in near if n])
    va, vb = path.vehicle, other.vehicle
    hit = footprints_overlap(xo[i], yo[i], path.direction(s_own[i]), va.length_m + 2 * m_own,
                             va.width_m + 2 * m_own, xt[j], yt[j], other.direction(s_oth[j]),
                             vb.length_m + 2 * m_oth, vb.width_m + 2 * m_oth)
    if not hit.any():
        return (math.inf, math.inf)
    found = s_own[i[hit]]
    lo = float(found.min()) - step_m / 2
    hi = float(found.max()) + step_m / 2
    return (-math.inf if edge_lo and found.min() == s_own[0] else lo,
            math.inf if edge_hi and found.max() == s_own[-1] else hi)


_coord = st.floats(-8.0, 8.0)
_angle = st.floats(-math.pi, math.pi)


@st.composite
def _paths(draw):
    """A straight path, a bend (a kink) or a turn (an arc), near the origin, of a vehicle of
    any size from a motorbike's to a truck's."""
    car = VehicleShape(draw(st.floats(2.0, 12.0)), draw(st.floats(0.8, 3.0)), 0.0, 10.0, -2.0,
                       1.0)
    point = (draw(_coord), draw(_coord))
    kind = draw(st.sampled_from(["straight", "bend", "turn"]))
    before = draw(_angle)
    if kind == "straight":
        return Path.straight(car, point, (math.cos(before), math.sin(before)))
    if kind == "bend":
        after = draw(_angle)
        return Path.bend(car, point, (math.cos(before), math.sin(before)),
                         (math.cos(after), math.sin(after)))
    turn = draw(st.floats(0.1, 3.0)) * draw(st.sampled_from([-1.0, 1.0]))
    return Path.turn(car, point, before, draw(st.floats(2.0, 40.0)), turn,
                     draw(st.floats(-15.0, 5.0)))


@st.composite
def _ranges(draw):
    kind = draw(st.sampled_from(["all", "all", "below", "above", "window"]))
    a, b = sorted((draw(st.floats(-45.0, 45.0)), draw(st.floats(-45.0, 45.0))))
    return {"all": (-math.inf, math.inf), "below": (-math.inf, b), "above": (a, math.inf),
            "window": (a, b + 0.01)}[kind]


@settings(max_examples=150)
@given(_paths(), _paths(), _ranges(), st.sampled_from([0.05, 0.1, 0.25]))
def test_occupancy_interval_equals_the_all_pairs_reference(path, other, other_range, step_m):
    """The occupancy interval scans from both ends for the first sample with a hit; the
    result is the reference's, every bit, whichever paths (straight, kinked, arcs), sizes,
    ranges of the other and sample spacings (exact)."""
    reach_m = 40.0
    got = occupancy_interval.__wrapped__(path, other, other_range, step_m, reach_m)
    assert got == _occupancy_reference(path, other, other_range, step_m, reach_m)


@settings(max_examples=300)
@given(st.sets(st.integers(0, 299), max_size=6), st.integers(0, 300), st.integers(0, 300),
       st.booleans(), st.sampled_from([None, 1.0, 0.5]))
def test_the_scan_from_an_end_finds_the_first_row_with_a_hit(rows_hit, a, b, upward, clear):
    """:func:`persuasive.geometry._first_hit` against ``min`` / ``max``: any rows with a hit
    (a single one at a block's edge too), any range, with or without rows passed over (all or
    half the rows up to the next hit, as ``zone_interval``'s distances tell); every row asked
    once at most, none outside the range (exact)."""
    lo, hi = min(a, b), max(a, b)
    asked = []

    def hits(rows):
        asked.extend(rows.tolist())
        return rows[np.isin(rows, list(rows_hit))]

    def clear_rows(row, up):
        ahead = [abs(r - row) for r in rows_hit if (r >= row if up else r <= row)]
        return int(clear * min(ahead, default=1000))

    inside = [r for r in rows_hit if lo <= r < hi]
    expected = (min(inside) if upward else max(inside)) if inside else None
    assert _first_hit(hits, lo, hi, upward, clear_rows if clear else None) == expected
    assert len(asked) == len(set(asked)) and all(lo <= r < hi for r in asked)
    if expected is None and clear is None:
        assert sorted(asked) == list(range(lo, hi))


@pytest.mark.parametrize("x0, lo", [(-6.2, -math.inf), (-6.1, -9.95), (-6.0, -9.85)])
def test_occupancy_is_unbounded_only_where_the_scan_ends_inside_an_overlap(x0, lo):
    """A car along x scanned from -10 m every 0.1 m; a crossing car at ``x = x0`` (a window of
    1 cm of its path): the footprints, enlarged by 5 cm, overlap while
    ``|x - x0| <= 3.85 m``. Whether the first sample, -10 m, overlaps (x0 = -6.2) or only the
    next (-6.1) or the one after (-6.0), both within reach: by hand, 1e-12 m, and equal to
    the reference (exact)."""
    own = Path.straight(CAR, (0.0, 0.0), (1.0, 0.0))
    other = Path.straight(CAR, (x0, 0.0), (0.0, 1.0))
    got = occupancy_interval.__wrapped__(own, other, (0.0, 0.01), 0.1, 10.0)
    assert got == _occupancy_reference(own, other, (0.0, 0.01), 0.1, 10.0)
    assert got[0] == pytest.approx(lo, abs=1e-12)
    assert got[1] == pytest.approx(x0 + 3.8 + 0.05, abs=1e-12)  # the last sample in, + 5 cm


def _zone_reference(path, other, min_dist_m, reach_m=150.0, step_m=0.01):
    """:func:`zone_interval` the straightforward way (its code at db4acd3): every sample's
    nearest distance."""
    from scipy.spatial import cKDTree

    pts_other = other.polyline(-reach_m, reach_m, step_m)
    s = np.arange(-reach_m, reach_m + step_m / 2, step_m)
    x, y = path.xy(s)
    margin = 2.0 * step_m
    d, _ = cKDTree(pts_other, compact_nodes=False).query(
        np.stack([x, y], axis=1), distance_upper_bound=2.0 * (min_dist_m + margin))
    inside = np.flatnonzero(d < min_dist_m + margin)
    if inside.size == 0:
        return (math.inf, math.inf)
    lo = -math.inf if inside[0] == 0 else float(s[inside[0]] - margin)
    hi = math.inf if inside[-1] == s.size - 1 else float(s[inside[-1]] + margin)
    return lo, hi


@settings(max_examples=100)
@given(_paths(), _paths(), st.floats(0.5, 12.0), st.sampled_from([0.01, 0.05]))
def test_zone_interval_equals_the_every_sample_reference(path, other, min_dist_m, step_m):
    """The zone scans from both ends, passing over samples known to be far; the result is the
    reference's, every bit (exact)."""
    got = zone_interval.__wrapped__(path, other, min_dist_m, 40.0, step_m)
    assert got == _zone_reference(path, other, min_dist_m, 40.0, step_m)


@pytest.mark.parametrize("x0, lo", [(-4.985, -math.inf), (-4.975, -10.01)])
def test_zone_is_unbounded_only_where_the_scan_ends_inside(x0, lo):
    """A path along x scanned from -10 m every 1 cm; a crossing path at ``x = x0``: the samples
    within 5 m + 2 cm (the margin) are inside. Whether the first sample is (x0 = -4.985) or
    only the next (-4.975): by hand, 1e-12 m, and equal to the reference (exact)."""
    own = Path.straight(CAR, (0.0, 0.0), (1.0, 0.0))
    other = Path.straight(CAR, (x0, 0.0), (0.0, 1.0))
    got = zone_interval.__wrapped__(own, other, 5.0, 10.0)
    assert got == _zone_reference(own, other, 5.0, 10.0)
    assert got[0] == pytest.approx(lo, abs=1e-12)


@pytest.mark.parametrize("kind", ["crossing", "left-turn", "merge"])
def test_scenario_occupancies_equal_the_all_pairs_reference(kind):
    """At each scenario's own paths and full range (merge: the HV's against the AV's side
    zone), also with the shield's enlarged footprints, and the zones at the scenario's
    distance (exact)."""
    scene = build_scenario(SCENARIO_CONFIGS[kind])
    side = (scene.av.occupancy[0], 0.0) if kind == "merge" else (-math.inf, math.inf)
    for av, hv in ((scene.av, scene.hv), (scene.av.inflated(0.25), scene.hv.inflated(0.25))):
        for path, other, other_range in ((av, hv, (-math.inf, math.inf)), (hv, av, side)):
            got = occupancy_interval.__wrapped__(path, other, other_range)
            assert got == _occupancy_reference(path, other, other_range)
    for path, other in ((scene.av, scene.hv), (scene.hv, scene.av)):
        got = zone_interval.__wrapped__(path, other, scene.min_dist_m)
        assert got == _zone_reference(path, other, scene.min_dist_m)


# -- scenario templates -------------------------------------------------------------------------


def test_scenarios_place_lines_zones_and_starts():
    inter = build_scenario(Config())
    assert inter.av.yield_s == inter.av.first_s == -6.5
    assert inter.nominal_s0("av") == inter.nominal_s0("hv") == -20.0
    merge = build_scenario(SCENARIO_CONFIGS["merge"])
    assert merge.lane_shared and merge.av.first_s == merge.hv.first_s == 0.0
    assert merge.av.zone[1] == math.inf  # the lane is shared after the merge point
    # computed numerically, widened by its sampling margin
    assert merge.av.zone[0] == pytest.approx(-7.5 / math.sin(math.radians(30)), abs=0.1)
    assert merge.av.zone[0] < -7.5 / math.sin(math.radians(30))  # and conservative
    left = build_scenario(SCENARIO_CONFIGS["left-turn"])
    x, y = left.av.xy(0.0)
    xh, yh = left.hv.xy(0.0)
    assert (float(x), float(y)) == pytest.approx((float(xh), float(yh)), abs=1e-12)  # s = 0 meet
    # every scenario's vehicles can start: the draws are outside the zones
    for config in SCENARIO_CONFIGS.values():
        for seed in range(1, 6):
            r = simulate(config.with_overrides({"simulation.n_steps": 1}), seed)
            assert r.hv_initial_state[0] < r.scenario.hv.zone[0]


def test_impossible_starts_are_a_clear_error():
    with pytest.raises(ConfigError, match=r"scenario.hv_s0_m = -7 .* inside its conflict zone"):
        build_scenario(Config().with_overrides({"scenario.hv_s0_m": -7.0,
                                                "scenario.hv_s0_halfwidth_m": 0.2}))
    with pytest.raises(ConfigError, match="scenario.angle_deg"):
        Config().with_overrides({"scenario.kind": "merge", "scenario.angle_deg": 120.0})
    with pytest.raises(ConfigError, match="turn_radius_m"):
        build_scenario(Config().with_overrides({"scenario.kind": "left-turn",
                                                "scenario.turn_radius_m": 3.0}))


# -- games in the merge whose answer is known ---------------------------------------------------


def _merge_game(x_av, x_hv, **overrides):
    config = SCENARIO_CONFIGS["merge"].with_overrides(overrides)
    P_av, P_hv = pack(config, build_scenario(config))
    return full_prediction(x_hv, x_av, P_hv, P_av, discounts(config)), P_av


def test_merge_without_conflict_both_take_full_progress():
    # the HV far ahead on the shared lane, the AV far back on the ramp: nothing can collide,
    # so whatever the roles both take their most progressive trajectory
    pred, _ = _merge_game(x_av=(-60.0, 4.0), x_hv=(40.0, 4.0))
    top = pred.ego.n_traj - 1
    assert (pred.ego_leader, pred.ego_follower, pred.other_leader, pred.other_follower) == (
        top, top, top, top)


def test_merge_blocked_by_a_standing_vehicle_the_ramp_vehicle_holds_back():
    # the HV stands on the merge point and can barely move (its own limits): every AV
    # trajectory that reaches the merge collides, and the AV's answer in either role keeps
    # its distance (its stop trajectory ends at its yield line, 15 m before the merge)
    pred, P_av = _merge_game(x_av=(-30.0, 4.0), x_hv=(0.0, 0.0),
                             **{"hv.vehicle.u_max_mps2": 1e-3})
    scene = build_scenario(SCENARIO_CONFIGS["merge"])
    for idx in (pred.other_leader, pred.other_follower):
        s = pred.other.s[idx]
        assert np.all(scene.distance(s, 0.0) >= scene.min_dist_m)


# -- closed loops against the reference ---------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["crossing", "left-turn", "merge"])
@pytest.mark.parametrize("mode", ["paper", "corrected"])
def test_scenario_closed_loop_equals_reference(kind, mode):
    config = SCENARIO_CONFIGS[kind].with_overrides({"mode": mode, "simulation.n_steps": 12})
    for av in ("persuasive", "lfg"):
        c = config.with_overrides({"av.kind": av})
        fast, ref = simulate(c, 3), reference.simulate(c, 3)
        np.testing.assert_array_equal(fast.states, ref["states"])
