"""The persuasive planner as a library call: give it the two vehicles' states, get an action.

:class:`Planner` wraps the AV's branch MPC (spec section 6) for use inside a user's own loop,
e.g. a vehicle stack at 10 Hz. It keeps, between calls, what the method keeps: the belief on the
human's role and the stored one-step prediction of the human. It uses corrected mode by default
(the paper's equations); pass a configuration to change any parameter or quirk.

Example
-------
>>> from persuasive import Planner
>>> planner = Planner()
>>> plan = planner.plan(av=(-20.0, 4.0), hv=(-22.0, 4.3))
>>> plan.accel_mps2, plan.feasible  # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _packed as K
from ._packed import discounts, pack
from .agents import (M_BEL_L, M_FEASIBLE, M_PSAFE_MIN, M_TRAJ, MPC_LOG, Q_L, mpc_init,
                     mpc_step_buffers)
from .config import Config, ConfigError
from .game import predict_buffers
from .library import lib_buffers
from .mpc import D_EXPECTED, D_MIN_SAFE, D_P_LL, N_DIAG
from .roles import FOLLOWER, LEADER

State = tuple[float, float]


@dataclass(frozen=True)
class Plan:
    """One decision of the planner."""

    accel_mps2: float  #: acceleration to apply now [m/s^2]
    candidate: int  #: index of the chosen candidate trajectory (library order)
    t_s: np.ndarray  #: sample times of the chosen trajectory, from now [s] ``(n,)``
    s_m: np.ndarray  #: its positions [m] ``(n,)``
    v_mps: np.ndarray  #: its speeds [m/s] ``(n,)``
    a_mps2: np.ndarray  #: its accelerations [m/s^2] ``(n,)``
    branch_probabilities: dict[str, float]  #: P(i, j) of the branches "LL", "LF", "FL", "FF"
    expected_reward: float  #: expected cumulative reward of the chosen candidate
    p_safe_min: float  #: lowest probability of being safe over the horizon
    chance_margin: float  #: ``p_safe_min - (1 - epsilon)``; > 0 when the constraint holds
    feasible: bool  #: some candidate met the chance constraint
    belief_hv_leader: float  #: P(HV = leader) after this call's update
    candidates: np.ndarray  #: per-candidate diagnostics ``(n_traj, 10)`` (``persuasive.mpc``)


class Planner:
    """The AV's persuasive branch-MPC planner.

    Parameters
    ----------
    config : Config, optional
        All parameters; default ``Config(mode="corrected")``.
    """

    def __init__(self, config: Config | None = None):
        self.config = config if config is not None else Config(mode="corrected")
        self._P, self._disc = pack(self.config), discounts(self.config)
        n, n_traj = self.config.library.n_samples, self.config.library.n_traj
        self._hv, self._av = lib_buffers(n, n_traj), lib_buffers(n, n_traj)
        self._idx = np.empty(4, np.int64)
        self._diag = np.empty((n_traj, N_DIAG))
        self._log = np.empty(len(MPC_LOG))
        self._times = np.arange(1, n + 1) * self.config.library.sample_dt_s
        self.reset()

    def reset(self) -> None:
        """Forget the belief and the stored prediction (a new encounter)."""
        self._state = mpc_init(float(self._P[K.PRIOR_L]))

    @property
    def belief_hv_leader(self) -> float:
        """Current P(HV = leader)."""
        return float(self._state[Q_L])

    def plan(self, av: State, hv: State, human_role: str | None = None) -> Plan:
        """Decide the AV's acceleration at AV state ``av`` and HV state ``hv``.

        ``av``, ``hv``: ``(s [m], v [m/s])`` along each vehicle's road, ``s < 0`` before the
        conflict point. ``human_role`` ("leader"/"follower") is needed only with quirk Q3 on
        (paper mode), where a belief tie reads the human's true role.
        """
        x_R, x_H = _state("av", av, self.config), _state("hv", hv, self.config)
        tie_given = self.config.effective_quirks.q3_tie_break_leak
        if tie_given and human_role not in ("leader", "follower"):
            raise ConfigError("human_role is required with quirk Q3 (paper mode); "
                              "allowed: leader | follower")
        given = LEADER if human_role == "leader" else FOLLOWER
        predict_buffers(x_H[0], x_H[1], x_R[0], x_R[1], self._P, self._disc, *self._hv,
                        *self._av, self._idx)
        accel = mpc_step_buffers(self._state, x_R[0], x_R[1], x_H[0], x_H[1], tie_given, given,
                                 self.config.p_a_hat, *self._hv, *self._av, self._idx,
                                 self._P, self._disc, self._diag, self._log)
        k = int(self._log[M_TRAJ])
        n = self.config.library.n_samples
        buf = self._av[0]
        d = self._diag[k]
        return Plan(
            accel_mps2=float(accel),
            candidate=k,
            t_s=self._times.copy(),
            s_m=buf[0:n, k].copy(),
            v_mps=buf[n:2 * n, k].copy(),
            a_mps2=buf[2 * n:3 * n, k].copy(),
            branch_probabilities={b: float(d[D_P_LL + i]) for i, b in
                                  enumerate(("LL", "LF", "FL", "FF"))},
            expected_reward=float(d[D_EXPECTED]),
            p_safe_min=float(d[D_MIN_SAFE]),
            chance_margin=float(self._log[M_PSAFE_MIN] - (1.0 - self.config.mpc.epsilon)),
            feasible=bool(self._log[M_FEASIBLE]),
            belief_hv_leader=float(self._log[M_BEL_L]),
            candidates=self._diag.copy(),
        )


def _state(name: str, x, config: Config) -> tuple[float, float]:
    try:
        s, v = (float(x[0]), float(x[1]))
    except (TypeError, ValueError, IndexError):
        raise ConfigError(f"{name} = {x!r} is not a state (s [m], v [m/s])") from None
    veh = config.vehicle
    if not (np.isfinite(s) and np.isfinite(v)) or not veh.v_min_mps <= v <= veh.v_max_mps:
        raise ConfigError(f"{name} = ({s!r}, {v!r}) is out of range; allowed: finite s, "
                          f"v in [{veh.v_min_mps:g}, {veh.v_max_mps:g}] m/s")
    return s, v


__all__ = ["Plan", "Planner"]
