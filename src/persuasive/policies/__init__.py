"""Policies: what drives each vehicle (docs/method.md §11).

A policy is one vehicle's decision rule, used through one protocol by both vehicles and by
both loops:

- the **compiled side** (``persuasive.policies.step``): a kind id (:mod:`.kinds`), a parameter
  vector (:func:`policy_params`), a state vector and a log row; one cached compiled step that
  dispatches on the kind, called by the compiled closed loop (``persuasive.world``);
- the **Python side** (:class:`Policy`): ``reset(context, rng)``, ``act(observation) ->
  acceleration`` and its ``log_columns``, called by the Python loop
  (:func:`persuasive.world.run_python`) for policies that live outside the compiled code (a
  person in the browser, a recorded trial, an external simulator). :class:`CompiledPolicy`
  wraps any compiled kind in that protocol; the two loops give the same runs bit for bit.

AV kinds: ``persuasive`` (the paper's branch MPC; alias ``mpc``), ``passive``, ``cv``,
``lfg``, ``yield``, the level-k players ``level1``, ``level2`` (:mod:`.levelk`) and Li et
al.'s rule-role LFG ``lfg-rule`` (:mod:`.lfg_rule`). Human
kinds: ``lfg``, ``stubborn``, ``noisy``, ``idm``, ``aggressive``, ``replay``, and the humans
that test the safety shield, ``adversary``, ``deceptive``, ``random`` (:mod:`.adversarial`).
Each module's docstring states the kind's definition and parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from .. import packing as slot
from ..config import AV_KINDS, SIMULATED_HV_KINDS, Config, ConfigError
from ..roles import FOLLOWER, LEADER
from . import kinds as kd
from .kinds import KINDS, KindSpec

#: The kinds each vehicle may use, by side.
SIDE_KINDS = {kd.AV: AV_KINDS, kd.HV: SIMULATED_HV_KINDS}


def kind_of(config: Config, side: int) -> KindSpec:
    """The :class:`~persuasive.policies.kinds.KindSpec` driving ``side`` in ``config``."""
    name = (config.av if side == kd.AV else config.hv).kind
    if name not in KINDS:
        raise ConfigError(f"hv.kind = {name!r} is driven by a person, not by the simulation: use "
                          "'persuasive drive', or persuasive.world.PythonWorld with a Python "
                          "policy for the HV")
    return KINDS[name]


def _role(name: str) -> float:
    return float(LEADER if name == "leader" else FOLLOWER)


def policy_params(config: Config, side: int, p_a_prior: np.ndarray | None = None) -> np.ndarray:
    """The compiled parameter vector of the policy driving ``side`` in ``config``.

    ``p_a_prior`` ``(mpc.p_a_grid,)``: for a persuasive AV with ``mpc.p_a_hat = "online"``,
    the prior masses over the grid in place of the Beta prior's (e.g. the posterior at the end
    of an earlier interaction with the same human); only their ratios matter."""
    spec = kind_of(config, side)
    if p_a_prior is not None and not (config.p_a_online and spec.kind == kd.PERSUASIVE):
        raise ConfigError("p_a_prior is a prior over p_a for the persuasive planner with "
                          'mpc.p_a_hat = "online"; this configuration keeps none')
    if spec.kind in (kd.LFG, kd.STUBBORN, kd.NOISY):
        from .lfg import PRM_ADAPT, PRM_BETA, PRM_P_A, PRM_ROLE

        prm = np.zeros(4)
        prm[PRM_P_A] = 0.0 if spec.kind == kd.STUBBORN else config.roles.p_a
        prm[PRM_ADAPT] = float(config.roles.adapt_role)
        prm[PRM_BETA] = config.hv.noisy.beta
        if side == kd.HV:
            prm[PRM_ROLE] = _role(config.hv.role)
        else:  # an LFG AV starts in the role complementary to the human's, unless set
            prm[PRM_ROLE] = _role(config.av.role) if config.av.role is not None else \
                1.0 - _role(config.hv.role)
        return prm
    if spec.kind in (kd.PERSUASIVE, kd.PASSIVE):
        from .planners import (PRM_HUMAN_ROLE, PRM_MODEL_IS_HUMAN, PRM_P_A_HAT, PRM_SIZE,
                               PRM_TIE_GIVEN)

        prm = np.zeros(PRM_SIZE)
        prm[PRM_P_A_HAT] = config.p_a_hat
        prm[PRM_TIE_GIVEN] = float(config.effective_quirks.q3_tie_break_leak)
        # Q3: with p_a_hat == p_a the reference's human model *is* the simulated human; an
        # online posterior is never assumed to be the human
        prm[PRM_MODEL_IS_HUMAN] = float(config.p_a_hat == config.roles.p_a
                                        and not config.p_a_online)
        prm[PRM_HUMAN_ROLE] = _role(config.hv.role)
        if config.p_a_online and spec.kind == kd.PERSUASIVE:
            from ..online import online_params, prior_masses

            grid, prior = prior_masses(*config.p_a_prior, config.p_a_grid) \
                if p_a_prior is None else (np.linspace(0.0, 1.0, config.p_a_grid),
                                           _check_prior(p_a_prior, config.p_a_grid))
            prm = np.concatenate([prm[:-1], online_params(grid, prior)])
        return prm
    if spec.kind == kd.IDM:
        p = config.hv.idm
        return np.array([p.desired_speed_mps, p.time_gap_s, p.max_accel_mps2,
                         p.comfort_decel_mps2, p.delta, p.jam_gap_m, p.critical_gap_s,
                         p.impatience_per_s])
    if spec.kind == kd.REPLAY:
        accel = load_replay(config).accel_mps2
        return np.concatenate([[float(accel.size)], accel])
    if spec.kind == kd.RANDOM:
        return np.array([config.hv.random.hold_min_s, config.hv.random.hold_max_s])
    if spec.kind == kd.LFG_RULE:  # the stubborn LFG; its role is the rule's (lfg_rule)
        from .lfg import PRM_ROLE

        prm = np.zeros(4)
        prm[PRM_ROLE] = float(FOLLOWER)  # until its first decision takes the rule's
        return prm
    if spec.kind in (kd.LEVEL1, kd.LEVEL2):
        from .levelk import PRM_LEVEL

        prm = np.zeros(1)
        prm[PRM_LEVEL] = 1.0 if spec.kind == kd.LEVEL1 else 2.0
        return prm
    return np.zeros(1)


def _check_prior(prior, n: int) -> np.ndarray:
    w = np.asarray(prior, dtype=np.float64)
    if w.shape != (n,) or not np.all(np.isfinite(w)) or np.any(w < 0.0) or not w.sum() > 0.0:
        raise ConfigError(f"p_a_prior must be {n} finite masses >= 0 with a positive sum "
                          f"(one per point of mpc.p_a_grid = {n})")
    return w  # only ratios matter: the posterior is normalised at every step


def state_size(prm: np.ndarray, kind: int) -> int:
    """Length of the state vector of a policy of ``kind`` with parameters ``prm``:
    ``kinds.STATE_SIZE``, plus the online posterior's block for a persuasive planner that
    keeps one."""
    if kind == kd.PERSUASIVE:
        from ..online import state_size as online_size
        from .planners import ONLINE_STATE, PRM_ONLINE

        if prm.shape[0] > PRM_ONLINE and prm[PRM_ONLINE] > 0.0:
            return ONLINE_STATE + online_size(int(prm[PRM_ONLINE]))
    return kd.STATE_SIZE


@dataclass(frozen=True)
class Recording:
    """A recorded trajectory for the ``replay`` human: initial state and accelerations."""

    s0_m: float
    v0_mps: float
    accel_mps2: np.ndarray  #: one per step [m/s^2]
    source: str


def load_replay(config: Config) -> Recording:
    """Read ``hv.replay.file`` (a per-step log, Parquet or CSV): the replayed vehicle's
    initial state and its accelerations per step."""
    import pandas as pd

    path = Path(config.hv.replay.file)
    who = config.hv.replay.vehicle
    if not path.exists():
        raise ConfigError(f"hv.replay.file = {str(path)!r} cannot be read: no such file")
    try:
        frame = pd.read_csv(path) if path.suffix.lower() == ".csv" else pd.read_parquet(path)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"hv.replay.file = {str(path)!r} cannot be read: "
                          f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") \
            from None
    need = (f"{who}_s_m", f"{who}_v_mps", f"{who}_accel_mps2")
    missing = [c for c in need if c not in frame.columns]
    if missing or len(frame) == 0:
        raise ConfigError(f"hv.replay.file = {str(path)!r} is not a per-step log of the "
                          f"{who.upper()} (missing columns: {', '.join(missing) or 'rows'})")
    return Recording(float(frame[need[0]].iloc[0]), float(frame[need[1]].iloc[0]),
                     frame[need[2]].to_numpy(dtype=np.float64), str(path))


# -- the Python side ------------------------------------------------------------------------


@dataclass
class Observation:
    """What a policy sees at one step (measured states, as the compiled policies do)."""

    step: int  #: decision step k
    t_s: float  #: time [s]
    av: tuple[float, float]  #: the AV's measured (s [m], v [m/s])
    hv: tuple[float, float]  #: the HV's measured (s [m], v [m/s])
    game: Any = None  #: the full prediction of the joint state, human's view (GameView)
    human_role: int = -1  #: the HV's current role if it has one (quirk Q3 only), else -1


@dataclass
class Context:
    """What a policy is told at ``reset``: the run's configuration and shared machinery."""

    config: Config
    scenario: Any  #: :class:`persuasive.scenarios.Scenario`
    P_av: np.ndarray
    P_hv: np.ndarray
    disc: np.ndarray
    side: int  #: the vehicle it drives (``kinds.AV`` / ``kinds.HV``)
    n_steps: int
    draws: np.ndarray  #: (n_steps, k) uniforms of this agent, drawn by the world's streams
    games: Any = None  #: :class:`persuasive.world.GameCache`, shared by the loop's policies
    extra: dict = field(default_factory=dict)


