"""Li et al.'s pairwise LFG AV (``lfg-rule``; ``persuasive.policies.lfg_rule``,
``persuasive.many.rule``): the rule's role, the worst pair's choice against a NumPy reference
of the game's values, the two-vehicle kind as the stubborn LFG in the rule's role, and the
junction's planner with one and with several humans.

Tolerances: the values are compared with the straightforward computation
(``persuasive.reference``) to 1e-9 (the candidates shifted into a frame add one rounding per
position); choices are integers and compared exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive import Config, Planner, simulate
from persuasive import reference as ref
from persuasive.config import JunctionSpec
from persuasive.many.rule import RulePlanner
from persuasive.many.world import JunctionWorld
from persuasive.packing import discounts, pack
from persuasive.policies.lfg_rule import maximin_choice, rule_role
from persuasive.roles import FOLLOWER, LEADER
from persuasive.scenarios import build_scenario

from _cli import run_cli

CORRECTED = Config(mode="corrected")
RULE = CORRECTED.with_overrides({"av.kind": "lfg-rule"})


# -- the rule's role and the worst pair ---------------------------------------------------------


def test_the_role_is_the_rule_and_first_come_without_one():
    assert rule_role(1.0, -50.0, 1.0, -5.0, 9.0) == LEADER  # the rule, however far behind
    assert rule_role(-1.0, -5.0, 9.0, -50.0, 1.0) == FOLLOWER
    assert rule_role(0.0, -10.0, 5.0, -30.0, 5.0) == LEADER  # 2 s against 6 s
    assert rule_role(0.0, -30.0, 5.0, -10.0, 5.0) == FOLLOWER
    assert rule_role(0.0, -10.0, 5.0, -10.0, 5.0) == FOLLOWER  # a tie: nobody has it
    # below 1 m/s the time counts at 1 m/s: standing 3 m before is 3 s, not forever
    assert rule_role(0.0, -3.0, 0.0, -20.0, 5.0) == LEADER


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 5), st.integers(1, 12), st.integers(0, 2 ** 32 - 1))
def test_the_choice_is_the_first_best_worst_pair(pairs, n, seed):
    rng = np.random.default_rng(seed)
    Q = rng.integers(-3, 3, size=(pairs, n)).astype(float)  # small integers: many ties
    worst = Q.min(axis=0)
    assert maximin_choice(Q) == int(np.flatnonzero(worst == worst.max())[0])


# -- the game's values, the plain way ------------------------------------------------------------


def reference_values(config: Config, x_R_frame, shift: float, x_H, leader: bool):
    """The AV's values of its candidates (its library at ``x_R_frame`` moved ``shift`` along
    its path) against the human at ``x_H``: the leader's ``Ql`` or the follower's ``Qf``
    (docs/method.md §4, corrected mode: ties of the follower aggregated by the minimum)."""
    P_av, P_hv = pack(config, build_scenario(config))
    disc = discounts(config)
    S_r, V_r, A_r, _ = ref.library(*x_R_frame, P_av)
    S_r = S_r + shift
    S_h, V_h, A_h, _ = ref.library(*x_H, P_hv)
    R_av = ref.reward_matrix(S_r, V_r, A_r, x_R_frame[0] + shift, S_h, disc, P_av, P_hv)
    if not leader:
        return R_av.min(axis=1), A_r
    R_hv = ref.reward_matrix(S_h, V_h, A_h, x_H[0], S_r, disc, P_hv, P_av)
    Qf_h = R_hv.min(axis=1)
    best = np.flatnonzero(Qf_h == Qf_h.max())
    assert not config.effective_quirks.q5_leader_agg_max
    return R_av[:, best].min(axis=1), A_r


def rule_planner(config: Config = RULE) -> RulePlanner:
    from persuasive.many.junction import pair_config

    return RulePlanner(pair_config(config.with_overrides({"scenario.kind": "junction"})))


@pytest.mark.parametrize("role", ["av", "hv"])
def test_with_one_human_the_junction_planner_is_the_two_vehicle_kind(role):
    """The same game on the same libraries: the junction's planner with one human chooses
    what the two-vehicle kernel chooses with the configuration's right of way."""
    config = RULE.with_overrides({"responsibility.right_of_way": role, "av.shield": "off"})
    rng = np.random.default_rng(7)
    for _ in range(40):
        x_R = (float(rng.uniform(-40, 5)), float(rng.uniform(0, 10)))
        x_H = (float(rng.uniform(-40, 5)), float(rng.uniform(0, 10)))
        planner = RulePlanner(config)
        planner._priority = {"h": 1.0 if role == "av" else -1.0}
        a = planner._propose(x_R[1], [("h", x_R, x_H)])
        two = Planner(config).accel(x_R, x_H)
        assert a == two
        expected, A = reference_values(config, x_R, 0.0, x_H, role == "av")
        np.testing.assert_allclose(planner.values[0], expected, rtol=0, atol=1e-9)


