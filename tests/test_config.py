"""The validated, frozen configuration (spec sections 1-9; STYLE "Parameters").

Defaults are the paper's values; invalid values raise :class:`ConfigError` with a one-line
message naming the field and the allowed range; dicts and TOML files round-trip; quirks resolve
per mode unless set explicitly.
"""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from persuasive import _packed as K
from persuasive._packed import pack
from persuasive.config import (Config, ConfigError, LibraryParams, MPCParams, Quirks,
                               RewardParams, RoleParams, ScenarioParams, SimulationParams,
                               VehicleParams)

# -- defaults -----------------------------------------------------------------------------------


def test_defaults_are_the_papers_values():
    c = Config()
    v, lib, rw, roles = c.vehicle, c.library, c.reward, c.roles
    # vehicle [m], [m/s], [m/s^2]
    assert (v.length_m, v.width_m, v.lane_width_m) == (5.0, 2.5, 4.0)
    assert (v.v_min_mps, v.v_max_mps, v.u_min_mps2, v.u_max_mps2) == (0.0, 10.0, -2.0, 1.0)
    assert v.stop_distance_m == 6.5  # lane width + length / 2 [m]
    assert v.min_dist_m == 7.5  # 1.5 * length [m]
    assert v.collision_half_extent_m == 3.75  # (length + width) / 2 [m]
    # library: 50 samples of 0.1 s (T = 5 s), 10 mesh speeds + keep-speed = 11 trajectories
    assert (lib.n_samples, lib.sample_dt_s, lib.n_mesh) == (50, 0.1, 10)
    assert lib.horizon_s == 5.0 and lib.n_traj == 11
    assert (lib.alpha, lib.beta, lib.kappa, lib.h_st_m) == (0.4, 0.5, 0.6, 5.0)
    # rewards, roles, MPC
    assert (rw.w_c, rw.w_u, rw.discount) == (100.0, 0.1, 0.99)
    assert (roles.p_a, roles.adapt_role, roles.prior_leader) == (1.0, True, 0.5)
    assert (roles.w_s_m2, roles.w_v_m2ps2) == (0.03, 0.01)  # W = diag(0.03, 0.01)
    assert c.mpc.epsilon == 0.02
    assert c.p_a_hat == 1.0  # unset p_a_hat follows p_a
    # scenario [m], [m/s] and simulation [s]
    sc = c.scenario
    assert (sc.av_s0_m, sc.av_v0_mps, sc.hv_s0_m, sc.hv_v0_mps) == (-20.0, 4.0, -20.0, 4.0)
    assert (sc.hv_s0_halfwidth_m, sc.hv_v0_halfwidth_mps) == (5.0, 1.0)
    assert (sc.av_s0_halfwidth_m, sc.av_v0_halfwidth_mps) == (0.0, 0.0)
    assert (c.simulation.dt_s, c.simulation.n_steps) == (0.1, 61)
    assert (c.simulation.av, c.simulation.hv_role) == ("mpc", "leader")


def test_packed_vector_holds_the_defaults():
    P = pack(Config())
    assert (P[K.STOP_DIST], P[K.MIN_DIST], P[K.HORIZON]) == (6.5, 7.5, 5.0)
    assert P[K.H_GO] == 5.0 + 10.0 / 0.6  # h_go = h_st + v_max / kappa [m]
    assert (P[K.W_C], P[K.W_U], P[K.EPSILON]) == (100.0, 0.1, 0.02)


def test_config_is_frozen():
    c = Config()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.mode = "corrected"
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.mpc.epsilon = 0.5


# -- validation ---------------------------------------------------------------------------------


def raises(build, *fragments):
    """``build()`` raises ConfigError whose one-line message contains every fragment."""
    with pytest.raises(ConfigError) as info:
        build()
    msg = str(info.value)
    assert "\n" not in msg
    for fragment in fragments:
        assert fragment in msg, msg
    return msg


@pytest.mark.parametrize("p_a", [-0.1, 1.5])
def test_p_a_outside_the_unit_interval(p_a):
    raises(lambda: RoleParams(p_a=p_a), "roles.p_a", "[0, 1]")
    raises(lambda: Config().with_overrides({"roles.p_a": p_a}), "roles.p_a", "[0, 1]")


@pytest.mark.parametrize("eps", [0.0, 1.0, -0.5, 2.0])
def test_epsilon_outside_the_open_unit_interval(eps):
    raises(lambda: MPCParams(epsilon=eps), "mpc.epsilon", "(0, 1)")


def test_p_a_hat_outside_the_unit_interval():
    raises(lambda: MPCParams(p_a_hat=1.2), "mpc.p_a_hat", "[0, 1]")


