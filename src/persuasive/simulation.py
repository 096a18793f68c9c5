"""The closed loop (spec section 7): measure, decide (HV first, then AV), advance, check.

One run is a pure function of its configuration and seed. :func:`simulate` creates the run's
random stream (``numpy.random.RandomState(seed)``: MT19937 seeded by ``init_genrand``, 53-bit
doubles, the reference stream), draws the initial state, then the per-step numbers in this
order: measurement noise (AV s, v, then HV s, v, when enabled), the LFG agents' uniforms in the
order they decide (HV, then an LFG AV), the acceleration noise (AV, HV, when enabled). None of
them depends on the state, so they are drawn up front and the loop itself runs compiled
(:func:`run_loop`), calling the agents' step functions of ``persuasive.agents``.

States are indexed ``x_0 .. x_N`` (``N = n_steps``): step ``k`` decides at ``x_k`` and advances
to ``x_{k+1}``; collision and arrival are tested on ``x_{k+1}``. The run never stops early.
``idx_end`` is the first step after which a vehicle is at the crossing line (the last step if
none is), and the "up to the line" minimum distance runs over ``x_0 .. x_{idx_end + 1}``.
Measured speeds with noise are clipped to ``[v_min, v_max]`` before an agent sees them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit

from . import __version__
from . import _packed as K
from ._packed import discounts, pack
from .agents import (LFG_LOG, MPC_LOG, MPRED_FS, MPRED_FV, MPRED_LS, MPRED_LV, MREADY, ROLE,
                     SWAP, lfg_init, lfg_step, mpc_init, mpc_step)
from .config import Config, ConfigError
from .game import predict_into
from .kinematics import saturated_step
from .library import new_lib
from .mpc import N_DIAG
from .roles import FOLLOWER, LEADER
from .scenario import Intersection, first_arrival

#: Labels of ``first_at_line`` / ``first_at_conflict_point``.
ARRIVAL_LABELS = {0: "neither", 1: "AV", 2: "HV", 3: "same step"}

# Layout of the compiled loop's log matrix: measurements and accelerations, then the HV's LFG
# columns, then the AV's (LFG or MPC) columns.
_BASE_LOG = ("av_meas_s_m", "av_meas_v_mps", "hv_meas_s_m", "hv_meas_v_mps", "av_accel_mps2",
             "hv_accel_mps2")
_HV_OFF = len(_BASE_LOG)
_AV_OFF = _HV_OFF + len(LFG_LOG)
_N_LOG = _AV_OFF + max(len(LFG_LOG), len(MPC_LOG))
_ROLE_COLUMNS = ("role", "next_role", "tie_role")
_INT_COLUMNS = ("trajectory", "n_feasible")


@dataclass(frozen=True)
class RunOutcome:
    """Per-run metrics (spec sections 7 and 8)."""

    first_at_line: int  #: 1 AV, 2 HV, 3 same step, 0 neither
    first_at_conflict_point: int  #: same labels, for ``s >= 0``
    collision: bool  #: footprints overlapped at some step
    min_distance_to_line_m: float  #: min distance over ``x_0 .. x_{idx_end + 1}`` [m]
    min_distance_m: float  #: min distance over the whole run [m]
    idx_end: int  #: first step after which a vehicle is at the line (last step if none)
    infeasible_steps: int  #: MPC steps with no candidate meeting the chance constraint
    hv_role_changes: int  #: role changes of the HV
    av_role_changes: int  #: role changes of an LFG AV (0 for the MPC)


@dataclass(frozen=True)
class RunRecord:
    """One closed-loop run: configuration, seed, per-step log and outcome."""

    config: Config
    seed: int
    av_initial_state: tuple[float, float]  #: ``(s [m], v [m/s])``
    hv_initial_state: tuple[float, float]
    states: np.ndarray = field(repr=False)  #: ``(n_steps + 1, 4)``: s_AV, v_AV, s_HV, v_HV
    log: dict[str, np.ndarray] = field(repr=False)  #: per-step columns, ``n_steps`` rows
    outcome: RunOutcome
    version: str = __version__

    @property
    def mode(self) -> str:
        return self.config.mode

    def summary(self) -> dict[str, Any]:
        """The run's identity and metrics as plain JSON values."""
        c, o = self.config, self.outcome
        return {
            "mode": c.mode,
            "av": c.simulation.av,
            "hv_role": c.simulation.hv_role,
            "pa": c.roles.p_a,
            "pa_hat": c.p_a_hat,
            "seed": self.seed,
            "hv_initial_state": [float(x) for x in self.hv_initial_state],
            "av_initial_state": [float(x) for x in self.av_initial_state],
            "first_at_line": o.first_at_line,
            "first_at_conflict_point": o.first_at_conflict_point,
            "collision": o.collision,
            "min_distance_to_line_m": o.min_distance_to_line_m,
            "min_distance_m": o.min_distance_m,
            "idx_end": o.idx_end,
            "infeasible_steps": o.infeasible_steps,
            "hv_role_changes": o.hv_role_changes,
            "av_role_changes": o.av_role_changes,
            "quirks": dict(vars(c.effective_quirks)),
            "version": self.version,
        }

    def frame(self):
        """The per-step log as a pandas DataFrame (one row per step)."""
        import pandas as pd

        return pd.DataFrame(self.log)


