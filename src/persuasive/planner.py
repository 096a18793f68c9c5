"""The AV's planner as a library call: give it the two vehicles' states, get an action.

:class:`Planner` runs one AV policy (docs/method.md §6, §11; the paper's persuasive branch MPC
by default) inside a user's own loop, e.g. a vehicle stack at 10 Hz. It is the same compiled
step the closed loop calls (``persuasive.policies.step.policy_step``), and it keeps between
calls what the policy keeps: for the MPC, the belief on the human's role and the stored
one-step prediction of the human. It uses corrected mode by default (the paper's equations),
and with it the worst-case safety shield (docs/method.md §12): every acceleration it returns
keeps a fallback that avoids the human whatever it does within its limits (``Plan.shielded``
says when the shield overrode the policy). Pass a configuration to change any parameter,
quirk, planner kind, shield or scenario.

Example
-------
>>> from persuasive import Planner
>>> planner = Planner()
>>> plan = planner.plan(av=(-20.0, 4.0), hv=(-22.0, 4.3))
>>> plan.accel_mps2, plan.feasible  # doctest: +SKIP
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import packing as slot
from .config import Config, ConfigError
from .game import build_buffers, predict_buffers, shifted_into
from .kinematics import check_state
from .library import lib_buffers
from .mpc import D_EXPECTED, D_MIN_SAFE, D_P_LL, N_DIAG
from .packing import discounts, pack
from .policies import kinds as kd
from .online import grid_view, posterior_of, prior_view
from .policies import kind_of, policy_params, state_size
from .policies.planners import ONLINE_STATE, PRM_ONLINE
from .policies.step import policy_init, policy_step_buffers
from .roles import FOLLOWER, LEADER
from .safety.filter import ShieldFilter
from .scenarios import build_scenario

State = tuple[float, float]


class CandidateView(NamedTuple):
    """A decision's candidates (:meth:`Planner.candidate_view`): per-candidate diagnostics
    ``(n_traj, 10)`` (``persuasive.mpc``'s ``D_*`` columns), the sample-major trajectories
    ``S, V, A`` ``(n, n_traj)`` and each one's collision-free reward ``base`` ``(n_traj,)``."""

    diag: np.ndarray
    S: np.ndarray
    V: np.ndarray
    A: np.ndarray
    base: np.ndarray


@dataclass(frozen=True)
class Plan:
    """One decision of the planner. Fields a kind does not compute are NaN."""

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
    proposed_accel_mps2: float = math.nan  #: the policy's acceleration before the shield
    shielded: bool = False  #: the shield overrode the policy (``accel_mps2`` is its fallback)
    shield_verdict: str | None = None  #: admitted | brake | go | uncertified; None: no shield
    model_confidence: float = math.nan  #: the MPC's confidence in its human model
    #: the p_a_hat this decision planned with (online: the posterior mean; NaN for kinds that
    #: do not use one)
    p_a_hat: float = math.nan


class Planner:
    """The AV's planner (the persuasive branch MPC unless ``config.av.kind`` says otherwise).

    Parameters
    ----------
    config : Config, optional
        All parameters; default ``Config(mode="corrected")``. ``config.av.kind`` selects the
        planner: persuasive, passive, cv, yield or lfg; ``config.scenario`` the geometry.
    seed : int, optional
        Seed of the planner's own uniforms (only the ``lfg`` kind draws: its role changes),
        and of foresight's predictions (below; unset: 0).
    p_a_prior : array, optional
        With ``mpc.p_a_hat = "online"`` (persuasive planner): the prior masses over the grid
        :attr:`p_a_grid` in place of the Beta prior ``mpc.p_a_prior``, e.g. a
        :attr:`p_a_posterior` saved after earlier encounters with the same human.

    **Foresight** (``Config.yield_line_choices``: corrected mode's default, [0, 3.75, 8] m,
    docs/method.md §12.12): at the first decision of an encounter (after :meth:`reset`) the
    planner picks its shield's yield line among those by predicting the run from the states
    it is given, as ``simulate(config, seed)`` does from its run's first measurement (the
    predictions' random stream is that of ``seed``: with the run's seed and state, the same
    line); :attr:`yield_line_m` says which (about 15 model runs once, some 0.1 s, not in the
    per-decision budget).

    With ``mpc.p_a_hat = "online"`` the planner keeps a posterior over the human's ``p_a``
    (docs/method.md §13.9) and plans with its mean (:attr:`p_a_hat`). :meth:`reset` starts a
    new encounter; ``reset(keep_posterior=True)`` when it is with the same human carries the
    posterior over as the new encounter's prior (the role belief starts afresh).
    """

    def __init__(self, config: Config | None = None, seed: int | None = None,
                 p_a_prior=None):
        self.config = config if config is not None else Config(mode="corrected")
        self._spec = kind_of(self.config, kd.AV)
        self._scenario = build_scenario(self.config)
        self._P_av, self._P_hv = pack(self.config, self._scenario)
        self._P_av0 = self._P_av
        self._seed = 0 if seed is None else int(seed)
        #: the yield line foresight picked for this encounter [m] (None: not yet, or off)
        self.yield_line_m: float | None = None
        self._disc = discounts(self.config)
        self._prm = policy_params(self.config, kd.AV, p_a_prior)
        n, n_traj = self.config.library.n_samples, self.config.library.n_traj
        self._hv, self._av = lib_buffers(n, n_traj), lib_buffers(n, n_traj)
        self._ahead_a, self._ahead_b = lib_buffers(n, n_traj), lib_buffers(n, n_traj)
        self._ahead = np.zeros((2, 3))
        self._idx = np.zeros(4, np.int64)
        self._q_values = np.zeros((4, n_traj))
        self._diag = np.full((n_traj, N_DIAG), np.nan)
        self._log = np.full(kd.LOG_SIZE, np.nan)
        self.work = np.zeros(slot.N_WORK, np.int64)  #: the kernels' counters, summed over calls
        self._times = np.arange(1, n + 1) * self.config.library.sample_dt_s
        self._rng = np.random.Generator(np.random.PCG64(seed))
        self._draws = np.zeros(2)
        self._state = np.zeros(state_size(self._prm, self._spec.kind))
        self._online = self._state.shape[0] > kd.STATE_SIZE
        self._k = 0
        self._shield = ShieldFilter.closed_loop(self._P_av, self._P_hv,
                                                self.config.simulation.dt_s)
        self._tie_given = self.config.effective_quirks.q3_tie_break_leak and \
            self._spec.kind in (kd.PERSUASIVE, kd.PASSIVE)
        self._prm0 = self._prm.copy()
        self.reset()

    def reset(self, keep_posterior: bool = False) -> None:
        """Forget the belief and the stored prediction (a new encounter). With an online
        posterior over ``p_a``: ``keep_posterior=True`` (the same human again) makes the
        posterior the new encounter's prior; otherwise the prior the planner was built
        with comes back."""
        if keep_posterior and self._online:
            prior_view(self._prm, PRM_ONLINE)[:] = self.p_a_posterior
        elif self._online:
            self._prm[:] = self._prm0
        policy_init(self._spec.kind, self._prm, self._state, float(self._P_av[slot.PRIOR_L]))
        self._k = 0
        if self.yield_line_m is not None:  # the next encounter picks its own line
            self._P_av, self.yield_line_m = self._P_av0, None
            self._shield = ShieldFilter.closed_loop(self._P_av, self._P_hv,
                                                    self.config.simulation.dt_s)

    def _foresee(self, x_R: State, x_H: State) -> None:
        """Foresight at an encounter's first decision (class docstring): pick the line and
        set it in the planner's parameters and shield."""
        from .packing import place_yield_line
        from .safety.foresight import choose_line
        from .world import predicted_summary

        x0 = np.array([x_R[0], x_R[1], x_H[0], x_H[1]], dtype=np.float64)
        line = choose_line(self.config, self._seed, x0, predicted_summary)
        self._P_av = self._P_av0.copy()  # the packed vector is shared: never changed
        place_yield_line(self._P_av, line)
        self._shield = ShieldFilter.closed_loop(self._P_av, self._P_hv,
                                                self.config.simulation.dt_s)
        self.yield_line_m = line

    @property
    def kind(self) -> str:
        """The planner's kind (``config.av.kind``)."""
        return self._spec.name

    @property
    def p_a_hat(self) -> float:
        """The estimate of ``p_a`` the next decision plans with: the posterior mean when
        online, else ``mpc.p_a_hat`` (NaN for kinds that use none)."""
        if self._online:
            return float(self._state[ONLINE_STATE])
        return self.config.p_a_hat if self._spec.kind == kd.PERSUASIVE else math.nan

    @property
    def p_a_grid(self) -> np.ndarray | None:
        """The online posterior's grid over ``p_a`` ``(G,)`` (None unless online)."""
        if not self._online:
            return None
        return grid_view(self._prm, PRM_ONLINE).copy()

    @property
    def p_a_posterior(self) -> np.ndarray | None:
        """The online posterior's masses over :attr:`p_a_grid` ``(G,)``, a copy (None unless
        online); pass it as ``p_a_prior`` to a new planner to carry it on."""
        if not self._online:
            return None
        return posterior_of(self._state, ONLINE_STATE, int(self._prm[PRM_ONLINE]))

    @property
    def belief_hv_leader(self) -> float:
        """Current P(HV = leader) (NaN for kinds without a belief)."""
        if self._spec.kind in (kd.PERSUASIVE, kd.PASSIVE):
            return float(self._state[0])
        return math.nan

    def plan(self, av: State, hv: State, human_role: str | None = None) -> Plan:
        """Decide the AV's acceleration at AV state ``av`` and HV state ``hv``.

        ``av``, ``hv``: ``(s [m], v [m/s])`` along each vehicle's path, ``s < 0`` before the
        conflict point. ``human_role`` ("leader"/"follower") is needed only with quirk Q3 on
        (paper mode), where a belief tie reads the human's true role.
        """
        x_R, x_H = _state("av", av, self.config), _state("hv", hv, self.config)
        if human_role is not None and human_role not in ("leader", "follower"):
            raise ConfigError(f"human_role = {human_role!r} is out of range; allowed: "
                              "leader | follower")
        if self._tie_given and human_role is None:
            raise ConfigError("human_role is required with quirk Q3 (paper mode); "
                              "allowed: leader | follower")
        role = -1 if human_role is None else (LEADER if human_role == "leader" else FOLLOWER)
        proposed = self._step(x_R, x_H, role)
        # decide, then filter: the same shield as every world applies (persuasive.safety.filter)
        accel, code = self._shield.one(proposed, x_R, x_H)
        return self._plan(accel, proposed, ShieldFilter.name(code))

    def accel(self, av: State, hv: State) -> float:
        """The acceleration [m/s^2] the planner *proposes* at the same states as :meth:`plan`
        (its ``proposed_accel_mps2``), with the same update of the belief and the stored
        prediction, but before the shield, without the :class:`Plan` around it and without
        checking the states: for a caller that plans against many vehicles and applies the
        one shield over all of them itself, and that passes finite states with speeds inside
        the vehicles' limits (the adapter for outside simulators, ``persuasive.envs.external``).
        Not with quirk Q3 on."""
        if self._tie_given:
            raise ConfigError("Planner.accel cannot take the human's role (quirk Q3, paper "
                              "mode); use Planner.plan")
        return self._step((float(av[0]), float(av[1])), (float(hv[0]), float(hv[1])), -1)

    def accel_among(self, av: State, hv: State, candidates: tuple) -> float:
        """:meth:`accel` with other candidates than the AV's own library at ``av``:
        ``candidates = (S, V, A, shift)``, sample-major ``(n, n_traj)`` positions [m], speeds
        [m/s] and accelerations [m/s^2] of another frame, ``shift`` [m] added to ``S`` to put
        them in this planner's frame (their first sample follows ``av``). The human's full
        prediction is still made with the AV's own library (what the human expects of the
        AV); the candidates then replace it for the decision: their reward parts are computed
        here (``persuasive.rewards.reward_terms``). For a planner of many humans that
        evaluates one set of candidates against each (``persuasive.many.joint``); read the
        result with :meth:`candidate_view` and :meth:`allowed_now`."""
        if self._tie_given:
            raise ConfigError("Planner.accel_among cannot take the human's role (quirk Q3, "
                              "paper mode); use Planner.plan")
        return self._step((float(av[0]), float(av[1])), (float(hv[0]), float(hv[1])), -1,
                          candidates)

    def candidate_view(self) -> CandidateView:
        """The last decision's candidates and their diagnostics, as views of the planner's
        buffers (valid until its next call)."""
        n = self.config.library.n_samples
        buf = self._av[0]
        return CandidateView(self._diag, buf[0:n], buf[n:2 * n], buf[2 * n:3 * n], buf[6 * n])

    def allowed_now(self, av: State, hv: State, out: np.ndarray) -> int:
        """Which of the last decision's candidates may count as feasible at states ``av``,
        ``hv`` (``persuasive.policies.planners.shield_allowed``, with the confidence filter's
        verdict of that decision), into ``out`` ``(n_traj,)`` bool; returns how many."""
        from .policies.planners import CONFIDENCE, allowed_of

        P = self._P_av
        robust = self._spec.kind in (kd.PERSUASIVE, kd.PASSIVE) and \
            P[slot.CONF_THRESHOLD] > 0.0 and self._state[CONFIDENCE] < P[slot.CONF_THRESHOLD]
        return int(allowed_of(float(av[0]), float(av[1]), float(hv[0]), float(hv[1]),
                              *self._av, P, self._P_hv, bool(robust), out))

    def _step(self, x_R: State, x_H: State, role: int, candidates: tuple | None = None
              ) -> float:
        """One decision, before the shield: the proposed acceleration; advances the kept
        state. ``candidates``: as :meth:`accel_among`."""
        if self._k == 0 and self.yield_line_m is None and \
                self.config.yield_line_choices is not None:
            self._foresee(x_R, x_H)
        if self._spec.needs_game:
            predict_buffers(x_H[0], x_H[1], x_R[0], x_R[1], self._P_hv, self._P_av, self._disc,
                            *self._hv, *self._av, self._idx, self._q_values, self.work)
        elif self._spec.needs_av_library:
            build_buffers(x_R[0], x_R[1], self._P_av, self._disc, *self._av)
        if candidates is not None:
            S, V, A, shift = candidates
            shifted_into(S, V, A, float(shift), x_R[0], self._P_av, self._disc, *self._av)
        if self._spec.draws:
            self._draws[:self._spec.draws] = self._rng.random(self._spec.draws)
        self._log[:] = np.nan
        accel = policy_step_buffers(
            self._spec.kind, kd.AV, self._prm, self._state, self._k, x_R[0], x_R[1], x_H[0],
            x_H[1], self._draws, role, *self._hv, *self._av, self._idx, self._q_values,
            self._P_av, self._P_hv, self._disc, self.config.simulation.dt_s, self._diag,
            *self._ahead_a, *self._ahead_b, self._ahead, self._log, self.work)
        self._k += 1
        return float(accel)

    def _plan(self, accel: float, proposed: float, verdict: str | None) -> Plan:
        n = self.config.library.n_samples
        col = self._spec.log.index("trajectory")
        k = int(self._log[col]) if not math.isnan(self._log[col]) else -1
        buf = self._av[0]
        mpc = self._spec.kind in (kd.PERSUASIVE, kd.PASSIVE, kd.CV)
        d = self._diag[k] if mpc and k >= 0 else np.full(N_DIAG, np.nan)
        traj = (lambda row: buf[row * n:(row + 1) * n, k].copy()) if k >= 0 else \
            (lambda row: np.full(n, np.nan))
        epsilon = self.config.mpc.epsilon
        feasible = bool(self._log[1]) if mpc else True
        return Plan(
            accel_mps2=accel,
            candidate=k,
            t_s=self._times.copy(),
            s_m=traj(0),
            v_mps=traj(1),
            a_mps2=traj(2),
            branch_probabilities={b: float(d[D_P_LL + i]) for i, b in
                                  enumerate(("LL", "LF", "FL", "FF"))},
            expected_reward=float(d[D_EXPECTED]),
            p_safe_min=float(d[D_MIN_SAFE]),
            chance_margin=float(d[D_MIN_SAFE] - (1.0 - epsilon)),
            feasible=feasible,
            belief_hv_leader=self.belief_hv_leader,
            candidates=self._diag.copy() if mpc else np.full_like(self._diag, np.nan),
            proposed_accel_mps2=proposed,
            shielded=verdict not in (None, "admitted"),
            shield_verdict=verdict,
            model_confidence=float(self._log[self._spec.log.index("model_confidence")])
            if "model_confidence" in self._spec.log else math.nan,
            p_a_hat=float(self._log[self._spec.log.index("p_a_hat")])
            if "p_a_hat" in self._spec.log else math.nan,
        )


def _state(name: str, x, config: Config) -> tuple[float, float]:
    """A validated ``(s, v)`` of vehicle ``name`` ("av"/"hv")."""
    return check_state(name, x, config.vehicle_of(name))


__all__ = ["CandidateView", "Plan", "Planner"]