@pytest.mark.parametrize("u_min", [0.0, 0.5])
def test_u_min_not_negative(u_min):
    raises(lambda: VehicleParams(u_min_mps2=u_min), "vehicle.u_min_mps2", "(-inf, 0)")


def test_u_max_not_positive():
    raises(lambda: VehicleParams(u_max_mps2=0.0), "vehicle.u_max_mps2", "(0, inf)")


@pytest.mark.parametrize("v_max", [5.0, 4.0])
def test_v_max_not_above_v_min(v_max):
    raises(lambda: VehicleParams(v_min_mps=5.0, v_max_mps=v_max), "vehicle.v_max_mps", "(5, inf)")


@pytest.mark.parametrize("dt", [0.0, -0.1])
def test_non_positive_time_steps(dt):
    raises(lambda: SimulationParams(dt_s=dt), "simulation.dt_s", "(0, 10]")
    raises(lambda: LibraryParams(sample_dt_s=dt), "library.sample_dt_s", "(0, 10]")


def test_simulation_step_must_equal_the_sample_step():
    raises(lambda: Config().with_overrides({"simulation.dt_s": 0.2}), "simulation.dt_s",
           "library.sample_dt_s")


@pytest.mark.parametrize("s0", [0.0, 3.0])
def test_initial_state_at_or_past_the_conflict_point(s0):
    raises(lambda: ScenarioParams(hv_s0_m=s0), "scenario.hv_s0_m", "(-inf, 0)")
    raises(lambda: ScenarioParams(av_s0_m=s0), "scenario.av_s0_m", "(-inf, 0)")


def test_initial_range_reaching_the_conflict_point():
    # -3 + U(-5, 5) can start past the conflict point
    raises(lambda: ScenarioParams(hv_s0_m=-3.0), "scenario.hv_s0_m", "hv_s0_halfwidth_m", "< 0")


def test_initial_speed_range_outside_the_speed_limits():
    raises(lambda: Config().with_overrides({"scenario.hv_v0_mps": 9.5}), "scenario.hv_v0_mps",
           "[0, 10]")


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_nan_and_infinity(bad):
    raises(lambda: RewardParams(w_c=bad), "reward.w_c", "finite")
    raises(lambda: RoleParams(p_a=bad), "roles.p_a", "finite")
    raises(lambda: MPCParams(epsilon=bad), "mpc.epsilon", "finite")
    raises(lambda: Config().with_overrides({"vehicle.v_max_mps": bad}), "vehicle.v_max_mps",
           "finite")


def test_unknown_mode_and_role():
    raises(lambda: Config(mode="fast"), "mode", "paper | corrected")
    raises(lambda: Config().with_overrides({"mode": "fast"}), "mode", "paper | corrected")
    raises(lambda: SimulationParams(hv_role="boss"), "simulation.hv_role", "leader | follower")
    raises(lambda: SimulationParams(av="human"), "simulation.av", "mpc | lfg")


def test_wrong_types():
    raises(lambda: RoleParams(adapt_role=1), "roles.adapt_role", "true | false")
    raises(lambda: LibraryParams(n_samples=5.0), "library.n_samples", "integer")
    raises(lambda: RoleParams(p_a="1"), "roles.p_a", "finite number")
    raises(lambda: Quirks(q1_branch_time_offset="yes"), "quirks.q1_branch_time_offset")
    raises(lambda: Quirks(q7_arrival_tolerance_m=-0.1), "quirks.q7_arrival_tolerance_m",
           "[0, inf)")


def test_unknown_section_or_key():
    raises(lambda: Config.from_dict({"solver": {"x": 1}}), "solver", "mpc", "vehicle")
    raises(lambda: Config.from_dict({"mpc": {"epsilonn": 0.1}}), "mpc.epsilonn", "epsilon")
    raises(lambda: Config().with_overrides({"mpc.epsilonn": 0.1}), "mpc.epsilonn")
    raises(lambda: Config().with_overrides({"epsilon": 0.1}), "epsilon", "section.field")
    raises(lambda: Config.from_dict({"mpc": 3}), "[mpc]", "table")