@runtime_checkable
class Policy(Protocol):
    """The Python side of a policy."""

    log_columns: tuple[str, ...]  #: names of the values of :attr:`last_log`
    needs_game: bool  #: the loop must compute the full prediction for it

    def reset(self, context: Context, rng: np.random.Generator | None) -> None:
        """Start a run; ``rng`` is the agent's own random stream (after ``context.draws``)."""

    def act(self, observation: Observation) -> float:
        """The acceleration [m/s^2] at this step."""


class CompiledPolicy:
    """A compiled kind behind the Python protocol (the same step the compiled loop calls)."""

    def __init__(self, kind: str, side: int):
        if kind not in SIDE_KINDS[side]:
            who = "av" if side == kd.AV else "hv"
            raise ConfigError(f"{who}.kind = {kind!r} is out of range; allowed: "
                              f"{' | '.join(SIDE_KINDS[side])}")
        self.spec = KINDS[kind]
        self.side = side
        self.log_columns = self.spec.log
        self.needs_game = self.spec.needs_game
        self.needs_av_library = self.spec.needs_av_library
        self.has_role = self.spec.has_role

    def reset(self, context: Context, rng: np.random.Generator | None = None) -> None:
        from .step import policy_init

        self.context = context
        self.prm = policy_params(context.config, self.side)
        self.state = np.zeros(state_size(self.prm, self.spec.kind))
        policy_init(self.spec.kind, self.prm, self.state, float(context.P_av[slot.PRIOR_L]))
        n_traj = context.config.library.n_traj
        self.diag = np.zeros((n_traj, 10))
        self.last_log = np.full(kd.LOG_SIZE, np.nan)
        self._draws = context.draws

    @property
    def role(self) -> int:
        """The current role (0 = L, 1 = F) of a role-holding kind, else -1."""
        from .step import policy_role

        return int(policy_role(self.spec.kind, self.state))

    def act(self, observation: Observation) -> float:
        from ..kinematics import check_state
        from .step import policy_step_buffers

        ctx = self.context
        for name in ("av", "hv"):
            check_state(f"observation.{name}", getattr(observation, name),
                        ctx.config.vehicle_of(name))
        games = ctx.games
        view = observation.game
        if view is None:
            view = games.empty_view()
        if self.needs_av_library and not self.needs_game and observation.game is None:
            view = games.av_library(observation.av)
        k = observation.step
        draws = self._draws[k] if self._draws.shape[1] else np.zeros(2)
        self.last_log[:] = np.nan
        return float(policy_step_buffers(
            self.spec.kind, self.side, self.prm, self.state, k, float(observation.av[0]),
            float(observation.av[1]), float(observation.hv[0]), float(observation.hv[1]),
            draws, int(observation.human_role), *view.hv, *view.av, view.idx, view.q_values,
            ctx.P_av, ctx.P_hv, ctx.disc, ctx.config.simulation.dt_s, self.diag,
            *games.ahead_a, *games.ahead_b, games.ahead, self.last_log, games.work))


def make_policy(config: Config, side: int) -> CompiledPolicy:
    """The :class:`CompiledPolicy` that ``config`` names for ``side``."""
    return CompiledPolicy((config.av if side == kd.AV else config.hv).kind, side)


__all__ = ["CompiledPolicy", "Context", "Observation", "Policy", "Recording", "kind_of",
           "load_replay", "make_policy", "policy_params", "state_size"]
