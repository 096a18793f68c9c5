"""The closed loop (spec section 7): measure, decide (HV first, then AV), advance, check.

One run is a pure function of its configuration and seed: :func:`simulate` creates the run's
random stream (``numpy.random.RandomState(seed)``, MT19937 with ``init_genrand``, the reference
stream), draws the initial state, then steps the loop ``n_steps`` times without ever stopping
early. Draw order per step: measurement noise (AV s, v, then HV s, v, when enabled), the LFG
agents' uniforms in the order they decide (HV, then an LFG AV), then the acceleration noise
(AV, HV, when enabled).

States are indexed ``x_0 .. x_N`` (``N = n_steps``): step ``k`` decides at ``x_k`` and
advances to ``x_{k+1}``; collision and arrival are tested on ``x_{k+1}``. ``idx_end`` is the
first step after which a vehicle is at the crossing line (the last step if none is), and the
"distance to the line" minimum runs over ``x_0 .. x_{idx_end + 1}``.

Measured speeds with noise are clipped to ``[v_min, v_max]`` before an agent sees them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import __version__
from ._packed import discounts, pack
from .agents import GameCache, LFGAgent, PersuasiveMPCAgent
from .config import Config
from .kinematics import saturated_step
from .mpc import (D_BELIEF_L, D_EXPECTED, D_MAX_SAFE, D_MIN_SAFE, D_P_FF, D_P_FL, D_P_LF,
                  D_P_LL, D_PLAUSIBLE_L)
from .roles import FOLLOWER, LEADER
from .scenario import Intersection, first_arrival

#: Labels of ``first_at_line`` / ``first_at_conflict_point``.
ARRIVAL_LABELS = {0: "neither", 1: "AV", 2: "HV", 3: "same step"}


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
    states: np.ndarray  #: ``(n_steps + 1, 4)``: s_AV, v_AV, s_HV, v_HV [m, m/s]
    log: dict[str, np.ndarray] = field(repr=False)  #: per-step columns, ``n_steps`` rows
    outcome: RunOutcome
    version: str = __version__

    @property
    def mode(self) -> str:
        return self.config.mode

    def summary(self) -> dict[str, Any]:
        """The run's identity and metrics as plain JSON values."""
        c = self.config
        o = self.outcome
        return {
            "mode": c.mode,
            "av": c.simulation.av,
            "hv_role": c.simulation.hv_role,
            "pa": c.roles.p_a,
            "pa_hat": c.p_a_hat,
            "seed": self.seed,
            "hv_initial_state": list(self.hv_initial_state),
            "av_initial_state": list(self.av_initial_state),
            "first_at_line": o.first_at_line,
            "first_at_conflict_point": o.first_at_conflict_point,
            "collision": o.collision,
            "min_distance_to_line_m": o.min_distance_to_line_m,
            "min_distance_m": o.min_distance_m,
            "idx_end": o.idx_end,
            "infeasible_steps": o.infeasible_steps,
            "hv_role_changes": o.hv_role_changes,
            "av_role_changes": o.av_role_changes,
            "quirks": {k: v for k, v in vars(c.effective_quirks).items()},
            "version": self.version,
        }

    def frame(self):
        """The per-step log as a pandas DataFrame (one row per step)."""
        import pandas as pd

        return pd.DataFrame(self.log)