@njit(cache=True)
def run_loop(P: np.ndarray, disc: np.ndarray, x0: np.ndarray, dt: float, av_lfg: bool,
             hv_role: int, p_a: float, adapt: bool, p_a_hat: float, tie_given: bool,
             model_is_human: bool, noisy: bool, meas_noise: np.ndarray,
             accel_noise: np.ndarray, draws: np.ndarray, states: np.ndarray,
             log: np.ndarray) -> None:
    """The closed loop, compiled: fills ``states`` ``(n_steps + 1, 4)`` and ``log``.

    ``x0``: initial ``(s_AV, v_AV, s_HV, v_HV)``; ``draws`` ``(n_steps, 2)``: the uniforms of
    the HV and of an LFG AV; ``meas_noise`` ``(n_steps, 4)`` and ``accel_noise``
    ``(n_steps, 2)``: additive noise (used when ``noisy``). With ``tie_given`` (quirk Q3) the
    human model's tie role is the HV's current role when ``model_is_human``, else its initial
    role.
    """
    n, n_traj = int(P[K.N_SAMPLES]), int(P[K.N_MESH]) + 1
    v_min, v_max, w_s, w_v = P[K.V_MIN], P[K.V_MAX], P[K.W_S], P[K.W_V]
    LH, LR = new_lib(n, n_traj), new_lib(n, n_traj)
    # The MPC builds the HV's libraries one sample ahead, at the states it stores as its
    # prediction of the HV (role L into LH1a; role F into LH1b when it differs). Unless noise
    # moved the HV, its next measured state is one of them and that library is reused.
    LH1a, LH1b = new_lib(n, n_traj), new_lib(n, n_traj)
    idx, idx_av = np.empty(4, np.int64), np.empty(4, np.int64)
    diag = np.empty((n_traj, N_DIAG))
    hv = lfg_init(hv_role, P[K.PRIOR_L])
    av = lfg_init(1 - hv_role, P[K.PRIOR_L]) if av_lfg else mpc_init(P[K.PRIOR_L])
    s_av, v_av, s_hv, v_hv = x0[0], x0[1], x0[2], x0[3]
    states[0, 0], states[0, 1], states[0, 2], states[0, 3] = s_av, v_av, s_hv, v_hv
    n_lfg = len(LFG_LOG)
    for k in range(states.shape[0] - 1):
        ms_av, mv_av, ms_hv, mv_hv = s_av, v_av, s_hv, v_hv
        if noisy:
            ms_av += meas_noise[k, 0]
            mv_av = min(max(mv_av + meas_noise[k, 1], v_min), v_max)
            ms_hv += meas_noise[k, 2]
            mv_hv = min(max(mv_hv + meas_noise[k, 3], v_min), v_max)
        # The HV's own game; the AV's view of it is the same pair of solves.
        built = False
        if not av_lfg and av[MREADY] != 0.0:
            if av[MPRED_LS] == ms_hv and av[MPRED_LV] == mv_hv:
                LH, LH1a = LH1a, LH
                built = True
            elif av[MPRED_FS] == ms_hv and av[MPRED_FV] == mv_hv:
                LH, LH1b = LH1b, LH
                built = True
        predict_into(ms_hv, mv_hv, ms_av, mv_av, P, disc, LH, LR, idx, built)
        row = log[k]
        a_hv = lfg_step(hv, ms_av, mv_av, draws[k, 0], p_a, adapt, LH, LR, idx, w_s, w_v,
                        row[_HV_OFF:_HV_OFF + n_lfg])
        if av_lfg:
            for j in range(4):
                idx_av[j] = idx[SWAP[j]]
            a_av = lfg_step(av, ms_hv, mv_hv, draws[k, 1], p_a, adapt, LR, LH, idx_av,
                            w_s, w_v, row[_AV_OFF:_AV_OFF + n_lfg])
        else:
            given = int(hv[ROLE]) if model_is_human else hv_role
            a_av = mpc_step(av, ms_av, mv_av, ms_hv, mv_hv, tie_given, given, p_a_hat,
                            LH, LR, idx, P, disc, diag, row[_AV_OFF:], LH1a, LH1b)
        if noisy:
            a_av += accel_noise[k, 0]
            a_hv += accel_noise[k, 1]
        row[0], row[1], row[2], row[3] = ms_av, mv_av, ms_hv, mv_hv
        row[4], row[5] = a_av, a_hv
        s_av, v_av = saturated_step(s_av, v_av, a_av, dt, v_min, v_max)
        s_hv, v_hv = saturated_step(s_hv, v_hv, a_hv, dt, v_min, v_max)
        states[k + 1, 0], states[k + 1, 1], states[k + 1, 2], states[k + 1, 3] = (
            s_av, v_av, s_hv, v_hv)