def test_with_several_humans_the_worst_pair_decides():
    planner = rule_planner()
    config = planner.config
    rng = np.random.default_rng(11)
    chosen_by_one = 0
    for trial in range(30):
        v = float(rng.uniform(0, 10))
        # the AV's position in each pair's frame (its conflicts lie at different places)
        s_R = sorted((float(rng.uniform(-45, 0)) for _ in range(3)), reverse=True)
        planned, prio = [], {}
        for h, s in enumerate(s_R):
            planned.append((h, (s, v), (float(rng.uniform(-45, 5)), float(rng.uniform(0, 10)))))
            prio[h] = float(rng.choice([-1.0, 1.0]))
        planner._priority = prio
        planner.roles.clear()
        a = planner._propose(v, planned)
        Q = []
        for h, (key, ego, other) in enumerate(planned):
            values, A = reference_values(config, (s_R[0], v), ego[0] - s_R[0], other,
                                         prio[h] > 0)
            Q.append(values)
        Q = np.array(Q)
        np.testing.assert_allclose(planner.values, Q, rtol=0, atol=1e-9)
        worst = Q.min(axis=0)
        assert worst[planner.chosen] >= worst.max() - 1e-9
        assert a == A[planner.chosen, 0]  # the frame of the first conflict: s_R[0]
        assert planner.roles == {h: LEADER if prio[h] > 0 else FOLLOWER for h in prio}
        # the worst pair, not one human alone, decided
        alone = [int(np.argmax(Q[h])) for h in range(3)]
        chosen_by_one += planner.chosen in alone
    assert chosen_by_one < 30


def test_the_role_is_kept_while_the_human_is_planned_against():
    planner = rule_planner(RULE.with_overrides({"responsibility.right_of_way": None}))
    planner._priority = {"h": 0.0}
    planner._propose(5.0, [("h", (-10.0, 5.0), (-30.0, 5.0))])  # the AV comes first
    assert planner.roles == {"h": LEADER}
    planner._propose(5.0, [("h", (-10.0, 1.0), (-6.0, 9.0))])  # now the human would
    assert planner.roles == {"h": LEADER}
    planner._propose(5.0, [])  # gone: forgotten
    assert planner.roles == {}


# -- the two-vehicle kind ------------------------------------------------------------------------


@pytest.mark.parametrize("rule, role", [("av", "leader"), ("hv", "follower")])
def test_two_vehicles_is_the_stubborn_lfg_in_the_rules_role(rule, role):
    base = CORRECTED.with_overrides({"av.shield": "off", "roles.adapt_role": False,
                                     "responsibility.right_of_way": rule})
    for seed in (1, 2, 5):
        a = simulate(base.with_overrides({"av.kind": "lfg-rule"}), seed)
        b = simulate(base.with_overrides({"av.kind": "lfg", "av.role": role}), seed)
        assert np.array_equal(a.states, b.states)
        assert set(a.log["av_role"]) == {role}


def test_without_a_rule_the_first_to_come_leads():
    leaders = 0
    config = RULE.with_overrides({"scenario.kind": "merge"})  # both come first on these seeds
    for seed in range(1, 9):
        run = simulate(config, seed)
        x0 = run.states[0]  # s_AV, v_AV, s_HV, v_HV
        first = rule_role(0.0, x0[0], x0[1], x0[2], x0[3])
        assert set(run.log["av_role"]) == {"leader" if first == LEADER else "follower"}
        leaders += first == LEADER
    assert 0 < leaders < 8  # both roles occur on these seeds


# -- at the junction ------------------------------------------------------------------------------


def test_at_the_junction_the_roles_are_the_rows_and_nobody_is_hit():
    for seed in (2, 3, 5):
        world = JunctionWorld(RULE, JunctionSpec(n_vehicles=6), seed)
        assert isinstance(world.planner, RulePlanner)
        rows = {(r.j if r.i == 0 else r.i): (r.priority if r.i == 0 else -r.priority)
                for r in world.table.rows if 0 in (r.i, r.j) and r.kind != "follow"}
        seen = {}
        while True:
            info = world.step()
            seen.update(world.planner.roles)
            if info.done:
                break
        assert seen  # it planned against someone
        for key, role in seen.items():
            assert role == (LEADER if rows[key] > 0 else FOLLOWER)
        assert not any(caused for *_, caused in world.collisions)
        again = JunctionWorld(RULE, JunctionSpec(n_vehicles=6), seed)
        while not again.step().done:
            pass
        assert np.array_equal(world.S, again.S, equal_nan=True)


def test_the_cli_runs_the_rule_av_at_the_junction(capsys):
    code, out, err = run_cli(capsys, "simulate", "--scenario", "junction", "--vehicles", "3",
                                      "--av", "lfg-rule", "--seed", "2")
    assert code == 0, err
    assert "lfg-rule AV (the rule's role per human, the worst pair decides" in out
