"""The level-k AV (``level1``, ``level2``; ``persuasive.policies.levelk``): the compiled choice
against a plain NumPy reference on the game's reward matrices, closed loops with the shield,
reproducibility, and the refusal of an unknown level.

Tolerances: everything here is exact. The reference's reward matrices are the straightforward
computation (``persuasive.reference``), equal bit for bit to the game's; the choices are
argmaxes with exact ties (lowest index), so they are compared as integers.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from persuasive import Config, ConfigError, Planner, simulate
from persuasive import reference as ref
from persuasive.config import AV_KINDS, SCENARIO_KINDS
from persuasive.game import full_prediction, predict_buffers
from persuasive.library import lib_buffers
from persuasive.packing import N_WORK, discounts, pack
from persuasive.policies import kinds as kd
from persuasive.policies import policy_params
from persuasive.policies.levelk import COL_HV_TRAJ, COL_N_ALLOWED, COL_REWARD, COL_TRAJ
from persuasive.policies.planners import allowed_of
from persuasive.policies.step import policy_step_buffers
from persuasive.scenarios import build_scenario
from persuasive.world import run_python

from _cli import run_cli

LEVELS = {"level1": 1, "level2": 2}
#: Joint states ``(x_AV, x_HV)`` where the shield (corrected mode) admits some candidates but
#: not the plain best response of level 1 or 2 (found by a search over random states; the
#: shield restricts the choice in about 1 random state of 300).
SHIELD_STATES = {
    "intersection": [((-3.97, 3.18), (-21.14, 8.11)), ((-21.19, 8.28), (-24.94, 7.32))],
    "crossing": [((-9.71, 5.76), (-6.86, 0.47))],
    "left-turn": [((-23.98, 8.51), (-7.05, 6.81))],
    "merge": [((-20.73, 7.15), (-25.01, 6.39))],
}


# -- the NumPy reference -----------------------------------------------------------------------


def level_choice(R_me: np.ndarray, R_you: np.ndarray, k: int, allowed=None) -> int:
    """The level-``k`` trajectory of the player of ``R_me[own, other's]``: level 0 keeps its
    speed (trajectory 0); level ``k`` is the first maximiser of its column of the other's
    level ``k - 1`` (among ``allowed`` rows when given and any is)."""
    if k == 0:
        return 0
    column = R_me[:, level_choice(R_you, R_me, k - 1)]
    if allowed is not None and allowed.any():
        column = np.where(allowed, column, -np.inf)
    return int(np.flatnonzero(column == column.max())[0])


def reference_matrices(config: Config, x_R, x_H):
    """``(R_av, R_hv, A_av)`` at the joint state, the straightforward way: the two reward
    matrices (``R_av[i, j]``, ``R_hv[j, i]`` for AV trajectory ``i``, human trajectory ``j``)
    and the AV library's accelerations ``(n_traj, n)``."""
    P_av, P_hv = pack(config, build_scenario(config))
    disc = discounts(config)
    S_r, V_r, A_r, _ = ref.library(*x_R, P_av)
    S_h, V_h, A_h, _ = ref.library(*x_H, P_hv)
    R_av = ref.reward_matrix(S_r, V_r, A_r, x_R[0], S_h, disc, P_av, P_hv)
    R_hv = ref.reward_matrix(S_h, V_h, A_h, x_H[0], S_r, disc, P_hv, P_av)
    return R_av, R_hv, A_r


class Kernel:
    """The compiled step of a level-k AV at one joint state (the entry point ``Planner`` and
    ``CompiledPolicy`` use), on the libraries the game cache builds."""

    def __init__(self, config: Config):
        self.config = config
        self.P_av, self.P_hv = pack(config, build_scenario(config))
        self.disc = discounts(config)
        self.prm = policy_params(config, kd.AV)
        n, n_traj = config.library.n_samples, config.library.n_traj
        self.shape = (n, n_traj)
        self.hv, self.av = lib_buffers(n, n_traj), lib_buffers(n, n_traj)
        self.scratch = lib_buffers(n, n_traj), lib_buffers(n, n_traj)
        self.work = np.zeros(N_WORK, np.int64)

    def __call__(self, x_R, x_H):
        """``(acceleration, log row, allowed)``."""
        n, n_traj = self.shape
        idx, q = np.zeros(4, np.int64), np.zeros((4, n_traj))
        predict_buffers(x_H[0], x_H[1], x_R[0], x_R[1], self.P_hv, self.P_av, self.disc,
                        *self.hv, *self.av, idx, q, self.work)
        log = np.full(kd.LOG_SIZE, np.nan)
        kind = kd.KINDS[self.config.av.kind].kind
        accel = policy_step_buffers(
            kind, kd.AV, self.prm, np.zeros(kd.STATE_SIZE), 0, x_R[0], x_R[1], x_H[0], x_H[1],
            np.zeros(2), -1, *self.hv, *self.av, idx, q, self.P_av, self.P_hv, self.disc,
            self.config.simulation.dt_s, np.zeros((n_traj, 10)), *self.scratch[0],
            *self.scratch[1], np.zeros((2, 3)), log, self.work)
        allowed = np.empty(n_traj, np.bool_)
        allowed_of(x_R[0], x_R[1], x_H[0], x_H[1], *self.av, self.P_av, self.P_hv, False,
                   allowed)
        return accel, log, allowed


def random_states(config: Config, rng: np.random.Generator, count: int):
    """Joint states around the conflict: each vehicle from 5 m before its nominal start to
    3 m past its conflict zone (or 18 m past the conflict point in a merge's shared lane), at
    speeds inside its limits."""
    sc = build_scenario(config)
    for _ in range(count):
        out = []
        for who in ("av", "hv"):
            path = getattr(sc, who)
            lo, hi = sc.nominal_s0(who) - 5.0, min(path.zone[1], 15.0) + 3.0
            out.append((float(rng.uniform(lo, hi)),
                        float(rng.uniform(0.0, path.vehicle.v_max_mps))))
        yield tuple(out)


# -- the compiled choice is the reference's ----------------------------------------------------


@pytest.mark.parametrize("scenario", SCENARIO_KINDS)
def test_the_compiled_choice_is_the_numpy_reference(scenario):
    """Per level, shield off (paper mode) and on (corrected mode, the worst-case shield with
    ``mpc.shield_aware``): the AV's choice, the human trajectory it answers, its reward and
    its acceleration are the reference's. The states are informative: the two levels differ,
    the human's level-1 answer is not always its level 0, the collision term decides, and the
    shield takes the plain best response away (``SHIELD_STATES``)."""
    rng = np.random.default_rng(20240601)
    seen = {"differ": 0, "human_moves": 0, "collision_decides": 0, "restricted": 0}
    choices = set()
    for mode in ("paper", "corrected"):
        base = Config(mode=mode).with_overrides({"scenario.kind": scenario})
        kernels = {name: Kernel(base.with_overrides({"av.kind": name})) for name in LEVELS}
        states = list(random_states(base, rng, 25))
        if mode == "corrected":
            states += SHIELD_STATES[scenario]
        for x_R, x_H in states:
            R_av, R_hv, A_r = reference_matrices(base, x_R, x_H)
            B = reference_matrices(base.with_overrides({"reward.w_c": 0.0}), x_R, x_H)[0][:, 0]
            # the game's own matrices (ego = the human) are the reference's, bit for bit
            game = full_prediction(x_H, x_R, kernels["level1"].P_hv, kernels["level1"].P_av,
                                   kernels["level1"].disc)
            np.testing.assert_array_equal(game.rewards_ego, R_hv)
            np.testing.assert_array_equal(game.rewards_other, R_av)
            picks = {}
            for name, k in LEVELS.items():
                accel, log, allowed = kernels[name](x_R, x_H)
                shield_on = mode == "corrected"
                h = level_choice(R_hv, R_av, k - 1)
                c = level_choice(R_av, R_hv, k, allowed if shield_on else None)
                assert (int(log[COL_TRAJ]), int(log[COL_HV_TRAJ])) == (c, h), (name, x_R, x_H)
                assert log[COL_REWARD] == R_av[c, h]
                assert accel == A_r[c, 0]
                assert log[COL_N_ALLOWED] == (allowed.sum() if shield_on else A_r.shape[0])
                picks[name] = c
                choices.add(c)
                seen["human_moves"] += k == 2 and h != 0
                # without the collision term every column is B: the best progress
                seen["collision_decides"] += not shield_on and c != int(np.argmax(B))
                seen["restricted"] += shield_on and c != level_choice(R_av, R_hv, k)
            seen["differ"] += picks["level1"] != picks["level2"]
    assert len(choices) >= 3, choices
    assert all(count > 0 for count in seen.values()), seen


def test_level0_is_the_constant_speed_trajectory():
    """Trajectory 0 of a library holds the current speed: level 0 keeps it (zero
    acceleration up to rounding, below 1e-12 m/s^2)."""
    config = Config(mode="corrected")
    P_av, _ = pack(config, build_scenario(config))
    for v0 in (0.0, 2.5, 7.0, 10.0):
        _, V, A, _ = ref.library(-20.0, v0, P_av)
        assert np.all(np.abs(A[0]) < 1e-12) and np.all(np.abs(V[0] - v0) < 1e-12)


def test_a_hand_made_pair_of_levels():
    """Small games with known answers, ties included (lowest index)."""
    R_av = np.array([[1.0, 5.0, 0.0],
                     [3.0, 5.0, 2.0],
                     [3.0, 1.0, 4.0]])  # R_av[i, j]: AV i against human j
    R_hv = np.array([[0.0, 0.0, 9.0],
                     [2.0, 1.0, 0.0],
                     [2.0, 7.0, 1.0]])  # R_hv[j, i]: human j against AV i
    # level 1: the best response to the other's trajectory 0; a tie goes to the lower index
    assert level_choice(R_av, R_hv, 1) == 1  # rows 1 and 2 tie at 3.0
    assert level_choice(R_hv, R_av, 1) == 1  # rows 1 and 2 tie at 2.0
    # level 2: the AV's answer to the human's level 1 (trajectory 1): rows 0 and 1 tie at 5
    assert level_choice(R_av, R_hv, 2) == 0
    # the compiled helpers agree
    from persuasive.policies.levelk import level_choice as compiled

    for k in range(5):
        assert compiled(R_av, R_hv, k) == level_choice(R_av, R_hv, k)
        assert compiled(R_hv, R_av, k) == level_choice(R_hv, R_av, k)


# -- closed loops ------------------------------------------------------------------------------


@pytest.mark.parametrize("av", list(LEVELS))
def test_with_the_shield_no_collision_is_the_avs(av):
    """Corrected mode (the worst-case shield): against the paper's human, one that never
    yields and one that tries to collide, on a handful of seeds in every scenario."""
    for scenario in SCENARIO_KINDS:
        for hv in ("lfg", "aggressive", "adversary"):
            config = Config(mode="corrected").with_overrides(
                {"av.kind": av, "hv.kind": hv, "scenario.kind": scenario})
            for seed in range(1, 5):
                o = simulate(config, seed).outcome
                assert not o.collision_caused_by_av, (scenario, hv, seed)


def test_without_the_shield_the_level_k_av_is_hit():
    """The test above tests something: without the shield the adversary hits it."""
    hits = 0
    for av in LEVELS:
        config = Config(mode="corrected").with_overrides(
            {"av.kind": av, "av.shield": "off", "hv.kind": "adversary"})
        hits += sum(simulate(config, s).outcome.collision_caused_by_av for s in range(1, 11))
    assert hits > 0


@pytest.mark.parametrize("av", list(LEVELS))
def test_runs_are_reproducible_and_both_loops_agree(av):
    """The same seed twice gives the same run bit for bit, states and every log column, and
    the Python loop (``CompiledPolicy``) gives it too."""
    for mode in ("paper", "corrected"):
        config = Config(mode=mode).with_overrides({"av.kind": av, "scenario.kind": "crossing"})
        for seed in (3, 996):
            first, again = simulate(config, seed), simulate(config, seed)
            python = run_python(config, seed)
            for other in (again, python):
                np.testing.assert_array_equal(other.states, first.states)
                assert other.log.keys() == first.log.keys()
                for column, values in first.log.items():
                    np.testing.assert_array_equal(other.log[column], values, err_msg=column)


def test_the_planner_runs_both_levels():
    """``Planner`` (the junction world's and the outside simulators' per-human planner): the
    proposal is the compiled step's, then the shield."""
    for av, k in LEVELS.items():
        config = Config(mode="corrected").with_overrides({"av.kind": av,
                                                          "av.yield_line_choices_m": []})
        planner = Planner(config, seed=1)
        x_R, x_H = (-14.0, 5.0), (-12.0, 6.0)
        plan = planner.plan(av=x_R, hv=x_H)
        _, log, allowed = Kernel(config)(x_R, x_H)
        R_av, R_hv, A_r = reference_matrices(config, x_R, x_H)
        assert plan.candidate == level_choice(R_av, R_hv, k, allowed) == int(log[COL_TRAJ])
        assert plan.proposed_accel_mps2 == A_r[plan.candidate, 0]
        assert plan.shield_verdict is not None


# -- input ---------------------------------------------------------------------------------------


def test_an_unknown_level_is_refused_in_one_line():
    assert {"level1", "level2"} <= set(AV_KINDS)
    with pytest.raises(ConfigError) as err:
        Config().with_overrides({"av.kind": "level3"})
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("av.kind = 'level3' is out of range; allowed: ")
    assert "| level1 | level2" in message


def test_the_cli_runs_a_level_k_av(capsys):
    code, out, err = run_cli(capsys, "simulate", "--av", "level2", "--seed", 4, "--json")
    assert (code, err) == (0, "")
    assert json.loads(out)["collision"] is False
    code, _, err = run_cli(capsys, "simulate", "--av", "level3")
    assert code == 2 and "level1" in err and "level2" in err
