"""Parameters packed into float64 vectors for the compiled kernels, one per vehicle.

Numba kernels take plain arrays; this module fixes, once, which slot of a vehicle's parameter
vector holds which parameter. The slot names are module constants, so inside the kernels they
are compile-time constants: ``P[slot.V_MAX]``. Each vehicle has its own vector (its limits,
its path and lines, its conflict-zone window); the shared parameters (library, rewards,
roles, MPC, quirks, the conflict) hold the same value in both. Boolean quirks are 0.0 / 1.0.

Kernels that build or score one vehicle's trajectories take that vehicle's vector; kernels
that only need shared values take either.
"""

from __future__ import annotations

import math

import numpy as np

_names: list[str] = []


def _slots(*names: str) -> range:
    start = len(_names)
    _names.extend(names)
    return range(start, len(_names))


# -- shared by both vehicles -------------------------------------------------------------------
# Trajectory library (docs/method.md §2)
N_SAMPLES, SAMPLE_DT, N_MESH, ALPHA, BETA, KAPPA, H_ST, HORIZON = _slots(
    "N_SAMPLES", "SAMPLE_DT", "N_MESH", "ALPHA", "BETA", "KAPPA", "H_ST", "HORIZON")
# Rewards (§3)
W_C, W_U = _slots("W_C", "W_U")
# Roles (§5) and the MPC (§6)
W_S, W_V, PRIOR_L, EPSILON = _slots("W_S", "W_V", "PRIOR_L", "EPSILON")
# Quirks (§9): Q1, Q2, Q4, Q5, Q6
(QUIRK_BRANCH_OFFSET, QUIRK_BELIEF_OFFSET, QUIRK_UNDISCOUNTED_COLLISION, QUIRK_LEADER_AGG_MAX,
 QUIRK_TIME_LIKE_STOP_TEST) = _slots("Q1", "Q2", "Q4", "Q5", "Q6")
# The conflict between the two paths (scenarios): its kind (``CONFLICT_*``), the safety
# distance, and ``MIN_DIST_SQ``: ``sqrt(x) < min_dist`` exactly when ``x < MIN_DIST_SQ``
# (see :func:`sqrt_threshold`)
CONFLICT, MIN_DIST, MIN_DIST_SQ = _slots("CONFLICT", "MIN_DIST", "MIN_DIST_SQ")
# 1.0 when the two paths share one lane past ``s = 0`` (a merge): a vehicle ahead there leads
LANE_SHARED = _slots("LANE_SHARED")[0]
# The safety shield (docs/method.md §12): its kind (``persuasive.safety.shield.SHIELD_*``), the
# responsive human's response time [s]; the MPC's use of it (candidates the shield rejects are
# infeasible: 0/1) and its model-confidence filter (threshold, 0 when the filter is off;
# acceleration width [m/s^2], switching probability per step)
SHIELD, SHIELD_RESPONSE, SHIELD_AWARE, CONF_THRESHOLD, CONF_STD, CONF_SWITCH = _slots(
    "SHIELD", "SHIELD_RESPONSE", "SHIELD_AWARE", "CONF_THRESHOLD", "CONF_STD", "CONF_SWITCH")
# The half-width of the uniform acceleration noise on both vehicles [m/s^2]
# (``simulation.accel_noise_mps2``), which the shield certifies against, and the shield's
# clearance between the footprints [m] (``av.shield_margin_m``)
ACCEL_NOISE, SHIELD_MARGIN = _slots("ACCEL_NOISE", "SHIELD_MARGIN")
# The shield's cut-in rule in a shared lane (``[responsibility]``, docs/method.md §12.10): the
# follower's reaction time [s], its acceleration during it and its braking after it [m/s^2,
# braking positive], and the AV's hardest braking in the lane ahead of it [m/s^2, positive]
RESP_RHO, RESP_ACCEL, RESP_BRAKE, RESP_FRONT_BRAKE = _slots(
    "RESP_RHO", "RESP_ACCEL", "RESP_BRAKE", "RESP_FRONT_BRAKE")