def test_malformed_toml_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[mpc\nepsilon = 0.05\n")
    raises(lambda: Config.from_toml(path), "bad.toml", "not valid TOML")


def test_unknown_key_in_toml_file(tmp_path):
    path = tmp_path / "typo.toml"
    path.write_text('mode = "corrected"\n[roles]\npa = 0.5\n')
    raises(lambda: Config.from_toml(path), "roles.pa", "p_a")


def test_missing_toml_file(tmp_path):
    raises(lambda: Config.from_toml(tmp_path / "nowhere.toml"), "nowhere.toml", "cannot be read")


# -- building and round trips -------------------------------------------------------------------


def to_toml(data: dict) -> str:
    """A minimal TOML writer for :meth:`Config.to_dict` output (scalars in one-level tables)."""

    def value(x):
        if isinstance(x, bool):
            return "true" if x else "false"
        if isinstance(x, str):
            return json.dumps(x)
        return repr(x)

    lines = [f"mode = {value(data['mode'])}"]
    for section, fields in data.items():
        if section == "mode":
            continue
        lines.append(f"[{section}]")
        lines += [f"{k} = {value(v)}" for k, v in fields.items()]
    return "\n".join(lines) + "\n"


CONFIGS = [
    Config(),
    Config(mode="corrected"),
    Config().with_overrides({"mpc.epsilon": 0.05, "roles.p_a": 0.7, "mpc.p_a_hat": 0.95,
                             "simulation.hv_role": "follower", "roles.adapt_role": False,
                             "quirks.q5_leader_agg_max": True,
                             "quirks.q7_arrival_tolerance_m": 0.0}),
    Config(mode="corrected", simulation=SimulationParams(av="lfg", n_steps=5)),
]


@pytest.mark.parametrize("c", CONFIGS)
def test_dict_round_trip(c):
    assert Config.from_dict(c.to_dict()) == c


@pytest.mark.parametrize("c", CONFIGS)
def test_toml_round_trip(c, tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(to_toml(c.to_dict()))
    assert Config.from_toml(path) == c


def test_with_overrides_changes_only_what_it_names():
    base = Config()
    c = base.with_overrides({"mpc.epsilon": 0.05, "roles.p_a": 0.7})
    assert (c.mpc.epsilon, c.roles.p_a) == (0.05, 0.7)
    assert c.p_a_hat == 0.7  # unset p_a_hat follows p_a
    assert dataclasses.replace(c, mpc=base.mpc, roles=base.roles) == base
    assert base.mpc.epsilon == 0.02  # the original is untouched


def test_integers_are_accepted_for_float_fields(tmp_path):
    c = Config().with_overrides({"reward.w_c": 50})
    assert c.reward.w_c == 50.0 and isinstance(c.reward.w_c, float)
    path = tmp_path / "ints.toml"
    path.write_text("[vehicle]\nv_max_mps = 12\n")
    assert isinstance(Config.from_toml(path).vehicle.v_max_mps, float)


# -- quirks per mode ----------------------------------------------------------------------------

FIXED_IN_CORRECTED = ("q1_branch_time_offset", "q2_belief_offset", "q3_tie_break_leak",
                      "q5_leader_agg_max")
KEPT_IN_BOTH = ("q4_undiscounted_collision", "q6_time_like_stop_test")


@pytest.mark.parametrize("mode, expected", [("paper", True), ("corrected", False)])
def test_quirks_resolve_per_mode(mode, expected):
    q = Config(mode=mode).effective_quirks
    for name in FIXED_IN_CORRECTED:
        assert getattr(q, name) is expected, name
    for name in KEPT_IN_BOTH:
        assert getattr(q, name) is True, name
    assert q.q7_arrival_tolerance_m == 0.2  # [m]
    P = pack(Config(mode=mode))
    assert (P[K.Q1], P[K.Q2], P[K.Q5]) == (float(expected),) * 3
    assert (P[K.Q4], P[K.Q6]) == (1.0, 1.0)


def test_explicit_quirk_overrides_the_mode():
    c = Config(mode="corrected",
               quirks=Quirks(q5_leader_agg_max=True, q6_time_like_stop_test=False))
    q = c.effective_quirks
    assert q.q5_leader_agg_max is True and q.q6_time_like_stop_test is False
    assert q.q1_branch_time_offset is False  # the rest still follows the mode
    c = Config(mode="paper", quirks=Quirks(q1_branch_time_offset=False))
    assert c.effective_quirks.q1_branch_time_offset is False
    assert c.effective_quirks.q2_belief_offset is True


def test_switching_mode_keeps_only_explicit_quirks():
    c = Config(quirks=Quirks(q5_leader_agg_max=True)).with_overrides({"mode": "corrected"})
    q = c.effective_quirks
    assert q.q5_leader_agg_max is True  # explicit: kept
    assert q.q1_branch_time_offset is False  # unset: follows the new mode
    assert Config().with_overrides({"mode": "corrected"}).effective_quirks == \
        Config(mode="corrected").effective_quirks