def simulate(config: Config, seed: int) -> RunRecord:
    """Run one closed loop of the intersection for ``seed`` (a positive integer)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        from .config import ConfigError

        raise ConfigError(f"seed = {seed!r} is out of range; allowed: integer in [0, 2^32 - 1]")
    seed = int(seed)
    rng = np.random.RandomState(seed)
    scene = Intersection(config)
    x_av, x_hv = scene.initial_states(rng)
    sim, veh = config.simulation, config.vehicle
    P, disc = pack(config), discounts(config)
    games = GameCache(P, disc)

    hv = LFGAgent(sim.hv_role, config.roles.p_a, config.roles.adapt_role, games)
    av_lfg = sim.av == "lfg"
    q3 = config.effective_quirks.q3_tie_break_leak
    if av_lfg:
        av_role = "follower" if sim.hv_role == "leader" else "leader"
        av: LFGAgent | PersuasiveMPCAgent = LFGAgent(
            av_role, config.roles.p_a, config.roles.adapt_role, games)
    else:
        av = PersuasiveMPCAgent(config.p_a_hat, games, tie_rule="given" if q3 else "belief")
    # Q3: with p_a_hat == p_a the reference's human model *is* the simulated human, so a belief
    # tie reads the HV's current (already adapted) role; otherwise its fixed initial role.
    model_is_human = config.p_a_hat == config.roles.p_a

    n, dt = sim.n_steps, sim.dt_s
    v_min, v_max = veh.v_min_mps, veh.v_max_mps
    noise = sim.measurement_noise
    states = np.empty((n + 1, 4))
    states[0] = (*x_av, *x_hv)
    rows: list[tuple] = []
    for k in range(n):
        m_av, m_hv = x_av, x_hv
        if noise != "none":
            m_av, m_hv = _measure(rng, noise, sim.noise_s_m, sim.noise_v_mps, x_av, x_hv,
                                  v_min, v_max)
        h = hv.decide(m_hv, m_av, rng)
        if av_lfg:
            a = av.decide(m_av, m_hv, rng)
            a_av = a.accel_mps2
        else:
            a = av.decide(m_av, m_hv, (hv.role if model_is_human else hv.initial_role))
            a_av = a.accel_mps2
        a_hv = h.accel_mps2
        if sim.accel_noise_mps2 > 0.0:
            w = sim.accel_noise_mps2
            a_av += -w + 2.0 * w * rng.random_sample()
            a_hv += -w + 2.0 * w * rng.random_sample()
        x_av = saturated_step(x_av[0], x_av[1], a_av, dt, v_min, v_max)
        x_hv = saturated_step(x_hv[0], x_hv[1], a_hv, dt, v_min, v_max)
        states[k + 1] = (*x_av, *x_hv)
        rows.append((m_av, m_hv, a_av, a_hv, h, a))

    log = {
        "step": np.arange(n, dtype=np.int64),
        "t_s": np.arange(n) * dt,
        "av_s_m": states[:-1, 0],
        "av_v_mps": states[:-1, 1],
        "hv_s_m": states[:-1, 2],
        "hv_v_mps": states[:-1, 3],
        "distance_m": scene.distance(states[:-1, 0], states[:-1, 2]),
        **_columns(rows, av_lfg, 1.0 - config.mpc.epsilon),
    }
    outcome = _outcome(scene, states, log)
    return RunRecord(config, seed, tuple(states[0, :2]), tuple(states[0, 2:]), states, log,
                     outcome)


def _measure(rng, noise, w_s, w_v, x_av, x_hv, v_min, v_max):
    out = []
    for s, v in (x_av, x_hv):
        if noise == "uniform":
            s += -w_s + 2.0 * w_s * rng.random_sample()
            v += -w_v + 2.0 * w_v * rng.random_sample()
        else:
            s += w_s * rng.standard_normal()
            v += w_v * rng.standard_normal()
        out.append((s, min(max(v, v_min), v_max)))
    return out[0], out[1]


def _lfg_columns(prefix: str, steps) -> dict[str, np.ndarray]:
    return {
        f"{prefix}_role": np.array([("leader", "follower")[s.role] for s in steps]),
        f"{prefix}_next_role": np.array([("leader", "follower")[s.next_role] for s in steps]),
        f"{prefix}_trajectory": np.array([s.trajectory for s in steps], np.int64),
        f"{prefix}_plausible_leader": np.array([s.plausible_leader for s in steps]),
        f"{prefix}_pi_ll": np.array([s.transition[0, 0] for s in steps]),
        f"{prefix}_pi_lf": np.array([s.transition[0, 1] for s in steps]),
        f"{prefix}_pi_fl": np.array([s.transition[1, 0] for s in steps]),
        f"{prefix}_pi_ff": np.array([s.transition[1, 1] for s in steps]),
        f"{prefix}_draw": np.array([s.draw for s in steps]),
        f"{prefix}_belief_other_leader": np.array([s.belief_leader for s in steps]),
        f"{prefix}_belief_other_follower": np.array([s.belief_follower for s in steps]),
    }


def _columns(rows, av_lfg: bool, threshold: float) -> dict[str, np.ndarray]:
    log: dict[str, np.ndarray] = {
        "av_meas_s_m": np.array([r[0][0] for r in rows]),
        "av_meas_v_mps": np.array([r[0][1] for r in rows]),
        "hv_meas_s_m": np.array([r[1][0] for r in rows]),
        "hv_meas_v_mps": np.array([r[1][1] for r in rows]),
        "av_accel_mps2": np.array([r[2] for r in rows]),
        "hv_accel_mps2": np.array([r[3] for r in rows]),
    }
    log.update(_lfg_columns("hv", [r[4] for r in rows]))
    if av_lfg:
        log.update(_lfg_columns("av", [r[5] for r in rows]))
        return log
    steps = [r[5] for r in rows]
    chosen = [s.diagnostics[s.trajectory] for s in steps]
    log.update({
        "av_trajectory": np.array([s.trajectory for s in steps], np.int64),
        "av_feasible": np.array([s.feasible for s in steps]),
        "av_p_safe_min": np.array([c[D_MIN_SAFE] for c in chosen]),
        "av_p_safe_max": np.array([c[D_MAX_SAFE] for c in chosen]),
        "av_expected_reward": np.array([c[D_EXPECTED] for c in chosen]),
        "av_belief_hv_leader_used": np.array([s.q_used[0] for s in steps]),
        "av_belief_hv_leader": np.array([s.belief_leader for s in steps]),
        "av_belief_hv_follower": np.array([s.belief_follower for s in steps]),
        "av_tie_role": np.array([("leader", "follower")[s.tie_role] for s in steps]),
        "av_human_belief_av_leader": np.array([c[D_BELIEF_L] for c in chosen]),
        "av_human_plausible_leader": np.array([c[D_PLAUSIBLE_L] for c in chosen]),
        "av_branch_p_ll": np.array([c[D_P_LL] for c in chosen]),
        "av_branch_p_lf": np.array([c[D_P_LF] for c in chosen]),
        "av_branch_p_fl": np.array([c[D_P_FL] for c in chosen]),
        "av_branch_p_ff": np.array([c[D_P_FF] for c in chosen]),
        "av_n_feasible": np.array(
            [int(np.sum(s.diagnostics[:, D_MIN_SAFE] > threshold)) for s in steps], np.int64),
    })
    return log


def _outcome(scene: Intersection, states: np.ndarray, log: dict[str, np.ndarray]) -> RunOutcome:
    after = states[1:]
    line, idx_line = first_arrival(scene.at_line(after[:, 0]), scene.at_line(after[:, 2]))
    conflict, _ = first_arrival(scene.at_conflict_point(after[:, 0]),
                                scene.at_conflict_point(after[:, 2]))
    d = scene.distance(states[:, 0], states[:, 2])
    n = after.shape[0]
    idx_end = idx_line if idx_line is not None else n - 1
    changes = {}
    for who in ("hv", "av"):
        col = log.get(f"{who}_role")
        changes[who] = int(np.sum(log[f"{who}_next_role"] != col)) if col is not None else 0
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