# Who has the right of way at the conflict under the responsibility rule
# (``responsibility.right_of_way``, docs/method.md §12.13): 1 the AV, -1 the other, 0 neither
RIGHT_OF_WAY = _slots("RIGHT_OF_WAY")[0]
# The half-widths of a uniform error on every measured position [m] and speed [m/s], which the
# shield certifies against (``simulation.measurement_noise = "uniform"``; 0 otherwise)
MEAS_S, MEAS_V = _slots("MEAS_S", "MEAS_V")

# -- per vehicle -------------------------------------------------------------------------------
# Limits and size (§1); ``H_GO = h_st + v_max / kappa`` of the OVM law (§2)
V_MIN, V_MAX, U_MIN, U_MAX, LENGTH, WIDTH, H_GO = _slots(
    "V_MIN", "V_MAX", "U_MIN", "U_MAX", "LENGTH", "WIDTH", "H_GO")
# Lines along the path [m]: the stop target of the library's stop trajectory (the crossing
# line, ``-stop_distance`` at the intersection), the line whose first arrival decides who
# went first, and the position past which the vehicle no longer conflicts with the other path
YIELD_S, FIRST_S, CLEAR_S = _slots("YIELD_S", "FIRST_S", "CLEAR_S")
# The conservative window of positions ``ZONE_LO < s < ZONE_HI`` [m] outside which the vehicle
# is at least ``min_dist`` from every point of the other path (euclidean conflicts)
ZONE_LO, ZONE_HI = _slots("ZONE_LO", "ZONE_HI")
# The interval of positions ``OCC_LO <= s <= OCC_HI`` [m] outside which the vehicle's footprint
# cannot touch the other's (``persuasive.geometry.occupancy_interval``); in a merge, the side
# zone up to the merge point (the shield and the surrogate safety measures, §12)
OCC_LO, OCC_HI = _slots("OCC_LO", "OCC_HI")
# The shield's occupancy interval [m]: ``OCC_LO..OCC_HI`` on footprints enlarged by the
# clearance ``SHIELD_MARGIN`` (the same without one); its yield line [m], where the vehicle
# stands when the shield makes it yield, at or before ``SHIELD_OCC_LO`` (``av.yield_line_m``
# before it; the human's is its ``SHIELD_OCC_LO``)
SHIELD_OCC_LO, SHIELD_OCC_HI, SHIELD_LINE = _slots("SHIELD_OCC_LO", "SHIELD_OCC_HI",
                                                   "SHIELD_LINE")
# The path: ``xy(s)`` in three pieces (``persuasive.geometry``): straight before ``B1``
# (direction ``U0``, through ``(X1, Y1)`` at ``B1``), an arc from ``B1`` to ``B2`` (centre,
# radius, polar angle at ``B1``, +1 left / -1 right; none when ``R == 0``), straight after ``B2``
# (direction ``U2`` through ``(X2, Y2)``)
(PATH_B1, PATH_B2, PATH_X1, PATH_Y1, PATH_UX0, PATH_UY0, PATH_CX, PATH_CY, PATH_R, PATH_PHI1,
 PATH_TURN, PATH_X2, PATH_Y2, PATH_UX2, PATH_UY2) = _slots(
    "PATH_B1", "PATH_B2", "PATH_X1", "PATH_Y1", "PATH_UX0", "PATH_UY0", "PATH_CX", "PATH_CY",
    "PATH_R", "PATH_PHI1", "PATH_TURN", "PATH_X2", "PATH_Y2", "PATH_UX2", "PATH_UY2")

N_SLOTS = len(_names)

#: Counters of the work the kernels do, in an int64 array ``work`` (``N_WORK``,) that the
#: callers pass down and the benchmark reports: pair tests of the games' reward matrices, pair
#: tests of the MPC (branch safety and the re-solve pruning), re-solves done and skipped by the
#: pruning, libraries built and reused (the loop's look-ahead cache).
(WORK_PAIRS_GAME, WORK_PAIRS_MPC, WORK_RESOLVES, WORK_RESOLVES_SKIPPED, WORK_LIBRARIES,
 WORK_LIBRARIES_REUSED) = range(6)