def draw_stream(rng: np.random.RandomState, config: Config):
    """The per-step random numbers of a run, in the spec's order (see the module docstring).

    Returns ``(draws (n, 2), meas_noise (n, 4), accel_noise (n, 2), noisy)``.
    """
    sim = config.simulation
    n, n_lfg = sim.n_steps, 2 if sim.av == "lfg" else 1
    draws = np.zeros((n, 2))
    meas = np.zeros((n, 4))
    accel = np.zeros((n, 2))
    kind, w_acc = sim.measurement_noise, sim.accel_noise_mps2
    if kind == "none" and w_acc == 0.0:
        draws[:, :n_lfg] = rng.random_sample((n, n_lfg))
        return draws, meas, accel, False
    widths = (sim.noise_s_m, sim.noise_v_mps) * 2
    for k in range(n):
        if kind == "uniform":
            meas[k] = [-w + 2.0 * w * rng.random_sample() for w in widths]
        elif kind == "gaussian":
            meas[k] = [w * rng.standard_normal() for w in widths]
        draws[k, :n_lfg] = [rng.random_sample() for _ in range(n_lfg)]
        if w_acc > 0.0:
            accel[k] = [-w_acc + 2.0 * w_acc * rng.random_sample() for _ in range(2)]
    return draws, meas, accel, True


def check_seed(seed: Any) -> int:
    """The seed as an int, or :class:`ConfigError` if it is not an integer in [0, 2^32 - 1]."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise ConfigError(f"seed = {seed!r} is out of range; allowed: integer in [0, 2^32 - 1]")
    return int(seed)


def simulate(config: Config, seed: int) -> RunRecord:
    """Run one closed loop of the intersection for ``seed``; bit-identical for equal inputs."""
    seed = check_seed(seed)
    rng = np.random.RandomState(seed)
    scene = Intersection(config)
    x_av, x_hv = scene.initial_states(rng)
    draws, meas, accel, noisy = draw_stream(rng, config)
    sim = config.simulation
    P, disc = pack(config), discounts(config)
    states = np.empty((sim.n_steps + 1, 4))
    raw = np.full((sim.n_steps, _N_LOG), np.nan)
    hv_role = LEADER if sim.hv_role == "leader" else FOLLOWER
    run_loop(P, disc, np.array([*x_av, *x_hv]), sim.dt_s, sim.av == "lfg", hv_role,
             config.roles.p_a, config.roles.adapt_role, config.p_a_hat,
             config.effective_quirks.q3_tie_break_leak,
             # Q3: with p_a_hat == p_a the reference's human model *is* the simulated human
             config.p_a_hat == config.roles.p_a,
             noisy, meas, accel, draws, states, raw)
    log = _columns(states, raw, sim, scene)
    return RunRecord(config, seed, x_av, x_hv, states, log, _outcome(scene, states, log))


def _columns(states, raw, sim, scene) -> dict[str, np.ndarray]:
    n = raw.shape[0]
    log: dict[str, np.ndarray] = {
        "step": np.arange(n, dtype=np.int64),
        "t_s": np.arange(n) * sim.dt_s,
        "av_s_m": states[:-1, 0],
        "av_v_mps": states[:-1, 1],
        "hv_s_m": states[:-1, 2],
        "hv_v_mps": states[:-1, 3],
        "distance_m": scene.distance(states[:-1, 0], states[:-1, 2]),
    }
    log.update({name: raw[:, j] for j, name in enumerate(_BASE_LOG)})
    blocks = [("hv", LFG_LOG, _HV_OFF), ("av", LFG_LOG if sim.av == "lfg" else MPC_LOG, _AV_OFF)]
    for who, names, off in blocks:
        for j, name in enumerate(names):
            col = raw[:, off + j]
            if name in _ROLE_COLUMNS:
                col = np.where(col == LEADER, "leader", "follower")
            elif name in _INT_COLUMNS:
                col = col.astype(np.int64)
            elif name == "feasible":
                col = col != 0.0
            log[f"{who}_{name}"] = col
    return log


def _outcome(scene: Intersection, states: np.ndarray, log: dict[str, np.ndarray]) -> RunOutcome:
    after = states[1:]
    line, idx_line = first_arrival(scene.at_line(after[:, 0]), scene.at_line(after[:, 2]))
    conflict, _ = first_arrival(scene.at_conflict_point(after[:, 0]),
                                scene.at_conflict_point(after[:, 2]))
    d = scene.distance(states[:, 0], states[:, 2])
    idx_end = idx_line if idx_line is not None else after.shape[0] - 1
    changes = {
        who: int(np.sum(log[f"{who}_next_role"] != log[f"{who}_role"]))
        if f"{who}_role" in log else 0
        for who in ("hv", "av")
    }
    infeasible = int(np.sum(~log["av_feasible"])) if "av_feasible" in log else 0
    return RunOutcome(
        first_at_line=line,
        first_at_conflict_point=conflict,
        collision=bool(np.any(scene.collides(after[:, 0], after[:, 2]))),
        min_distance_to_line_m=float(d[: idx_end + 2].min()),
        min_distance_m=float(d.min()),
        idx_end=int(idx_end),
        infeasible_steps=infeasible,
        hv_role_changes=changes["hv"],
        av_role_changes=changes["av"],
    )
