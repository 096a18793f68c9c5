"""Policies (``persuasive.policies``): each kind on hand-made cases, the human's draws and
initial state independent of the AV, and the protocol's two sides (compiled and Python) equal.

Tolerances: everything here is exact (same operations, same order), except the IDM's
hand-computed accelerations, compared to 1e-12 m/s^2.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from persuasive import Config, ConfigError, Planner, simulate
from persuasive import packing as slot
from persuasive.config import AV_KINDS
from persuasive.policies import CompiledPolicy, Context, Observation, kinds as kd
from persuasive.policies.idm import idm_step
from persuasive.policies.lfg import boltzmann_choice
from persuasive.world import run_python

N_SEEDS = 12
CORRECTED = Config(mode="corrected")  # per-agent streams


def run(config: Config, seed: int, **overrides):
    return simulate(config.with_overrides(overrides) if overrides else config, seed)


# -- the human's randomness and start do not depend on the AV ----------------------------------


def test_human_draws_and_start_are_the_same_whatever_the_av():
    for seed in (1, 2, 3):
        records = [run(CORRECTED, seed, **{"av.kind": av}) for av in AV_KINDS]
        first = records[0]
        for r in records[1:]:
            assert r.hv_initial_state == first.hv_initial_state
            assert r.av_initial_state == first.av_initial_state
            np.testing.assert_array_equal(r.log["hv_draw"], first.log["hv_draw"])
        assert {r.streams for r in records} == {"per-agent"}


def test_legacy_streams_keep_the_papers_order():
    # paper mode: one RandomState; the LFG AV's uniform follows the human's at every step
    r = run(Config(), 7, **{"av.kind": "lfg"})
    rng = np.random.RandomState(7)
    rng.random_sample(8)  # the initial state's
    expected = rng.random_sample((61, 2))
    np.testing.assert_array_equal(r.log["hv_draw"], expected[:, 0])
    np.testing.assert_array_equal(r.log["av_draw"], expected[:, 1])
    assert r.streams == "legacy"


# -- AV kinds ----------------------------------------------------------------------------------


@pytest.mark.parametrize("human", ["aggressive", "lfg"])
def test_yield_never_crosses_first_against_a_human_that_goes(human):
    for seed in range(1, N_SEEDS + 1):
        r = run(CORRECTED, seed, **{"av.kind": "yield", "hv.kind": human})
        o = r.outcome
        assert o.first_at_line == 2, seed  # the human goes first, every time
        released = r.log["av_released"]
        # it holds back until the human has cleared the conflict, then goes
        cleared = r.log["hv_s_m"] >= r.scenario.hv.clear_s
        assert not released[~np.maximum.accumulate(cleared)].any(), seed


def test_yield_stops_before_its_line_while_waiting():
    r = run(CORRECTED, 3, **{"av.kind": "yield", "hv.kind": "idm",
                             "hv.idm.critical_gap_s": 100.0})  # a human that never accepts
    line = r.scenario.av.yield_s
    assert r.outcome.first_at_line == 0  # nobody goes: the human waits, the AV yields
    assert np.all(r.states[:, 0] <= line + 1e-9)


def test_passive_is_the_mpc_without_persuasion():
    for seed in (1, 4, 9):
        passive = run(Config(), seed, **{"av.kind": "passive"})
        no_transition = run(Config(), seed, **{"mpc.p_a_hat": 0.0})
        np.testing.assert_array_equal(passive.states, no_transition.states)
        np.testing.assert_array_equal(passive.log["av_trajectory"],
                                      no_transition.log["av_trajectory"])
        assert np.all(passive.log["av_branch_p_lf"] == 0.0)
        assert np.all(passive.log["av_branch_p_fl"] == 0.0)


def test_cv_predicts_the_human_at_constant_speed():
    # The human far away and slow: every candidate is safe; cv takes the best progress.
    planner = Planner(Config(mode="corrected").with_overrides({"av.kind": "cv"}))
    plan = planner.plan(av=(-40.0, 4.0), hv=(-60.0, 1.0))
    assert plan.feasible and plan.candidate == int(np.argmax(plan.candidates[:, 0]))
    # The human already at the conflict point, standing: candidates reaching it within the
    # horizon are unsafe at every sample they spend inside the safety distance.
    plan = planner.plan(av=(-30.0, 4.0), hv=(0.0, 0.0))
    unsafe = plan.candidates[:, 1] == 0.0  # P(safe) minimum: 0 or 1 with one branch
    assert unsafe.any() and not unsafe.all()
    assert plan.feasible and not unsafe[plan.candidate]


def test_cv_planner_against_a_constant_human_never_collides():
    for seed in range(1, N_SEEDS + 1):
        r = run(CORRECTED, seed, **{"av.kind": "cv", "hv.kind": "aggressive"})
        # the aggressive human is exactly what cv assumes, at its speed now; it accelerates,
        # so cv is not always right, but it must never run into it
        assert not r.outcome.collision, seed


# -- human kinds -------------------------------------------------------------------------------


def test_aggressive_never_yields():
    for seed in range(1, N_SEEDS + 1):
        r = run(CORRECTED, seed, **{"hv.kind": "aggressive"})
        assert np.all(r.log["hv_accel_mps2"] == 1.0)  # u_max at every step
        assert np.all(np.diff(r.states[:, 3]) >= 0.0)
        # it drives exactly the free flow of the delay's definition: no delay at all
        assert r.outcome.hv_delay_s == 0.0


def test_stubborn_never_changes_role():
    for role in ("leader", "follower"):
        for seed in range(1, N_SEEDS + 1):
            r = run(Config(), seed, **{"hv.kind": "stubborn", "hv.role": role})
            assert set(r.log["hv_role"]) == {role} and r.outcome.hv_role_changes == 0
            assert np.all(r.log["hv_pi_ll"] == 1.0) and np.all(r.log["hv_pi_ff"] == 1.0)


def test_noisy_with_a_huge_beta_is_the_lfg():
    for seed in range(1, N_SEEDS + 1):
        lfg = run(CORRECTED, seed)
        noisy = run(CORRECTED, seed, **{"hv.kind": "noisy", "hv.noisy.beta": 1e300})
        np.testing.assert_array_equal(noisy.states, lfg.states)
        np.testing.assert_array_equal(noisy.log["hv_trajectory"], lfg.log["hv_trajectory"])


def test_noisy_default_beta_is_visibly_noisy_and_larger_beta_less_so():
    """The default (0.1) departs from the LFG human's run on a noticeable share of steps;
    0.5 (the top candidates' values lie a few units apart) departs on far fewer."""

    def share(beta):
        differ = total = 0
        for seed in range(1, N_SEEDS + 1):
            lfg = run(CORRECTED, seed)
            noisy = run(CORRECTED, seed, **{"hv.kind": "noisy", "hv.noisy.beta": beta})
            differ += int(np.sum(noisy.log["hv_accel_mps2"] != lfg.log["hv_accel_mps2"]))
            total += len(lfg.log)
        return differ / total

    assert Config().hv.noisy.beta == 0.1
    default, sharper = share(0.1), share(0.5)
    assert default > 0.04 and sharper < default / 4


def test_noisy_with_beta_zero_picks_uniformly():
    picks = []
    for seed in range(1, 9):
        r = run(CORRECTED, seed, **{"hv.kind": "noisy", "hv.noisy.beta": 0.0})
        p = r.log["hv_choice_probability"]
        np.testing.assert_array_equal(p, np.full(p.shape, 1.0 / 11.0))
        picks.append(r.log["hv_trajectory"])
    counts = np.bincount(np.concatenate(picks), minlength=11)
    assert counts.min() > 0  # every candidate gets picked


def test_boltzmann_choice_by_hand():
    q = np.array([1.0, 3.0, 3.0, 2.0])
    # ties at the maximum collapse onto the lowest index: weights e^-2, 1, 0, e^-1
    w = np.array([math.exp(-2.0), 1.0, 0.0, math.exp(-1.0)])
    total = w.sum()
    cdf = np.cumsum(w) / total
    for r, expected in ((0.0, 0), (cdf[0] - 1e-12, 0), (cdf[0] + 1e-12, 1), (cdf[1] - 1e-12, 1),
                        (cdf[2] + 1e-12, 3), (0.999999, 3)):
        c, p = boltzmann_choice(q, 1.0, r)
        assert c == expected, r
        assert p == pytest.approx(w[expected] / total, rel=1e-15)


def _idm(config: Config, s, v, s_o, v_o, waiting=0.0):
    from persuasive.packing import pack
    from persuasive.policies import policy_params
    from persuasive.scenarios import build_scenario

    P_av, P_hv = pack(config, build_scenario(config))
    prm = policy_params(config.with_overrides({"hv.kind": "idm"}), kd.HV)
    st = np.array([waiting, 0.0])
    log = np.full(kd.LOG_SIZE, np.nan)
    a = idm_step(st, prm, s, v, s_o, v_o, config.simulation.dt_s, P_hv, P_av, log)
    return a, st, log


def test_idm_free_road_and_yield_line_by_hand():
    c = Config()
    p = c.hv.idm
    # The AV has cleared the conflict: free road, a = a (1 - (v/v0)^4)
    a, _, log = _idm(c, -20.0, 6.0, 10.0, 5.0)
    assert a == pytest.approx(p.max_accel_mps2 * (1 - (6.0 / p.desired_speed_mps) ** 4),
                              abs=1e-12)
    assert log[0] == 1.0  # goes
    # The AV arrives 0.5 s after the driver (gap 1 s): it yields to its line, a standing leader
    s, v = -20.0, 4.0
    t_own = 20.0 / 4.0
    s_o = -(t_own + 0.5) * 5.0  # the AV at 5 m/s, 0.5 s later
    a, _, log = _idm(c, s, v, s_o, 5.0)
    gap = c.vehicle.lane_width_m + c.vehicle.length_m / 2  # the line at -6.5 m
    line_gap = (-gap) - s + p.jam_gap_m
    s_star = p.jam_gap_m + v * p.time_gap_s + v * v / (2 * math.sqrt(p.max_accel_mps2 *
                                                                      p.comfort_decel_mps2))
    expected = p.max_accel_mps2 * (1 - (v / p.desired_speed_mps) ** 4 - (s_star / line_gap) ** 2)
    assert log[0] == 0.0 and a == pytest.approx(max(expected, c.vehicle.u_min_mps2), abs=1e-12)
    assert log[4] == pytest.approx(t_own) and log[5] == pytest.approx(t_own + 0.5)
    # 1.5 s later: the gap is accepted, free road
    a, _, log = _idm(c, s, v, -(t_own + 1.5) * 5.0, 5.0)
    assert log[0] == 1.0 and a == pytest.approx(1.0 * (1 - (v / 10.0) ** 4), abs=1e-12)


def test_idm_commits_once_it_cannot_stop_and_impatience_shrinks_the_gap():
    c = Config()
    # 1 m before its line at 6 m/s: v^2 / (2 b) = 12 m > 1 m, so it commits and goes even
    # with the AV about to arrive
    _, st, log = _idm(c, -7.5, 6.0, -8.0, 6.0)
    assert st[1] == 1.0 and log[0] == 1.0
    # waiting 10 s with impatience 0.05/s halves the accepted gap
    waiting = c.with_overrides({"hv.idm.impatience_per_s": 0.05})
    _, _, log = _idm(waiting, -30.0, 0.0, -10.0, 1.0, waiting=10.0)
    assert log[3] == pytest.approx(0.5 * c.hv.idm.critical_gap_s)


def test_idm_human_in_closed_loop_yields_or_goes_by_its_rule():
    for seed in range(1, N_SEEDS + 1):
        r = run(CORRECTED, seed, **{"hv.kind": "idm"})
        go = r.log["hv_go"]
        assert not r.outcome.collision
        # once committed, it goes for good
        committed = r.log["hv_committed"]
        assert np.all(np.diff(committed.astype(int)) >= 0)
        assert np.all(go[committed])


def test_replay_reproduces_a_recorded_run(tmp_path):
    for fmt in ("parquet", "csv"):
        original = run(Config(), 996)
        path = tmp_path / f"log.{fmt}"
        frame = original.frame()
        frame.to_parquet(path) if fmt == "parquet" else frame.to_csv(path, index=False)
        replayed = run(Config(), 996, **{"hv.kind": "replay", "hv.replay.file": str(path)})
        np.testing.assert_array_equal(replayed.states[:, 2:], original.states[:, 2:])
        # the AV is deterministic and sees the same human: the whole run is the same
        np.testing.assert_array_equal(replayed.states, original.states)


def test_replay_coasts_after_the_recording_and_rejects_bad_files(tmp_path):
    short = run(Config(), 5).frame().iloc[:10]
    path = tmp_path / "short.parquet"
    short.to_parquet(path)
    r = run(Config(), 5, **{"hv.kind": "replay", "hv.replay.file": str(path)})
    assert np.all(r.log["hv_accel_mps2"][10:] == 0.0)
    pd.DataFrame({"x": [1.0]}).to_parquet(tmp_path / "bad.parquet")
    with pytest.raises(ConfigError, match="missing columns: hv_s_m"):
        run(Config(), 5, **{"hv.kind": "replay", "hv.replay.file": str(tmp_path / "bad.parquet")})
    with pytest.raises(ConfigError, match="cannot be read"):
        run(Config(), 5, **{"hv.kind": "replay", "hv.replay.file": str(tmp_path / "no.parquet")})
    with pytest.raises(ConfigError, match="hv.replay.file is required"):
        Config().with_overrides({"hv.kind": "replay"})


# -- the protocol ------------------------------------------------------------------------------

PAIRS = [("persuasive", "lfg"), ("passive", "noisy"), ("cv", "idm"), ("lfg", "stubborn"),
         ("yield", "aggressive"), ("persuasive", "idm")]


@pytest.mark.parametrize("mode", ["paper", "corrected"])
@pytest.mark.parametrize("av, hv", PAIRS, ids=[f"{a}-{h}" for a, h in PAIRS])
def test_python_loop_equals_compiled_loop(mode, av, hv):
    config = Config(mode=mode).with_overrides({"av.kind": av, "hv.kind": hv,
                                               "simulation.n_steps": 30})
    for seed in (2, 11):
        compiled, python = simulate(config, seed), run_python(config, seed)
        np.testing.assert_array_equal(python.states, compiled.states)
        assert python.log.keys() == compiled.log.keys()
        for key in compiled.log:
            np.testing.assert_array_equal(python.log[key], compiled.log[key], err_msg=key)
        assert python.outcome == compiled.outcome


class FullThrottle:
    """A Python policy: full throttle, like the ``aggressive`` kind."""

    log_columns = ("throttle",)
    needs_game = False

    def reset(self, context: Context, rng) -> None:
        self.u_max = context.config.vehicle_of("hv").u_max_mps2
        self.calls = 0

    def act(self, observation: Observation) -> float:
        self.calls += 1
        self.last_log = np.array([1.0])
        return self.u_max


def test_a_python_policy_drives_like_its_compiled_twin():
    config = CORRECTED.with_overrides({"hv.kind": "aggressive"})
    human = FullThrottle()
    python = run_python(config, 4, hv=human)
    compiled = simulate(config, 4)
    np.testing.assert_array_equal(python.states, compiled.states)
    assert human.calls == 61 and np.all(python.log["hv_throttle"] == 1.0)


def test_policies_reject_bad_observations_and_sides():
    config = Config()
    with pytest.raises(ConfigError, match="av.kind = 'idm' is out of range"):
        CompiledPolicy("idm", kd.AV)
    with pytest.raises(ConfigError, match="hv.kind"):
        CompiledPolicy("persuasive", kd.HV)
    policy = CompiledPolicy("persuasive", kd.AV)
    from persuasive.packing import discounts, pack
    from persuasive.scenarios import build_scenario
    from persuasive.world import GameCache

    P_av, P_hv = pack(config, build_scenario(config))
    policy.reset(Context(config, build_scenario(config), P_av, P_hv, discounts(config), kd.AV,
                         61, np.zeros((61, 0)), GameCache(P_av, P_hv, discounts(config))), None)
    for bad in ((math.nan, 4.0), (-20.0, math.inf), (-20.0, 11.0), (-20.0, -0.1), (1.0,)):
        with pytest.raises(ConfigError, match="observation.av"):
            policy.act(Observation(0, 0.0, bad, (-20.0, 4.0)))
    with pytest.raises(ConfigError, match="hv.role = 'Leader' is out of range"):
        config.with_overrides({"hv.role": "Leader"})
    with pytest.raises(ConfigError, match="human_role = 'Leader' is out of range"):
        Planner(Config()).plan((-20.0, 4.0), (-20.0, 4.0), human_role="Leader")


@pytest.mark.parametrize("kind", AV_KINDS)
def test_planner_runs_every_av_kind(kind):
    planner = Planner(Config(mode="corrected").with_overrides({"av.kind": kind}), seed=3)
    assert planner.kind == kind
    plan = planner.plan(av=(-20.0, 4.0), hv=(-21.0, 4.2))
    assert -2.0 <= plan.accel_mps2 <= 1.0 and 0 <= plan.candidate < 11
    assert plan.s_m.shape == (50,) and np.all(np.diff(plan.s_m) >= 0)
    if kind in ("persuasive", "passive"):
        assert 0.0 < planner.belief_hv_leader < 1.0
    else:
        assert math.isnan(planner.belief_hv_leader)


def test_kinds_registry_is_consistent():
    from persuasive.config import HV_KINDS, SIMULATED_HV_KINDS

    assert set(AV_KINDS) | set(SIMULATED_HV_KINDS) == set(kd.KINDS)
    assert set(HV_KINDS) - set(SIMULATED_HV_KINDS) == {"person"}  # a Python policy only
    for name, spec in kd.KINDS.items():
        assert kd.BY_ID[spec.kind] is spec and spec.name == name
        assert len(spec.log) <= kd.LOG_SIZE
        for side in spec.sides:
            assert name in (AV_KINDS if side == kd.AV else SIMULATED_HV_KINDS)
    assert slot.N_WORK == len(slot.WORK_NAMES)


def test_a_person_is_not_simulated():
    config = Config().with_overrides({"hv.kind": "person"})
    with pytest.raises(ConfigError, match="driven by a person"):
        simulate(config, 1)
    # but a Python policy drives it, and the record says a person drove
    record = run_python(config, 1, hv=FullThrottle())
    assert record.config.hv.kind == "person" and np.all(record.log["hv_throttle"] == 1.0)