N_WORK = 6
WORK_NAMES = ("pair_tests_game", "pair_tests_mpc", "resolves", "resolves_skipped",
              "libraries_built", "libraries_reused")
#: Slot names, by index (for messages and tests).
SLOT_NAMES: tuple[str, ...] = tuple(_names)

#: Conflict kinds. ``ALONG_PATHS``: the distance combines each vehicle's distance along its path
#: to the conflict point, ``sqrt(s_a^2 + s_b^2)``, and the pair test is
#: ``s_a^2 + s_b^2 < MIN_DIST_SQ`` (the paper's intersection, bit for bit, and the left turn).
#: ``EUCLIDEAN``: the distance between the vehicles' centres ``xy(s)`` on their paths.
CONFLICT_ALONG_PATHS, CONFLICT_EUCLIDEAN = 0, 1


#: Shield kinds (``[av] shield``), by name: the kernels' ids.
SHIELD_OFF, SHIELD_WORST_CASE, SHIELD_RESPONSIVE, SHIELD_RESPONSIBILITY = 0, 1, 2, 3
SHIELD_KIND_IDS = {"off": SHIELD_OFF, "worst-case": SHIELD_WORST_CASE,
                   "responsive": SHIELD_RESPONSIVE, "responsibility": SHIELD_RESPONSIBILITY}

#: ``responsibility.right_of_way`` by name: the AV's right of way over the other vehicle
#: (:data:`RIGHT_OF_WAY` and the conflict vector's ``C_PRIORITY``).
RIGHT_OF_WAY_IDS = {None: 0.0, "av": 1.0, "hv": -1.0}

#: Relative widening of each zone for the kernels' windows (a window may be a superset).
ZONE_MARGIN = 1e-9


def sqrt_threshold(c: float) -> float:
    """The smallest double ``x`` with ``sqrt(x) >= c``, for ``c > 0``.

    IEEE ``sqrt`` is correctly rounded, hence monotone, so ``sqrt(x) < c`` holds exactly when
    ``x < sqrt_threshold(c)``: distance tests can compare squares and still agree, bit for bit,
    with ``d = sqrt(...) < min_dist``.
    """
    x = c * c
    while math.sqrt(x) < c:
        x = math.nextafter(x, math.inf)
    while math.sqrt(math.nextafter(x, -math.inf)) >= c:
        x = math.nextafter(x, -math.inf)
    return x


def widened(lo: float, hi: float) -> tuple[float, float]:
    """An interval of positions as the kernels read it: widened by the rounding margin
    ``ZONE_MARGIN``, never narrower than computed (infinite ends stay)."""
    return (lo - ZONE_MARGIN * (1.0 + abs(lo)) if math.isfinite(lo) else lo,
            hi + ZONE_MARGIN * (1.0 + abs(hi)) if math.isfinite(hi) else hi)


