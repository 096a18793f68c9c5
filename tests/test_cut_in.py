"""The shield's cut-in rule in a shared lane and the fault it decides (docs/method.md §12.10).

Layers: the rule against RSS's closed-form safe distance where that form holds (equal or
harder braking behind, no speed limit reached); the exact check against a brute-force time grid
on small random cases, including those the closed form gets wrong; the shield's verdicts in the
lane; the fault of a rear-end on hand-made runs; and closed loops in the merge.
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from persuasive import Config
from persuasive.config import ConfigError
from persuasive.kinematics import saturated_step
from persuasive.record import static_setup
from persuasive.safety import measures
from persuasive.safety import shield as sh
from persuasive.simulation import simulate


def merge_conflict(**over) -> tuple[np.ndarray, object]:
    config = Config(mode="corrected").with_overrides({"scenario.kind": "merge", **over})
    scenario, P_av, P_hv, _ = static_setup(config)
    C = np.empty(sh.N_CONFLICT)
    sh.conflict_vector(P_av, P_hv, C)
    return C, scenario


def rule(C, rho, acc, brake, front, v_max=60.0):
    """``C`` with the rule's values and speed limits far away (no saturation but at 0)."""
    C = C.copy()
    C[sh.C_RESP_RHO], C[sh.C_RESP_ACCEL], C[sh.C_RESP_BRAKE], C[sh.C_RESP_FRONT] = (
        rho, acc, brake, front)
    C[sh.C_R_VMAX] = C[sh.C_H_VMAX] = v_max
    return C


def rss_distance(v_rear, v_front, rho, acc, brake, front):
    """RSS's safe longitudinal distance (Shalev-Shwartz et al. 2017, Definition 1)."""
    v_r = v_rear + rho * acc
    return max(0.0, v_rear * rho + 0.5 * acc * rho ** 2 + v_r ** 2 / (2 * brake)
               - v_front ** 2 / (2 * front))


def fair_now(C, v_R, s_H, v_H):
    """The rule for an AV at the merge point now (``t_0 = 0``)."""
    return sh.cut_in_fair(C[sh.C_R_HI], v_R, 0.0, 0.1, 0.0, math.inf, 0.0, 0.0, s_H, v_H, C)


def smallest_fair_gap(C, v_R, v_H):
    """The bumper gap at which the rule starts to hold, by bisection on the human's place."""
    L = C[sh.C_GAP]
    lo, hi = 0.0, 500.0  # gaps: unfair at lo, fair at hi
    assert fair_now(C, v_R, C[sh.C_R_HI] - L - hi, v_H)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if fair_now(C, v_R, C[sh.C_R_HI] - L - mid, v_H):
            hi = mid
        else:
            lo = mid
    return hi


@pytest.mark.parametrize("v_H, v_R, rho, acc, brake, front", [
    (13.9, 0.0, 1.0, 0.0, 4.5, 4.5),   # the issue's example: 13.9 m/s, 1 s, 4.5 m/s^2
    (10.0, 4.0, 1.0, 1.0, 2.0, 2.0),   # the paper's vehicles
    (8.0, 8.0, 0.5, 2.0, 3.0, 6.0),    # the front brakes harder than the rear
    (5.0, 9.0, 2.0, 0.0, 4.0, 4.0),    # the AV faster than the follower
])
def test_the_rule_is_rss_where_the_closed_form_holds(v_H, v_R, rho, acc, brake, front):
    C = rule(merge_conflict()[0], rho, acc, brake, front)
    expected = rss_distance(v_H, v_R, rho, acc, brake, front)
    assert smallest_fair_gap(C, v_R, v_H) == pytest.approx(expected, abs=1e-5)


def test_the_issues_example_is_about_35_m():
    C = rule(merge_conflict()[0], 1.0, 0.0, 4.5, 4.5)
    assert smallest_fair_gap(C, 0.0, 13.9) == pytest.approx(13.9 + 13.9 ** 2 / 9.0, abs=1e-5)


def positions(s, v, a, t, v_min, v_max):
    """Positions at times ``t`` (an array) holding ``a`` from ``(s, v)``, the speed saturating
    at ``v_min``/``v_max`` (the closed loop's kinematics, written out for arrays)."""
    if a == 0.0:
        return s + v * t
    v_lim = v_max if a > 0.0 else v_min
    t_sat = (v_lim - v) / a
    free = s + v * t + 0.5 * a * t * t
    held = s + (v_lim * v_lim - v * v) / (2.0 * a) + v_lim * (t - t_sat)
    return np.where(t <= t_sat, free, held)


