"""The validated, frozen configuration (spec sections 1-9; STYLE "Parameters").

Defaults are the paper's values; invalid values raise :class:`ConfigError` with a one-line
message naming the field and the allowed range; dicts and TOML files round-trip; quirks resolve
per mode unless set explicitly.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from persuasive import packing as slot
from persuasive.config import (AVParams, Config, ConfigError, HVParams, LibraryParams,
                               MPCParams, Quirks, RewardParams, RoleParams, ScenarioParams,
                               SimulationParams, VehicleOverrides, VehicleParams)
from persuasive.packing import pack, sqrt_threshold
from persuasive.scenarios import build_scenario

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
    # scenario [m], [m/s] and simulation [s]: the nominal starts are left to the scenario,
    # which puts them 13.5 m before the crossing line: -6.5 - 13.5 = -20 m
    sc = c.scenario
    assert sc.kind == "intersection"
    assert (sc.av_s0_m, sc.av_v0_mps, sc.hv_s0_m, sc.hv_v0_mps) == (None, 4.0, None, 4.0)
    scene = build_scenario(c)
    assert (scene.nominal_s0("av"), scene.nominal_s0("hv")) == (-20.0, -20.0)
    assert (sc.hv_s0_halfwidth_m, sc.hv_v0_halfwidth_mps) == (5.0, 1.0)
    assert (sc.av_s0_halfwidth_m, sc.av_v0_halfwidth_mps) == (0.0, 0.0)
    assert (c.simulation.dt_s, c.simulation.n_steps) == (0.1, 61)
    # the agents: the paper's persuasive MPC against the LFG human, who starts as leader
    assert (c.av.kind, c.av.role, c.hv.kind, c.hv.role) == ("persuasive", None, "lfg", "leader")
    # the random streams follow the mode: the reference's single stream in paper mode
    assert c.simulation.streams is None
    assert (c.streams, Config(mode="corrected").streams) == ("legacy", "per-agent")
    # no vehicle overrides: both vehicles are [vehicle]
    assert c.vehicle_of("av") == c.vehicle_of("hv") == v


def test_old_av_name_mpc_is_the_persuasive_planner():
    assert AVParams(kind="mpc").kind == "persuasive"
    assert Config().with_overrides({"av.kind": "mpc"}) == Config()


def test_packed_vectors_hold_the_defaults():
    P_av, P_hv = pack(Config(), build_scenario(Config()))
    assert P_av.shape == P_hv.shape == (slot.N_SLOTS,)
    scene = build_scenario(Config())
    assert scene.av.zone == scene.hv.zone == (-7.5, 7.5) and scene.min_dist_m == 7.5
    for P in (P_av, P_hv):
        # the crossing line -(4 + 5 / 2) [m] both stops the stop trajectory and decides who
        # went first; the conflict zone is |s| < 7.5 m, cleared 7.5 m past the conflict point
        assert (P[slot.YIELD_S], P[slot.FIRST_S], P[slot.CLEAR_S]) == (-6.5, -6.5, 7.5)
        # the kernels' window of the zone |s| < 7.5 may be a little wider, never narrower
        assert -7.5 - 1e-6 < P[slot.ZONE_LO] <= -7.5 and 7.5 <= P[slot.ZONE_HI] < 7.5 + 1e-6
        assert (P[slot.MIN_DIST], P[slot.HORIZON]) == (7.5, 5.0)
        assert P[slot.MIN_DIST_SQ] == sqrt_threshold(7.5) == 56.25
        # the kernels' distance sqrt(s_av^2 + s_hv^2) (kind 0; the other kind, euclidean, is 1)
        assert P[slot.CONFLICT] == 0.0
        assert P[slot.LANE_SHARED] == 0.0
        assert P[slot.H_GO] == 5.0 + 10.0 / 0.6  # h_go = h_st + v_max / kappa [m]
        assert (P[slot.W_C], P[slot.W_U], P[slot.EPSILON]) == (100.0, 0.1, 0.02)
        assert (P[slot.V_MIN], P[slot.V_MAX], P[slot.U_MIN], P[slot.U_MAX]) == (
            0.0, 10.0, -2.0, 1.0)
        assert (P[slot.LENGTH], P[slot.WIDTH]) == (5.0, 2.5)
    # the AV drives along +x, the HV along +y, both straight through the origin: the two
    # vectors differ in the path's direction and nowhere else
    path = slice(slot.PATH_B1, slot.PATH_UY2 + 1)
    assert (P_av[slot.PATH_UX0], P_av[slot.PATH_UY0]) == (1.0, 0.0)
    assert (P_hv[slot.PATH_UX0], P_hv[slot.PATH_UY0]) == (0.0, 1.0)
    differ = {slot.SLOT_NAMES[i] for i in np.flatnonzero(P_av != P_hv)}
    assert differ == {"PATH_UX0", "PATH_UY0", "PATH_UX2", "PATH_UY2"}
    np.testing.assert_array_equal(np.delete(P_av, np.r_[path]), np.delete(P_hv, np.r_[path]))


def test_per_vehicle_slots_follow_each_vehicles_overrides():
    # The HV 4 m long with v_max = 8 m/s and u_min = -3 m/s^2: its own limits, length and
    # crossing line -(4 + 4 / 2) = -6 m; the pair's safety distance is 1.5 (5 + 4) / 2 = 6.75 m
    # (shared); the AV keeps [vehicle]'s values.
    c = Config(hv=HVParams(vehicle=VehicleOverrides(length_m=4.0, v_max_mps=8.0,
                                                    u_min_mps2=-3.0)))
    P_av, P_hv = pack(c, build_scenario(c))
    assert (P_hv[slot.V_MAX], P_hv[slot.U_MIN], P_hv[slot.LENGTH]) == (8.0, -3.0, 4.0)
    assert (P_av[slot.V_MAX], P_av[slot.U_MIN], P_av[slot.LENGTH]) == (10.0, -2.0, 5.0)
    assert (P_hv[slot.YIELD_S], P_av[slot.YIELD_S]) == (-6.0, -6.5)
    assert P_hv[slot.H_GO] == 5.0 + 8.0 / 0.6 and P_av[slot.H_GO] == 5.0 + 10.0 / 0.6
    for P in (P_av, P_hv):
        assert P[slot.MIN_DIST] == 6.75 and P[slot.MIN_DIST_SQ] == sqrt_threshold(6.75)
        assert P[slot.CLEAR_S] == 6.75
        assert -6.75 - 1e-6 < P[slot.ZONE_LO] <= -6.75 <= 6.75 <= P[slot.ZONE_HI] < 6.75 + 1e-6
    scene = build_scenario(c)
    assert scene.av.zone == scene.hv.zone == (-6.75, 6.75) and scene.min_dist_m == 6.75
    shared = slice(0, slot.V_MIN)  # every slot before the per-vehicle ones
    np.testing.assert_array_equal(P_av[shared], P_hv[shared])


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


@pytest.mark.parametrize("eps", [0.0, 1e-13, math.nextafter(1e-12, 0.0), 1.0, -0.5, 2.0])
def test_epsilon_outside_its_range(eps):
    # below 1e-12 the threshold 1 - epsilon is (nearly) 1 and no candidate is ever feasible
    raises(lambda: MPCParams(epsilon=eps), "mpc.epsilon", "[1e-12, 1)")


@pytest.mark.parametrize("eps", [1e-12, 0.5, math.nextafter(1.0, 0.0)])
def test_epsilon_at_the_edges_of_its_range(eps):
    assert MPCParams(epsilon=eps).epsilon == eps


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


def scene_of(overrides):
    return build_scenario(Config().with_overrides(overrides))


@pytest.mark.parametrize("s0", [0.0, 3.0])
def test_initial_state_at_or_past_the_conflict_point(s0):
    # The conflict zone starts at -min_dist = -7.5 m: the HV's -s0 +- 5 m and the AV's exact
    # s0 lie inside it. The message names the field and the bound (-7.5 - half-width).
    raises(lambda: scene_of({"scenario.hv_s0_m": s0}), "scenario.hv_s0_m", "conflict zone")
    raises(lambda: scene_of({"scenario.av_s0_m": s0}), "scenario.av_s0_m", "conflict zone",
           "below -7.50 m")
    assert ScenarioParams(hv_s0_m=s0).hv_s0_m == s0  # the section alone cannot know the zone


def test_initial_range_inside_the_conflict_zone():
    # -2.5 + U(-5, 5) lies in [-7.5, 2.5): every start inside the zone (which is open at
    # -7.5), an error; a micrometre lower, some starts lie before the zone and the draw's
    # retry rule decides (the old rule "s0 + half-width < 0" refused -3 + U(-5, 5) outright)
    raises(lambda: scene_of({"scenario.hv_s0_m": -2.5}), "scenario.hv_s0_m", "half-width 5")
    scene_of({"scenario.hv_s0_m": -2.500001})
    scene_of({"scenario.hv_s0_m": -3.0})
    # the AV has zero half-width: its start must lie before -7.5 itself
    raises(lambda: scene_of({"scenario.av_s0_m": -7.5}), "scenario.av_s0_m")
    scene_of({"scenario.av_s0_m": math.nextafter(-7.5, -math.inf)})


def test_start_error_states_the_bound_it_enforces():
    # scenario.hv_s0_m = 0 with half-width 5 is refused and -3 is accepted (above), so the
    # allowed range the message states must be s0 below -7.5 + 5 = -2.5 m
    raises(lambda: scene_of({"scenario.hv_s0_m": 0.0}), "scenario.hv_s0_m", "below -2.50 m")


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
    raises(lambda: HVParams(role="boss"), "hv.role", "leader | follower")
    raises(lambda: AVParams(role="boss"), "av.role", "leader | follower")
    raises(lambda: AVParams(kind="human"), "av.kind", "persuasive | passive | cv | lfg | yield")
    raises(lambda: HVParams(kind="robot"), "hv.kind",
           "lfg | stubborn | noisy | idm | aggressive | replay")
    raises(lambda: ScenarioParams(kind="roundabout"), "scenario.kind",
           "intersection | crossing | left-turn | merge")
    raises(lambda: SimulationParams(streams="shared"), "simulation.streams",
           "legacy | per-agent")
    raises(lambda: Config().with_overrides({"hv.vehicle.v_max_mps": -1.0}),
           "hv.vehicle.v_max_mps")


@pytest.mark.parametrize("old, new, value", [("av", "av.kind", "lfg"),
                                             ("hv_role", "hv.role", "follower")])
def test_moved_keys_say_where_they_went(old, new, value):
    raises(lambda: Config.from_dict({"simulation": {old: value}}), f"simulation.{old}",
           f"moved to {new}")
    raises(lambda: Config().with_overrides({f"simulation.{old}": value}), f"simulation.{old}",
           f"moved to {new}")


def test_wrong_types():
    raises(lambda: RoleParams(adapt_role=1), "roles.adapt_role", "true | false")
    raises(lambda: LibraryParams(n_samples=5.0), "library.n_samples", "integer")
    raises(lambda: RoleParams(p_a="1"), "roles.p_a", "finite number")
    raises(lambda: Quirks(q1_branch_time_offset="yes"), "quirks.q1_branch_time_offset")
    raises(lambda: Quirks(q7_arrival_tolerance_m=-0.1), "quirks.q7_arrival_tolerance_m",
           "[0, inf)")


def test_unknown_section_or_key():
    raises(lambda: Config.from_dict({"solver": {"x": 1}}), "unknown section 'solver'; allowed:",
           "mpc", "vehicle", "av", "hv")
    raises(lambda: Config.from_dict({"mpc": {"epsilonn": 0.1}}),
           "mpc.epsilonn: unknown key; allowed: epsilon, p_a_hat")
    raises(lambda: Config.from_dict({"hv": {"idm": {"gap": 1.0}}}), "hv.idm.gap: unknown key",
           "time_gap_s")
    raises(lambda: Config().with_overrides({"hv.idmx.gap": 1.0}), "hv.idmx", "idm")
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
    """A minimal TOML writer for :meth:`Config.to_dict` output (scalars in nested tables),
    independent of :meth:`Config.to_toml`."""

    def value(x):
        if isinstance(x, bool):
            return "true" if x else "false"
        if isinstance(x, str):
            return json.dumps(x)
        return repr(x)

    def table(name, fields):
        lines = [f"[{name}]"] + [f"{k} = {value(v)}" for k, v in fields.items()
                                 if not isinstance(v, dict)]
        for k, v in fields.items():
            if isinstance(v, dict):
                lines += table(f"{name}.{k}", v)
        return lines

    lines = [f"mode = {value(data['mode'])}"]
    for section, fields in data.items():
        if section != "mode":
            lines += table(section, fields)
    return "\n".join(lines) + "\n"


CONFIGS = [
    Config(),
    Config(mode="corrected"),
    Config().with_overrides({"mpc.epsilon": 0.05, "roles.p_a": 0.7, "mpc.p_a_hat": 0.95,
                             "hv.role": "follower", "roles.adapt_role": False,
                             "quirks.q5_leader_agg_max": True,
                             "quirks.q7_arrival_tolerance_m": 0.0}),
    Config(mode="corrected", simulation=SimulationParams(n_steps=5), av=AVParams(kind="lfg")),
    Config().with_overrides({"av.kind": "lfg", "av.role": "leader", "hv.kind": "idm",
                             "hv.idm.time_gap_s": 2.0, "hv.vehicle.v_max_mps": 8.0,
                             "scenario.kind": "crossing", "scenario.angle_deg": 60.0,
                             "scenario.hv_s0_m": -25.0, "simulation.streams": "per-agent"}),
]


@pytest.mark.parametrize("c", CONFIGS)
def test_dict_round_trip(c):
    assert Config.from_dict(c.to_dict()) == c


@pytest.mark.parametrize("c", CONFIGS)
def test_toml_round_trip(c, tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(to_toml(c.to_dict()))
    assert Config.from_toml(path) == c
    path.write_text(c.to_toml())
    assert Config.from_toml(path) == c


def test_toml_text_and_digest_identify_the_configuration():
    texts = [c.to_toml() for c in CONFIGS]
    assert len(set(texts)) == len(CONFIGS)
    # equal configurations built two ways give equal text and digests
    same = Config().with_overrides({"mpc.epsilon": 0.05})
    other = Config(mpc=MPCParams(epsilon=0.05))
    assert same.to_toml() == other.to_toml() and same.digest() == other.digest()
    digest = Config().digest()
    assert len(digest) == 10 and int(digest, 16) >= 0
    assert Config().digest(1, 1000) != digest != Config(mode="corrected").digest()
    assert Config().digest(1, 1000) == Config().digest(1, 1000)


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
    for P in pack(Config(mode=mode), build_scenario(Config(mode=mode))):
        assert (P[slot.QUIRK_BRANCH_OFFSET], P[slot.QUIRK_BELIEF_OFFSET],
                P[slot.QUIRK_LEADER_AGG_MAX]) == (float(expected),) * 3
        assert (P[slot.QUIRK_UNDISCOUNTED_COLLISION], P[slot.QUIRK_TIME_LIKE_STOP_TEST]) == (
            1.0, 1.0)


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


@pytest.mark.parametrize("kind, good, bad", [
    ("crossing", [15.0, 60.0, 90.0, 165.0], [0.001, 14.99, 165.01, 179.9]),
    ("merge", [15.0, 30.0, 90.0], [0.001, 14.99, 90.01, 120.0]),
])
def test_crossing_and_merge_angles_are_bounded_to_meaningful_geometry(kind, good, bad):
    for angle in good:
        config = Config().with_overrides({"scenario.kind": kind, "scenario.angle_deg": angle})
        scenario = build_scenario(config)
        # the conflict starts within four safety distances of the conflict point, so the
        # vehicles start (13.5 m before their yield line) about 40 m away at most
        assert -scenario.hv.zone[0] <= 4.0 * scenario.min_dist_m
    lo, hi = {"crossing": (15, 165), "merge": (15, 90)}[kind]
    for angle in bad:
        with pytest.raises(ConfigError, match=rf"^scenario.angle_deg = {angle!r} is out of "
                                              rf"range; allowed: \[{lo}, {hi}\] degrees for "
                                              rf"a {kind} \("):
            Config().with_overrides({"scenario.kind": kind, "scenario.angle_deg": angle})


@pytest.mark.parametrize("make, message", [
    (lambda: RoleParams(p_a=float("nan")),
     "roles.p_a = nan is out of range; allowed: a finite number in [0, 1]"),
    (lambda: RoleParams(p_a=float("inf")),
     "roles.p_a = inf is out of range; allowed: a finite number in [0, 1]"),
    (lambda: RoleParams(w_s_m2=float("inf")),
     "roles.w_s_m2 = inf is out of range; allowed: a finite number in (0, inf)"),
    (lambda: MPCParams(p_a_hat=float("nan")),
     'mpc.p_a_hat = nan is out of range; allowed: a number in [0, 1] or "online"'),
    (lambda: MPCParams(p_a_hat=-float("inf")),
     'mpc.p_a_hat = -inf is out of range; allowed: a number in [0, 1] or "online"'),
    (lambda: MPCParams(p_a_hat=1.5),
     'mpc.p_a_hat = 1.5 is out of range; allowed: a number in [0, 1] or "online"'),
], ids=["p_a-nan", "p_a-inf", "w_s-inf", "p_a_hat-nan", "p_a_hat-minus-inf", "p_a_hat-1.5"])
def test_non_finite_values_are_out_of_range_with_the_range_named(make, message):
    with pytest.raises(ConfigError) as info:
        make()
    assert str(info.value) == message
