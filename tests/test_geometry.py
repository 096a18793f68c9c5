"""Paths, conflicts and scenarios (``persuasive.geometry``, ``persuasive.scenarios``).

Hand-computed path positions; distance invariants; the distance of every scenario equal to an
independent computation from the logged positions; the crossing at 90 degrees equal to the
paper's intersection per step, bit for bit, also through the euclidean kernels; footprint
collisions; known games in the merge; each scenario's closed loop equal to the plain NumPy
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
from persuasive.geometry import Path, VehicleShape, footprints_overlap, unit, zone_interval
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