def brute_min_gap(C, s_R, v_R, s_H, v_H, step=1e-3, horizon=40.0):
    """The smallest bumper-to-bumper gap on a fine time grid: the AV braking at the rule's
    front braking from now, the human holding its rule acceleration for rho, then braking."""
    L = C[sh.C_GAP]
    rv, hv = (C[sh.C_R_VMIN], C[sh.C_R_VMAX]), (C[sh.C_H_VMIN], C[sh.C_H_VMAX])
    rho, acc = C[sh.C_RESP_RHO], C[sh.C_RESP_ACCEL]
    t = np.arange(0.0, horizon, step)
    s_av = positions(s_R, v_R, -C[sh.C_RESP_FRONT], t, *rv)
    s1, v1 = saturated_step(s_H, v_H, acc, rho, *hv)
    s_hv = np.where(t <= rho, positions(s_H, v_H, acc, t, *hv),
                    positions(s1, v1, -C[sh.C_RESP_BRAKE], t - rho, *hv))
    return float(np.min(s_av - s_hv - L))


def test_the_exact_rule_agrees_with_a_brute_force_grid():
    """Random small cases, speed limits reached and the rear braking harder than the front
    included (where RSS's closed form is wrong): the rule holds exactly when the grid's smallest
    gap is positive (cases within the grid's resolution of the boundary are left out)."""
    rng = np.random.default_rng(5)
    C0 = merge_conflict()[0]
    checked = fair_count = 0
    for _ in range(150):
        C = rule(C0, rng.uniform(0.0, 1.5), rng.uniform(0.0, 2.0), rng.uniform(1.0, 6.0),
                 rng.uniform(1.0, 6.0), v_max=rng.uniform(8.0, 15.0))
        v_R = rng.uniform(0.0, C[sh.C_R_VMAX])
        v_H = rng.uniform(0.0, C[sh.C_H_VMAX])
        s_H = C[sh.C_R_HI] - C[sh.C_GAP] - rng.uniform(0.0, 40.0)
        gap = brute_min_gap(C, C[sh.C_R_HI], v_R, s_H, v_H)
        if abs(gap) < 0.05:
            continue
        ok = fair_now(C, v_R, s_H, v_H)
        assert ok == (gap > 0.0), (C[sh.C_RESP_RHO:], v_R, s_H, v_H, gap)
        checked += 1
        fair_count += ok
    assert checked >= 120 and 20 <= fair_count <= checked - 20


def test_the_exact_rule_where_the_closed_form_is_wrong():
    """A follower at 10 m/s braking at 6 behind an AV at 5 m/s braking at 1, no reaction time:
    both stopping distances leave it 4.2 m short of the AV, so RSS's closed form asks for no
    gap, but it closes 2.5 m before the speeds are equal (relative speed 5 m/s, relative
    braking 5 m/s^2): 1 m is not enough, 3 m is."""
    C = rule(merge_conflict()[0], 0.0, 0.0, 6.0, 1.0)
    assert rss_distance(10.0, 5.0, 0.0, 0.0, 6.0, 1.0) == 0.0
    L, r_hi = C[sh.C_GAP], C[sh.C_R_HI]
    assert not fair_now(C, 5.0, r_hi - L - 1.0, 10.0)
    assert fair_now(C, 5.0, r_hi - L - 3.0, 10.0)
    assert smallest_fair_gap(C, 5.0, 10.0) == pytest.approx(2.5, abs=1e-5)


def test_the_rule_judges_the_furthest_and_fastest_human_at_entry():
    """Entry in the future: the gap must hold against every human state reachable by then,
    i.e. against the human at full throttle until the AV reaches the merge point."""
    C = rule(merge_conflict()[0], 1.0, 1.0, 2.0, 2.0, v_max=10.0)
    r_hi = C[sh.C_R_HI]
    s_R, v_R = r_hi - 8.0, 4.0  # 2 s from the merge point at constant speed
    t_0 = sh.profile_reach(s_R, v_R, 0.0, 0.1, 0.0, r_hi, 0.0, 10.0)
    assert t_0 == pytest.approx(2.0)
    s_far, v_far = saturated_step(-40.0, 6.0, C[sh.C_H_UMAX], t_0, 0.0, 10.0)
    need = rss_distance(v_far, v_R, 1.0, 1.0, 2.0, 2.0)
    # placed so that the human's *current* state would pass but its full-throttle one fails
    assert r_hi - C[sh.C_GAP] - (-40.0) > rss_distance(6.0, v_R, 1.0, 1.0, 2.0, 2.0)
    assert r_hi - C[sh.C_GAP] - s_far < need
    assert not sh.cut_in_fair(s_R, v_R, 0.0, 0.1, 0.0, math.inf, 0.0, t_0, -40.0, 6.0, C)
    assert sh.cut_in_fair(s_R, v_R, 0.0, 0.1, 0.0, math.inf, 0.0, t_0, -60.0, 6.0, C)


