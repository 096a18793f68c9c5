"""One filter in one place (persuasive.safety.filter, docs/method.md §12.2): every world
decides, then filters through the one compiled entry point; the planner's features that
anticipate the shield are its own settings."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from persuasive import packing as slot
from persuasive.config import Config, ConfigError
from persuasive.envs import external as X
from persuasive.planner import Planner
from persuasive.record import static_setup
from persuasive.safety import shield as sh
from persuasive.safety.filter import ShieldFilter
from persuasive.simulation import simulate
from persuasive.world import run_python

SRC = Path(__file__).resolve().parents[1] / "src" / "persuasive"


def _closed_loop_filter(config: Config) -> tuple[ShieldFilter, np.ndarray]:
    _, P_av, P_hv, _ = static_setup(config)
    C = np.empty(sh.N_CONFLICT)
    sh.conflict_vector(P_av, P_hv, C)
    return ShieldFilter.closed_loop(P_av, P_hv, config.simulation.dt_s), C


def test_the_shield_is_applied_in_one_place_only():
    """No module outside the shield's own package certifies a trajectory or picks a
    fallback: the worlds and adapters call the one entry point (shield_filter, directly in
    the compiled loop, else through ShieldFilter), and only the planner's anticipation of
    the shield (policies/planners.py) asks the certification itself."""
    internals = {"certified", "admissible", "threat", "human_window", "go_certified",
                 "shield_step", "yields_before"}
    allowed = {"safety/shield.py", "safety/filter.py", "policies/planners.py"}
    calls_filter = set()
    for path in SRC.rglob("*.py"):
        rel = path.relative_to(SRC).as_posix()
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
            if name in internals:
                assert rel in allowed, f"{rel} calls the shield's {name} itself"
            if name in ("shield_filter", "shield_filter_one", "ShieldFilter", "closed_loop", "one",
                        "among"):
                calls_filter.add(rel)
    assert {"world.py", "planner.py", "envs/external.py"} <= calls_filter


@pytest.mark.parametrize("av_kind, hv_kind, seed, shield", [
    ("persuasive", "random", 17, "worst-case"), ("passive", "random", 17, "worst-case"),
    ("cv", "adversary", 19, "worst-case"), ("cv", "adversary", 19, "responsibility")])
def test_every_world_gives_the_same_verdicts(av_kind, hv_kind, seed, shield):
    """The compiled loop, the Python loop and the Planner API filter alike: the same
    proposals get the same applied accelerations and verdicts, step by step (runs in which
    the shield, unanticipated by the planner, overrides it); the responsibility shield keeps
    its state (what is left of the human's response) from step to step in each."""
    config = Config(mode="corrected").with_overrides(
        {"av.kind": av_kind, "hv.kind": hv_kind, "mpc.shield_aware": False,
         "av.shield": shield})
    compiled, python = simulate(config, seed), run_python(config, seed)
    np.testing.assert_array_equal(compiled.states, python.states)
    for name in ("av_proposed_accel_mps2", "shield_verdict", "av_accel_mps2"):
        np.testing.assert_array_equal(compiled.log[name], python.log[name])
    verdicts = compiled.log["shield_verdict"]
    assert (verdicts != sh.ADMITTED).any()  # the filter did something here
    planner = Planner(config, seed=seed)
    for k, (s_av, v_av, s_hv, v_hv) in enumerate(compiled.states[:-1]):
        plan = planner.plan((s_av, v_av), (s_hv, v_hv))
        assert plan.proposed_accel_mps2 == compiled.log["av_proposed_accel_mps2"][k]
        assert plan.accel_mps2 == compiled.log["av_accel_mps2"][k]
        assert plan.shield_verdict == sh.VERDICTS[int(verdicts[k])]


def test_the_filter_off_passes_every_proposal():
    config = Config(mode="corrected").with_overrides({"av.shield": "off"})
    filt, C = _closed_loop_filter(config)
    assert not filt.on
    # a state the worst-case shield would override (test_shield: brake before the human)
    assert filt.one(1.0, (-8.0, 4.0), (-1.0, 0.0)) == (1.0, sh.OFF)
    assert sh.shield_step(-8.0, 4.0, 1.0, 0.1, -1.0, 0.0, C) == (1.0, sh.OFF)
    on, C_on = _closed_loop_filter(Config(mode="corrected"))
    assert on.one(1.0, (-8.0, 4.0), (-1.0, 0.0)) == (-2.0, sh.BRAKE)
    assert sh.shield_step(-8.0, 4.0, 1.0, 0.1, -1.0, 0.0, C_on) == (-2.0, sh.BRAKE)
    assert ShieldFilter.name(sh.OFF) is None and ShieldFilter.name(sh.BRAKE) == "brake"
    record = simulate(config, 2)
    assert (record.log["shield_verdict"] == sh.OFF).all()
    np.testing.assert_array_equal(record.log["av_accel_mps2"],
                                  record.log["av_proposed_accel_mps2"])


def test_the_filter_among_no_vehicles_admits_and_grows_its_scratch():
    filt = ShieldFilter("worst-case", 0.1, -4.5)
    empty = np.zeros(0)
    assert filt.among(0.7, 5.0, empty, empty, empty, np.zeros((0, sh.N_CONFLICT))) == \
        (0.7, sh.ADMITTED)
    config = Config(mode="corrected")
    ego = X.Limits.of(config, "av")
    conflicts = [X.Conflict(j, X.CROSSING, -12.76 - j, -15.0 - 3 * j, 4.0, (-4.9, 4.9),
                            (-4.9, 4.9)) for j in range(4)]
    s_R, s_H, v_H, C = X.conflict_arrays(conflicts, config, ego)
    got = filt.among(1.0, 6.0, s_R, s_H, v_H, C)
    # one fresh filter per call: the scratch kept from a larger call changes nothing
    assert got == ShieldFilter("worst-case", 0.1, -4.5).among(1.0, 6.0, s_R, s_H, v_H, C)
    assert filt.among(1.0, 6.0, s_R[:1], s_H[:1], v_H[:1], C[:1]) == \
        sh.shield_step(s_R[0], 6.0, 1.0, 0.1, s_H[0], v_H[0], C[0])


# -- the planner's own settings ----------------------------------------------------------------


def test_confidence_filter_is_a_setting_of_the_planner():
    base = Config(mode="corrected")
    assert base.confidence_filter and not base.with_overrides(
        {"av.shield": "off"}).confidence_filter  # unset: on exactly with a shield
    assert base.with_overrides({"av.shield": "off", "mpc.confidence_filter": True}
                               ).confidence_filter
    assert not base.with_overrides({"mpc.confidence_filter": False}).confidence_filter
    assert not Config(mode="paper").confidence_filter
    with pytest.raises(ConfigError, match=r"mpc\.confidence_filter = 'yes' is not a boolean"):
        base.with_overrides({"mpc.confidence_filter": "yes"})
    # the kernels read the filter's own switch, not the shield's
    for over, on in (({"av.shield": "off", "mpc.confidence_filter": True}, True),
                     ({"mpc.confidence_filter": False}, False), ({}, True),
                     ({"av.shield": "off"}, False)):
        _, P_av, _, _ = static_setup(base.with_overrides(over))
        assert (P_av[slot.CONF_THRESHOLD] > 0.0) == on, over


def test_confidence_filter_works_without_a_shield():
    """Against a human the model does not explain, the filter on (and no shield) loses
    confidence and keeps only the robust candidates; off (with the shield on) it tracks
    nothing."""
    base = Config(mode="corrected").with_overrides({"hv.kind": "adversary"})
    alone = simulate(base.with_overrides({"av.shield": "off", "mpc.confidence_filter": True}), 3)
    conf = alone.log["av_model_confidence"]
    assert np.nanmax(conf) == 1.0 and np.nanmin(conf) < base.mpc.confidence_threshold
    n_traj = base.library.n_traj
    assert alone.log["av_n_allowed"].min() < n_traj
    bare = simulate(base.with_overrides({"av.shield": "off"}), 3)
    assert np.isnan(bare.log["av_model_confidence"]).all()
    assert (bare.log["av_n_allowed"] == n_traj).all()
    untracked = simulate(base.with_overrides({"mpc.confidence_filter": False}), 3)
    assert np.isnan(untracked.log["av_model_confidence"]).all()


def test_outside_simulators_plan_with_the_closed_loops_planner():
    """The adapter's per-vehicle planner proposes what Planner(config) proposes, confidence
    filter and shield awareness included (before, it planned with the shield switched off
    and so without either), and the one shield over all vehicles then decides as the
    Planner's own does for a single vehicle."""
    config = Config(mode="corrected").with_overrides({"hv.kind": "adversary"})
    record = simulate(config, 3)
    _, P_av, P_hv, _ = static_setup(config)
    occ_av = (float(P_av[slot.OCC_LO]), float(P_av[slot.OCC_HI]))
    occ_hv = (float(P_hv[slot.OCC_LO]), float(P_hv[slot.OCC_HI]))
    outside = X.ExternalPlanner(config, seed=0)
    alone = Planner(config, seed=0)
    unaware = Planner(config.with_overrides({"av.shield": "off"}), seed=0)
    differs = 0
    for s_av, v_av, s_hv, v_hv in record.states[:-1]:
        if not (s_av < outside._clear_m and s_hv < outside._clear_m):
            break
        c = X.Conflict("hv", X.CROSSING, float(s_av), float(s_hv), float(v_hv), occ_av, occ_hv)
        decision = outside.act(float(v_av), [c], config.simulation.dt_s)
        plan = alone.plan((s_av, v_av), (s_hv, v_hv))
        assert decision.proposed_mps2 == plan.proposed_accel_mps2
        assert (decision.accel_mps2, decision.verdict) == (plan.accel_mps2, plan.shield_verdict)
        differs += unaware.accel((s_av, v_av), (s_hv, v_hv)) != plan.proposed_accel_mps2
    assert differs > 0  # the planner without its shield features is another planner here


# -- non-finite proposals ------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_proposal_is_never_admitted(bad):
    """NaN compares false everywhere, so the reach times once took it as a constant speed and
    admitted it: the filter now applies a fallback (finite) in every state."""
    config = Config(mode="corrected")
    filt, C = _closed_loop_filter(config)
    rng = np.random.default_rng(11)
    u_min, u_max = C[sh.C_R_UMIN], C[sh.C_R_UMAX]
    seen = set()
    for _ in range(300):
        x_R = (rng.uniform(-40.0, 10.0), rng.uniform(0.0, 8.0))
        x_H = (rng.uniform(-40.0, 10.0), rng.uniform(0.0, 8.0))
        a, code = filt.one(bad, x_R, x_H)
        assert code in (sh.BRAKE, sh.GO, sh.UNCERTIFIED) and a in (u_min, u_max)
        seen.add(code)
    assert {sh.BRAKE, sh.GO} <= seen
    among = ShieldFilter("worst-case", 0.1, -4.5)
    empty = np.zeros(0)
    assert among.among(bad, 5.0, empty, empty, empty, np.zeros((0, sh.N_CONFLICT))) == \
        (-4.5, sh.BRAKE)
    off, _ = _closed_loop_filter(config.with_overrides({"av.shield": "off"}))
    with pytest.raises(ValueError, match=r"non-finite acceleration .* \(av\.shield = off\)"):
        off.one(bad, (-20.0, 4.0), (-20.0, 4.0))


class _Proposer:
    """An AV policy that proposes NaN at step 5 and full throttle otherwise."""

    log_columns = ()
    needs_game = False

    def reset(self, context, rng):
        self.k = -1

    def act(self, observation):
        self.k += 1
        return math.nan if self.k == 5 else 1.0


def test_no_world_propagates_a_non_finite_state():
    from persuasive.world import PythonWorld

    config = Config(mode="corrected")
    world = PythonWorld(config, 3, av=_Proposer())
    while not world.done:
        world.step()
    record = world.record()
    assert np.isfinite(record.states).all()
    assert math.isnan(record.log["av_proposed_accel_mps2"][5])
    assert record.log["shield_verdict"][5] in (sh.BRAKE, sh.GO, sh.UNCERTIFIED)
    assert np.isfinite(record.log["av_accel_mps2"]).all()
    bare = PythonWorld(config.with_overrides({"av.shield": "off"}), 3, av=_Proposer())
    with pytest.raises(ValueError, match="non-finite"):
        while not bare.done:
            bare.step()
    assert np.isfinite(bare.states[:bare.k + 1]).all()

    class NaNHuman(_Proposer):
        def act(self, observation):
            return math.nan

    human = PythonWorld(config, 3, hv=NaNHuman())
    with pytest.raises(ValueError, match="human's policy returned a non-finite"):
        human.step()


def test_the_adapter_replaces_a_non_finite_proposal():
    config = Config(mode="corrected")
    planner = X.ExternalPlanner(config)
    c = X.Conflict(0, X.CROSSING, -12.76, -15.0, 4.0, (-4.9, 4.9), (-4.9, 4.9))
    a, verdict = planner.shield(5.0, math.nan, [c], 0.1)
    assert math.isfinite(a) and verdict in ("brake", "go", "uncertified")
    bare = X.ExternalPlanner(config.with_overrides({"av.shield": "off"}))
    with pytest.raises(ValueError, match="non-finite"):
        bare.shield(5.0, math.nan, [c], 0.1)
    assert bare.shield(5.0, 0.5, [c], 0.1) == (0.5, None)


def test_every_run_says_whether_the_guarantee_held():
    from persuasive.record import outcome

    shielded = simulate(Config(mode="corrected"), 3)
    assert shielded.outcome.uncertified_steps == 0 and shielded.outcome.guarantee_held
    assert not simulate(Config(mode="paper"), 3).outcome.guarantee_held  # no shield
    responsive = simulate(Config(mode="corrected").with_overrides(
        {"av.shield": "responsive"}), 3)
    assert not responsive.outcome.guarantee_held  # it rests on the human responding
    noisy = simulate(Config(mode="corrected").with_overrides(
        {"simulation.measurement_noise": "gaussian", "simulation.noise_s_m": 0.2}), 3)
    assert not noisy.outcome.guarantee_held  # unbounded noise: outside the guarantee
    boxed = simulate(Config(mode="corrected").with_overrides(
        {"simulation.measurement_noise": "uniform", "simulation.noise_s_m": 0.2}), 3)
    # bounded noise the shield certifies against, every step certified: the guarantee held
    assert boxed.outcome.uncertified_steps == 0 and boxed.outcome.guarantee_held
    known = simulate(Config(mode="corrected").with_overrides(
        {"simulation.accel_noise_mps2": 0.3}), 3)
    assert known.outcome.guarantee_held  # the acceleration noise it certifies against
    log = {k: v.copy() for k, v in shielded.log.items()}
    log["shield_verdict"][[4, 9]] = sh.UNCERTIFIED
    out = outcome(shielded.scenario, shielded.states, log)
    assert out.uncertified_steps == 2 and not out.guarantee_held
    assert out.first_at_line == shielded.outcome.first_at_line  # the rest as before
