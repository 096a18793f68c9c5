"""The planner API: what a user gets from one call, and that it is the simulator's AV."""

import numpy as np
import pytest

from persuasive import Config, ConfigError, Planner, simulate
from persuasive.library import trajectory_library
from persuasive.packing import pack
from persuasive.scenarios import build_scenario


def test_defaults_to_corrected_mode_and_returns_a_full_plan():
    planner = Planner()
    assert planner.config.mode == "corrected"
    plan = planner.plan((-20.0, 4.0), (-22.0, 4.3))
    assert planner.kind == "persuasive"
    P_av = pack(planner.config, build_scenario(planner.config))[0]
    lib = trajectory_library(-20.0, 4.0, P_av)  # the AV's library
    k = plan.candidate
    np.testing.assert_array_equal(plan.s_m, lib.s[k])
    np.testing.assert_array_equal(plan.a_mps2, lib.a[k])
    assert plan.accel_mps2 == plan.a_mps2[0]
    np.testing.assert_allclose(plan.t_s, np.arange(1, 51) * 0.1)
    assert sum(plan.branch_probabilities.values()) == pytest.approx(1.0, abs=1e-12)
    assert plan.feasible and plan.chance_margin > 0
    assert plan.chance_margin == pytest.approx(plan.p_safe_min - 0.98)
    assert plan.candidates.shape == (11, 10)
    assert plan.expected_reward == plan.candidates[k, 0]
    # among the feasible candidates, the chosen one has the highest expected reward
    feasible = plan.candidates[:, 1] > 0.98
    assert plan.expected_reward == plan.candidates[feasible, 0].max()


@pytest.mark.parametrize("mode", ["paper", "corrected"])
def test_replaying_a_run_gives_the_runs_accelerations(mode):
    config = Config(mode=mode)
    record = simulate(config, 21)
    planner = Planner(config)
    for k, (s_av, v_av, s_hv, v_hv) in enumerate(record.states[:-1]):
        role = str(record.log["hv_next_role"][k]) if mode == "paper" else None
        plan = planner.plan((s_av, v_av), (s_hv, v_hv), human_role=role)
        assert plan.accel_mps2 == record.log["av_accel_mps2"][k]
        assert plan.candidate == record.log["av_trajectory"][k]
        assert plan.belief_hv_leader == record.log["av_belief_hv_leader"][k]


def test_reset_forgets_the_belief():
    planner = Planner()
    first = planner.plan((-20.0, 4.0), (-22.0, 4.3))
    planner.plan((-19.6, 4.0), (-21.5, 4.3))
    assert planner.belief_hv_leader != 0.5
    planner.reset()
    assert planner.belief_hv_leader == 0.5
    again = planner.plan((-20.0, 4.0), (-22.0, 4.3))
    assert again.candidate == first.candidate and again.accel_mps2 == first.accel_mps2


@pytest.mark.parametrize("av, hv, name", [
    ((-20.0, 11.0), (-22.0, 4.0), "av"),
    ((-20.0, 4.0), (float("nan"), 4.0), "hv"),
    ("fast", (-22.0, 4.0), "av"),
])
def test_bad_states(av, hv, name):
    with pytest.raises(ConfigError, match=name):
        Planner().plan(av, hv)


def test_paper_mode_needs_the_human_role():
    with pytest.raises(ConfigError, match="human_role"):
        Planner(Config(mode="paper")).plan((-20.0, 4.0), (-22.0, 4.3))


@pytest.mark.parametrize("overrides", [{"av.kind": "passive"},
                                       {"hv.vehicle.v_max_mps": 8.0,
                                        "hv.vehicle.u_min_mps2": -3.0}])
def test_replaying_other_configurations(overrides):
    # the passive planner, and vehicles with their own limits: still the simulator's AV
    config = Config(mode="corrected").with_overrides(overrides)
    record = simulate(config, 21)
    planner = Planner(config)
    assert planner.kind == config.av.kind
    for k, (s_av, v_av, s_hv, v_hv) in enumerate(record.states[:-1]):
        plan = planner.plan((s_av, v_av), (s_hv, v_hv))
        assert plan.accel_mps2 == record.log["av_accel_mps2"][k]
        assert plan.candidate == record.log["av_trajectory"][k]
        assert plan.belief_hv_leader == record.log["av_belief_hv_leader"][k]


def test_the_hvs_own_speed_limit_is_checked():
    planner = Planner(Config(mode="corrected").with_overrides({"hv.vehicle.v_max_mps": 8.0}))
    planner.plan((-20.0, 9.0), (-22.0, 8.0))  # the AV may drive 9 m/s, the HV 8 m/s
    with pytest.raises(ConfigError, match=r"hv = \(-22.0, 8.5\).*\[0, 8\]"):
        planner.plan((-20.0, 4.0), (-22.0, 8.5))


@pytest.mark.parametrize("kind", ["persuasive", "passive", "lfg"])
def test_accel_is_plan_without_the_plan(kind):
    # the many-vehicle adapter's entry point: the same proposals (before the shield, which
    # the adapter applies once over all vehicles), belief and draws as plan() on the same
    # states, call after call
    config = Config(mode="corrected").with_overrides({"av.kind": kind})
    record = simulate(config, 21)
    full, lean = Planner(config, seed=3), Planner(config, seed=3)
    for s_av, v_av, s_hv, v_hv in record.states[:-1]:
        a = lean.accel((s_av, v_av), (s_hv, v_hv))
        assert a == full.plan((s_av, v_av), (s_hv, v_hv)).proposed_accel_mps2
        np.testing.assert_equal(lean.belief_hv_leader, full.belief_hv_leader)  # NaN: lfg
    with pytest.raises(ConfigError, match="Q3"):
        Planner(Config(mode="paper")).accel((-20.0, 4.0), (-22.0, 4.3))