# -- the shield in the lane ----------------------------------------------------------------


def test_in_the_lane_ahead_the_av_brakes_no_harder_than_the_rule():
    C, _ = merge_conflict(**{"responsibility.front_brake_mps2": 1.0})
    assert C[sh.C_R_ULANE] == -1.0  # the AV's braking command in the lane ahead of a human
    assert C[sh.C_R_UMIN] == -2.0  # its own, before the lane and against other conflicts
    assert sh.braking(10.0, 5.0, -30.0, 5.0, C) == -1.0  # in the lane, the human behind
    assert sh.braking(-20.0, 5.0, -30.0, 5.0, C) == -2.0  # before the merge point
    # the human behind: a proposal harder than the rule is overridden by the rule's braking
    assert sh.shield_step(10.0, 5.0, -2.0, 0.1, -30.0, 5.0, C) == (-1.0, sh.BRAKE)
    assert sh.shield_step(10.0, 5.0, -0.5, 0.1, -30.0, 5.0, C) == (-0.5, sh.ADMITTED)
    # before the merge point the rule limits the fallback, not a proposal that stops early
    C2, _ = merge_conflict()
    assert C2[sh.C_R_ULANE] == -2.0  # the default: the follower's 4.5 taken at its own 2


def test_merging_ahead_needs_the_rules_gap():
    """The review's case: a merge ahead that reached the merge point before any human could
    reach its side zone, but left only a few metres to a fast human, is no longer admitted."""
    C, _ = merge_conflict()
    r_hi, h_lo = C[sh.C_R_HI], C[sh.C_H_LO]
    # AV 1 m before the merge point at 6 m/s; the human at full speed 12 m behind the side
    # zone's start: it cannot reach the side zone first, but it is far too close to follow
    s_R, v_R, s_H, v_H = r_hi - 1.0, 6.0, h_lo - 12.0, 10.0
    window = sh.human_window(s_H, v_H, C)
    t_0 = sh.profile_reach(s_R, v_R, 1.0, 0.1, 1.0, r_hi, 0.0, 10.0)
    assert t_0 < window[0]  # the old "merge ahead" test passes
    assert not sh.certified(s_R, v_R, 1.0, 0.1, 1.0, s_H, v_H, C, *window)
    # the same with the human 60 m further back: the rule's gap is there
    far = s_H - 60.0
    assert sh.certified(s_R, v_R, 1.0, 0.1, 1.0, far, v_H, C, *sh.human_window(far, v_H, C))


def test_noise_beyond_the_in_lane_braking_is_refused():
    with pytest.raises(ConfigError, match="simulation.accel_noise_mps2"):
        Config(mode="corrected").with_overrides({
            "scenario.kind": "merge", "responsibility.front_brake_mps2": 0.5,
            "simulation.accel_noise_mps2": 0.5})
    with pytest.raises(ConfigError, match="responsibility.reaction_s"):
        Config().with_overrides({"responsibility.reaction_s": -1.0})


def test_the_default_configuration_text_is_unchanged():
    assert "responsibility" not in Config().to_toml()
    c = Config().with_overrides({"responsibility.reaction_s": 0.5})
    assert "[responsibility]" in c.to_toml()
    assert Config.from_dict(tomllib.loads(c.to_toml())) == c
    assert c.responsibility_rule == (0.5, 1.0, 2.0, 2.0)  # the paper's vehicles: 4.5 taken at 2


# -- the fault --------------------------------------------------------------------------------


def _run(scenario, s_R, v_R, a_R, s_H, v_H, a_H, dt=0.1):
    """States of a hand-made run: both vehicles holding their accelerations step by step."""
    cfg = scenario.config
    av, hv = cfg.vehicle_of("av"), cfg.vehicle_of("hv")
    states = [(s_R, v_R, s_H, v_H)]
    for ar, ah in zip(a_R, a_H):
        s_R, v_R = saturated_step(s_R, v_R, ar, dt, av.v_min_mps, av.v_max_mps)
        s_H, v_H = saturated_step(s_H, v_H, ah, dt, hv.v_min_mps, hv.v_max_mps)
        states.append((s_R, v_R, s_H, v_H))
    return np.array(states), np.asarray(a_R, float)