def pack(config, scenario) -> tuple[np.ndarray, np.ndarray]:
    """The kernel parameter vectors ``(P_av, P_hv)`` of ``config``: each ``(N_SLOTS,)``.

    ``scenario``: the :class:`persuasive.scenarios.Scenario` built from ``config``
    (``build_scenario(config)``; the scenarios sit above this module, which they read their
    slots from); it supplies each vehicle's path, lines and window and the conflict kind.
    """
    lib, rw, roles, q = config.library, config.reward, config.roles, config.effective_quirks
    shared = np.zeros(N_SLOTS)
    shared[N_SAMPLES], shared[SAMPLE_DT], shared[N_MESH] = lib.n_samples, lib.sample_dt_s, lib.n_mesh
    shared[ALPHA], shared[BETA], shared[KAPPA], shared[H_ST] = lib.alpha, lib.beta, lib.kappa, lib.h_st_m
    shared[HORIZON] = lib.horizon_s
    shared[W_C], shared[W_U] = rw.w_c, rw.w_u
    shared[W_S], shared[W_V], shared[PRIOR_L] = roles.w_s_m2, roles.w_v_m2ps2, roles.prior_leader
    shared[EPSILON] = config.mpc.epsilon
    shared[QUIRK_BRANCH_OFFSET] = q.q1_branch_time_offset
    shared[QUIRK_BELIEF_OFFSET] = q.q2_belief_offset
    shared[QUIRK_UNDISCOUNTED_COLLISION] = q.q4_undiscounted_collision
    shared[QUIRK_LEADER_AGG_MAX] = q.q5_leader_agg_max
    shared[QUIRK_TIME_LIKE_STOP_TEST] = q.q6_time_like_stop_test
    shared[CONFLICT] = scenario.conflict
    shared[MIN_DIST] = scenario.min_dist_m
    shared[MIN_DIST_SQ] = sqrt_threshold(scenario.min_dist_m)
    shared[LANE_SHARED] = float(scenario.lane_shared)
    shared[SHIELD] = SHIELD_KIND_IDS[config.shield]
    shared[SHIELD_RESPONSE] = config.av.shield_response_s
    mpc = config.mpc
    shared[SHIELD_AWARE] = float(mpc.shield_aware)
    # the filter's own switch (Config.confidence_filter): a threshold of 0 never trusts less
    shared[CONF_THRESHOLD] = mpc.confidence_threshold if config.confidence_filter else 0.0
    shared[CONF_STD] = mpc.confidence_accel_std_mps2
    shared[CONF_SWITCH] = mpc.confidence_switch
    shared[ACCEL_NOISE] = config.simulation.accel_noise_mps2
    shared[SHIELD_MARGIN] = config.shield_margin_m
    shared[RESP_RHO], shared[RESP_ACCEL], shared[RESP_BRAKE], shared[RESP_FRONT_BRAKE] = (
        config.responsibility_rule)
    shared[RIGHT_OF_WAY] = RIGHT_OF_WAY_IDS[config.responsibility.right_of_way]
    sim = config.simulation
    if sim.measurement_noise == "uniform":
        # a draw -w + 2 w u may round a hair past w: the box is widened by far more than that
        shared[MEAS_S], shared[MEAS_V] = (sim.noise_s_m * (1.0 + 1e-9),
                                          sim.noise_v_mps * (1.0 + 1e-9))
    out = []
    for path in (scenario.av, scenario.hv):
        P = shared.copy()
        veh = path.vehicle
        P[V_MIN], P[V_MAX], P[U_MIN], P[U_MAX] = (veh.v_min_mps, veh.v_max_mps, veh.u_min_mps2,
                                                  veh.u_max_mps2)
        P[LENGTH], P[WIDTH] = veh.length_m, veh.width_m
        P[H_GO] = lib.h_st_m + veh.v_max_mps / lib.kappa
        P[YIELD_S], P[FIRST_S], P[CLEAR_S] = path.yield_s, path.first_s, path.clear_s
        # the kernels' window may be wider than the zone, never narrower: rounding in xy(s)
        P[ZONE_LO], P[ZONE_HI] = widened(*path.zone)
        P[PATH_B1:PATH_UY2 + 1] = path.geometry_vector()
        # widened like the zone: never narrower than computed
        P[OCC_LO], P[OCC_HI] = widened(*path.occupancy)
        P[SHIELD_OCC_LO], P[SHIELD_OCC_HI] = widened(*path.shield_interval)
        P[SHIELD_LINE] = P[SHIELD_OCC_LO]
        out.append(P)
    place_yield_line(out[0], config.av.yield_line_m or 0.0)
    return out[0], out[1]


def place_yield_line(P_av: np.ndarray, line_m: float) -> None:
    """Set the AV's yield line ``line_m`` >= 0 before the start of its shield interval, in
    place (``av.yield_line_m``; foresight's pick): at or before the interval, a line only
    ever adds caution."""
    P_av[SHIELD_LINE] = P_av[SHIELD_OCC_LO] - line_m


def discounts(config) -> np.ndarray:
    """``lambda ** (k - 1)`` for samples ``k = 1..n``: shape ``(n_samples,)``.

    Computed once here and passed to every kernel so that all code paths use the same values.
    """
    return config.reward.discount ** np.arange(config.library.n_samples, dtype=np.float64)