def test_a_rear_end_after_a_fair_cut_in_is_the_humans():
    _, scenario = merge_conflict()
    n = 120
    # the AV enters 60 m ahead of a human at 10 m/s and brakes gently to a stop; the human
    # keeps full throttle into it
    states, a_R = _run(scenario, -1.0, 4.0, [0.0] * 5 + [-1.0] * (n - 5), -61.0, 10.0,
                       [1.0] * n)
    overlap = scenario.collides(states[1:, 0], states[1:, 2])
    assert overlap.any()
    fault = measures.human_at_fault(scenario, states, a_R, 0.1, np.ones(n))
    assert not measures.caused_by_av(overlap, fault).any()
    # the same entry 12 m ahead: unfair, the AV's
    states, a_R = _run(scenario, -1.0, 4.0, [0.0] * 5 + [-1.0] * (n - 5), -13.0, 10.0,
                       [1.0] * n)
    overlap = scenario.collides(states[1:, 0], states[1:, 2])
    assert overlap.any()
    assert measures.caused_by_av(overlap, measures.human_at_fault(scenario, states, a_R,
                                                                  0.1, np.ones(n))).any()


def test_a_collision_is_judged_at_its_first_contact_inside_the_step():
    """Issue 39's pass-through (``test_shield_configs.PASS_THROUGH``, a 1-s step): the human
    is ahead of the AV at the first overlapping state but was behind it at the first contact,
    found inside the step as a brute-force scan of 20,000 instants finds it; judged there, the
    collision is a rear-end by the human, and the run's guarantee held (its steps counted
    until that contact)."""
    from test_shield_configs import PASS_THROUGH

    record = simulate(Config(mode="corrected").with_overrides(PASS_THROUGH), 2634)
    scenario, states, log = record.scenario, record.states, record.log
    after = states[1:]
    overlap = scenario.collides(after[:, 0], after[:, 2])
    k = int(np.argmax(overlap))
    assert overlap[k] and not overlap[:k].any()
    # at the first overlapping state the human is ahead: the state alone calls it the AV's
    assert not measures.rear_end_mask(scenario, after[k:k + 1, 0], after[k:k + 1, 2])[0]
    dt = record.config.simulation.dt_s
    t, s_a, s_h = measures.first_contact(scenario, states[k], log["av_accel_mps2"][k],
                                         log["hv_accel_mps2"][k], dt)
    av, hv = scenario.av.vehicle, scenario.hv.vehicle
    grid = np.linspace(0.0, dt, 20_001)[1:]
    pos = np.array([(saturated_step(states[k, 0], states[k, 1], log["av_accel_mps2"][k], u,
                                    av.v_min_mps, av.v_max_mps)[0],
                     saturated_step(states[k, 2], states[k, 3], log["hv_accel_mps2"][k], u,
                                    hv.v_min_mps, hv.v_max_mps)[0]) for u in grid])
    first = grid[np.argmax(scenario.collides(pos[:, 0], pos[:, 1]))]
    assert abs(t - first) <= dt / 20_000 and s_h < s_a  # behind at the first contact
    o = record.outcome
    assert o.collision and o.rear_end_by_human and not o.collision_caused_by_av
    assert o.uncertified_steps == 0 and o.guarantee_held


def test_braking_harder_than_the_rule_after_a_fair_entry_is_the_avs():
    _, scenario = merge_conflict(**{"responsibility.front_brake_mps2": 1.0})
    n = 120
    hard = [0.0] * 5 + [-2.0] * (n - 5)
    states, a_R = _run(scenario, -1.0, 4.0, hard, -61.0, 10.0, [1.0] * n)
    overlap = scenario.collides(states[1:, 0], states[1:, 2])
    assert overlap.any()
    assert measures.caused_by_av(overlap, measures.human_at_fault(scenario, states, a_R,
                                                                  0.1, np.ones(n))).any()


# -- closed loops -------------------------------------------------------------------------------


@pytest.mark.parametrize("av_kind", ["cv", "persuasive"])
def test_merges_against_the_idm_cause_nothing(av_kind):
    """The review's reproduction (a shielded ``cv`` AV merged 5.2 m ahead of the ``idm`` human,
    which braked at its limit and hit it): with the rule, no collision is the AV's, none is
    uncertified, and the AV keeps the rule's braking in the lane."""
    config = Config(mode="corrected").with_overrides({
        "scenario.kind": "merge", "av.kind": av_kind, "hv.kind": "idm",
        "simulation.n_steps": 150})
    for seed in range(1, 11):
        record = simulate(config, seed)
        o = record.outcome
        assert not o.collision_caused_by_av and o.uncertified_steps == 0, seed
