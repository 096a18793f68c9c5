"""The closed loop (docs/method.md §7): measure, decide (HV first, then AV), advance.

One run is a pure function of its configuration and seed. The world owns what the two
policies share and nothing of what they decide:

- the **random streams** (``persuasive.streams``, drawn by ``persuasive.record.setup``): the
  initial state, each agent's uniforms and the world's noise, drawn up front;
- **measuring** and **advancing** (:func:`measure_states`, :func:`advance_states`): additive
  measurement noise (speeds clipped to each vehicle's limits), acceleration noise, the
  saturated step of each vehicle;
- the **game cache**: the full prediction of the joint state from the human's view, computed
  once per step for every policy that needs it (the LFG human's own game *is* the persuasive
  MPC's prediction of the human), and the MPC's look-ahead libraries of the HV one sample
  ahead, reused when the HV's next measured state is one of them (exact equality).

The same two functions drive :func:`run_loop` (compiled, over compiled policies) and
:func:`run_python` (Python, over :class:`~persuasive.policies.Policy` objects: a person, a
replay, an external simulator); a test keeps the two bit-identical.

States are indexed ``x_0 .. x_N`` (``N = n_steps``): step ``k`` decides at ``x_k`` and advances
to ``x_{k+1}``. The run never stops early.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit, objmode

from . import packing as slot
from .config import Config, ConfigError
from .game import build, predict_into
from .kinematics import saturated_step
from .library import lib_buffers, new_lib
from .mpc import AHEAD_S, AHEAD_V, AHEAD_VALID, N_DIAG
from .policies import kinds as kd
from .policies.step import policy_init, policy_role, policy_step
from .record import (W_AV_A, W_AV_PROPOSED, W_AV_S, W_AV_V, W_HV_A, W_HV_S, W_HV_V, W_SHIELD,
                     WORLD_LOG, make_record, setup)
from .safety.filter import ShieldFilter
from .safety.shield import N_CONFLICT, ONE_BUFFER, conflict_vector, shield_filter_one
from .streams import measure_states  # noqa: F401  (the loops' measurement; envs use it here)


# -- measuring and advancing (shared by both loops) --------------------------------------------


@njit(cache=True, _nrt=False)
def advance_states(x: np.ndarray, a_av: float, a_hv: float, k: int, noisy: bool,
                   accel_noise: np.ndarray, dt: float, P_av: np.ndarray, P_hv: np.ndarray,
                   out: np.ndarray) -> tuple[float, float]:
    """Advance the true state ``x`` by one step into ``out``; returns the applied
    accelerations (with their noise)."""
    if noisy:
        a_av += accel_noise[k, 0]
        a_hv += accel_noise[k, 1]
    out[0], out[1] = saturated_step(x[0], x[1], a_av, dt, P_av[slot.V_MIN], P_av[slot.V_MAX])
    out[2], out[3] = saturated_step(x[2], x[3], a_hv, dt, P_hv[slot.V_MIN], P_hv[slot.V_MAX])
    return a_av, a_hv


@njit(cache=True)
def _clock_ns() -> int:
    with objmode(t="int64"):
        t = time.perf_counter_ns()
    return t


# -- the compiled loop -------------------------------------------------------------------------


@njit(cache=True)
def run_loop(P_av: np.ndarray, P_hv: np.ndarray, disc: np.ndarray, x0: np.ndarray, dt: float,
             av_kind: int, av_prm: np.ndarray, hv_kind: int, hv_prm: np.ndarray,
             av_draws: np.ndarray, hv_draws: np.ndarray, needs: np.ndarray, noisy: bool,
             meas_noise: np.ndarray, accel_noise: np.ndarray, timed: bool,
             states: np.ndarray, world_log: np.ndarray, av_log: np.ndarray,
             hv_log: np.ndarray, av_time_ns: np.ndarray, work: np.ndarray,
             av_st: np.ndarray, stop_av_m: float, stop_hv_m: float) -> int:
    """The closed loop, compiled: fills ``states`` ``(n_steps + 1, 4)`` and the logs;
    returns the steps taken.

    ``needs`` (3,) bool: compute the full prediction of the joint state (some policy reads
    it); build only the AV's library (a policy reads it, none the game); the AV's timing
    includes that work. ``av_time_ns`` (n_steps,): the AV's decision time per step when
    ``timed``. ``work``: the kernels' counters (``persuasive.packing.WORK_*``), added to.
    ``av_st``: the AV policy's state (``persuasive.policies.state_size`` slots), initialised
    here and left as the run ends it (e.g. the online posterior over ``p_a``).
    ``stop_av_m``, ``stop_hv_m``: the loop ends after the first step that leaves both
    vehicles at or past these positions (``math.inf``: never); the states and logs up to there
    are those of the whole run (a step reads nothing of the steps after it), the rest is
    left as it was (foresight's predictions, ``persuasive.safety.foresight``).
    """
    n, n_traj = int(P_av[slot.N_SAMPLES]), int(P_av[slot.N_MESH]) + 1
    lib_h, lib_r = new_lib(n, n_traj), new_lib(n, n_traj)
    # The MPC builds the HV's libraries one sample ahead (ahead[0] into lib_h1a, ahead[1] into
    # lib_h1b). Unless noise moved the HV, its next measured state is one of them and that
    # library is reused as the next step's HV library.
    lib_h1a, lib_h1b = new_lib(n, n_traj), new_lib(n, n_traj)
    ahead = np.zeros((2, 3))
    idx = np.zeros(4, np.int64)
    q_values = np.zeros((4, n_traj))
    diag = np.empty((n_traj, N_DIAG))
    hv_st = np.zeros(kd.STATE_SIZE)
    policy_init(av_kind, av_prm, av_st, P_av[slot.PRIOR_L])
    policy_init(hv_kind, hv_prm, hv_st, P_hv[slot.PRIOR_L])
    need_game, need_av_lib, av_uses_libs = needs[0], needs[1], needs[2]
    # the shield (one conflict): decide, then filter (persuasive.safety.filter)
    shield_kind, u_brake = P_av[slot.SHIELD], P_av[slot.U_MIN]
    shield_buf = np.zeros(ONE_BUFFER)
    conflict_vector(P_av, P_hv, shield_buf[:N_CONFLICT])
    no_draws = np.zeros(2)
    x = np.empty(4)
    x[:] = x0
    states[0, :] = x
    for k in range(states.shape[0] - 1):
        ms_av, mv_av, ms_hv, mv_hv = measure_states(x, k, noisy, meas_noise, P_av, P_hv)
        t0 = _clock_ns() if timed else 0
        if need_game:
            built = False
            for i in range(2):
                if (not built and ahead[i, AHEAD_VALID] != 0.0 and ahead[i, AHEAD_S] == ms_hv
                        and ahead[i, AHEAD_V] == mv_hv):
                    if i == 0:
                        lib_h, lib_h1a = lib_h1a, lib_h
                    else:
                        lib_h, lib_h1b = lib_h1b, lib_h
                    built = True
            ahead[:, AHEAD_VALID] = 0.0  # the scratch libraries are stale from here
            predict_into(ms_hv, mv_hv, ms_av, mv_av, P_hv, P_av, disc, lib_h, lib_r, idx,
                         q_values, work, built)
        elif need_av_lib:
            build(ms_av, mv_av, P_av, disc, lib_r)
            work[slot.WORK_LIBRARIES] += 1
        t_libs = (_clock_ns() - t0) if timed else 0
        hv_draw = hv_draws[k] if hv_draws.shape[1] else no_draws
        a_hv = policy_step(hv_kind, kd.HV, hv_prm, hv_st, k, ms_av, mv_av, ms_hv, mv_hv,
                           hv_draw, -1, lib_h, lib_r, idx, q_values, P_av, P_hv, disc, dt, diag,
                           lib_h1a, lib_h1b, ahead, hv_log[k], work)
        av_draw = av_draws[k] if av_draws.shape[1] else no_draws
        t1 = _clock_ns() if timed else 0
        a_av = policy_step(av_kind, kd.AV, av_prm, av_st, k, ms_av, mv_av, ms_hv, mv_hv,
                           av_draw, policy_role(hv_kind, hv_st), lib_h, lib_r, idx, q_values,
                           P_av, P_hv, disc, dt, diag, lib_h1a, lib_h1b, ahead, av_log[k], work)
        row = world_log[k]
        row[W_AV_PROPOSED] = a_av
        a_av, verdict = shield_filter_one(shield_kind, a_av, ms_av, mv_av, dt, u_brake, ms_hv,
                                          mv_hv, shield_buf)
        row[W_SHIELD] = verdict
        if not (math.isfinite(a_av) and math.isfinite(a_hv)):  # never propagated
            raise ValueError("a policy's acceleration is not finite (and no shield replaced it)")
        if timed:
            av_time_ns[k] = (_clock_ns() - t1) + (t_libs if av_uses_libs else 0)
        row[W_AV_S], row[W_AV_V], row[W_HV_S], row[W_HV_V] = ms_av, mv_av, ms_hv, mv_hv
        row[W_AV_A], row[W_HV_A] = advance_states(x, a_av, a_hv, k, noisy, accel_noise, dt,
                                                  P_av, P_hv, x)
        states[k + 1, :] = x
        if x[0] >= stop_av_m and x[2] >= stop_hv_m:
            return k + 1
    return states.shape[0] - 1


# -- the Python loop ---------------------------------------------------------------------------


class GameView:
    """One full prediction of the joint state from the human's view, as buffers.

    ``hv``, ``av``: each library as its ``(buf, win)`` storage
    (:func:`persuasive.library.lib_buffers`); ``idx``: (HV-L, HV-F, AV-L, AV-F);
    ``q_values`` ``(4, n_traj)``.
    """

    __slots__ = ("hv", "av", "idx", "q_values")

    def __init__(self, hv, av, idx, q_values):
        self.hv, self.av, self.idx, self.q_values = hv, av, idx, q_values


class GameCache:
    """The Python loop's game cache: full predictions keyed on the exact joint state, and the
    MPC's look-ahead libraries (reused like the compiled loop does)."""

    def __init__(self, P_av: np.ndarray, P_hv: np.ndarray, disc: np.ndarray):
        from .game import predict_buffers

        self._predict = predict_buffers
        self.P_av, self.P_hv, self.disc = P_av, P_hv, disc
        self._shape = (int(P_av[slot.N_SAMPLES]), int(P_av[slot.N_MESH]) + 1)
        self.ahead_a, self.ahead_b = lib_buffers(*self._shape), lib_buffers(*self._shape)
        self.ahead = np.zeros((2, 3))
        self._key: tuple | None = None
        self._view: GameView | None = None
        self.solves = 0  #: number of games actually solved
        self.work = np.zeros(slot.N_WORK, np.int64)  #: the kernels' counters

    def empty_view(self) -> GameView:
        n, n_traj = self._shape
        return GameView(lib_buffers(n, n_traj), lib_buffers(n, n_traj), np.zeros(4, np.int64),
                        np.zeros((4, n_traj)))

    def __call__(self, x_av, x_hv) -> GameView:
        """The full prediction at measured ``x_av``, ``x_hv`` (each ``(s, v)``)."""
        from .game import build_buffers

        key = (float(x_hv[0]), float(x_hv[1]), float(x_av[0]), float(x_av[1]))
        if key == self._key:
            return self._view
        n, n_traj = self._shape
        hv, av = lib_buffers(n, n_traj), lib_buffers(n, n_traj)
        built = False
        for i, scratch in enumerate((self.ahead_a, self.ahead_b)):
            a = self.ahead[i]
            if not built and a[AHEAD_VALID] != 0.0 and a[AHEAD_S] == key[0] and a[AHEAD_V] == key[1]:
                hv[0][:], hv[1][:] = scratch[0], scratch[1]
                built = True
        self.ahead[:, AHEAD_VALID] = 0.0
        idx, q_values = np.empty(4, np.int64), np.empty((4, n_traj))
        if not built:
            build_buffers(key[0], key[1], self.P_hv, self.disc, *hv)
            self.work[slot.WORK_LIBRARIES] += 1
        else:
            self.work[slot.WORK_LIBRARIES_REUSED] += 1
        build_buffers(key[2], key[3], self.P_av, self.disc, *av)
        self.work[slot.WORK_LIBRARIES] += 1
        from .game import solve_buffers

        solve_buffers(*hv, *av, self.P_hv, idx, q_values, self.work)
        self.solves += 1
        self._key, self._view = key, GameView(hv, av, idx, q_values)
        return self._view

    def av_library(self, x_av) -> GameView:
        """A view holding only the AV's library at ``x_av`` (for policies that need no game)."""
        from .game import build_buffers

        view = self.empty_view()
        build_buffers(float(x_av[0]), float(x_av[1]), self.P_av, self.disc, *view.av)
        self.work[slot.WORK_LIBRARIES] += 1
        return view


class PythonWorld:
    """The Python loop, one step at a time, over :class:`~persuasive.policies.Policy` objects.

    ``av``, ``hv``: the policies (default: the configuration's kinds, as
    :class:`~persuasive.policies.CompiledPolicy`). A policy may declare ``draws_per_step``
    (default: its kind's, or 0) uniforms of the run's streams. :meth:`step` decides and
    advances once (the HV decides first, then the AV, as in :func:`run_loop`); :meth:`record`
    is the :class:`~persuasive.simulation.RunRecord` of the steps taken so far. Drives the
    browser page (a person as the HV), the gymnasium environment and :func:`run_python`.
    """

    def __init__(self, config: Config, seed: int, av=None, hv=None, timed: bool = False):
        from .policies import Context, make_policy

        self.config = config
        self.av = av if av is not None else make_policy(config, kd.AV)
        self.hv = hv if hv is not None else make_policy(config, kd.HV)
        self.timed = timed
        k_av, k_hv = (_draws_per_step(p) for p in (self.av, self.hv))
        self.setup = s = setup(config, seed, k_av, k_hv, predict=predicted_summary)
        self.scenario = s.scenario
        self.n_steps = n = config.simulation.n_steps
        self.dt = config.simulation.dt_s
        self.games = GameCache(s.P_av, s.P_hv, s.disc)
        self.shield = ShieldFilter.closed_loop(s.P_av, s.P_hv, self.dt)
        st = s.streams
        for policy, side, draws, rng in ((self.av, kd.AV, st.draws_av, st.av_rng),
                                         (self.hv, kd.HV, st.draws_hv, st.hv_rng)):
            policy.reset(Context(config, s.scenario, s.P_av, s.P_hv, s.disc, side, n, draws,
                                 self.games), rng)
        self._need_game = getattr(self.av, "needs_game", False) or \
            getattr(self.hv, "needs_game", False)
        self.states = np.empty((n + 1, 4))
        self.world_log = np.full((n, len(WORLD_LOG)), np.nan)
        self.av_log = np.full((n, kd.LOG_SIZE), np.nan)
        self.hv_log = np.full((n, kd.LOG_SIZE), np.nan)
        self.av_ms = np.zeros(n)
        self.x = s.x0.copy()
        self.states[0] = self.x
        self.k = 0  #: steps taken

    @property
    def done(self) -> bool:
        """All ``n_steps`` steps have been taken."""
        return self.k >= self.n_steps

    def step(self) -> np.ndarray:
        """Decide and advance one step; returns the new true state ``(s_av, v_av, s_hv,
        v_hv)``."""
        from .policies import Observation

        if self.done:
            raise ConfigError(f"the run has ended after {self.n_steps} steps "
                              "(simulation.n_steps)")
        s, st, k = self.setup, self.setup.streams, self.k
        ms_av, mv_av, ms_hv, mv_hv = measure_states(self.x, k, st.noisy, st.meas_noise, s.P_av,
                                                    s.P_hv)
        t0 = time.perf_counter_ns()
        game = self.games((ms_av, mv_av), (ms_hv, mv_hv)) if self._need_game else None
        t_game = time.perf_counter_ns() - t0
        obs = Observation(k, k * self.dt, (ms_av, mv_av), (ms_hv, mv_hv), game)
        a_hv = float(self.hv.act(obs))
        if not math.isfinite(a_hv):  # no world propagates a non-finite state
            raise ValueError(f"the human's policy returned a non-finite acceleration "
                             f"({a_hv!r}) at step {k}")
        self.hv_log[k, :len(self.hv.log_columns)] = _last_log(self.hv)
        obs.human_role = int(getattr(self.hv, "role", -1))
        t1 = time.perf_counter_ns()
        a_av = float(self.av.act(obs))
        row = self.world_log[k]
        row[W_AV_PROPOSED] = a_av
        # the same filter as the compiled loop, after any AV policy
        a_av, row[W_SHIELD] = self.shield.one(a_av, (ms_av, mv_av), (ms_hv, mv_hv))
        own = t_game if getattr(self.av, "needs_game", False) else 0
        self.av_ms[k] = (time.perf_counter_ns() - t1 + own) / 1e6
        self.av_log[k, :len(self.av.log_columns)] = _last_log(self.av)
        row[W_AV_S], row[W_AV_V], row[W_HV_S], row[W_HV_V] = ms_av, mv_av, ms_hv, mv_hv
        row[W_AV_A], row[W_HV_A] = advance_states(self.x, a_av, a_hv, k, st.noisy,
                                                  st.accel_noise, self.dt, s.P_av, s.P_hv,
                                                  self.x)
        self.states[k + 1] = self.x
        self.k += 1
        return self.x.copy()

    def record(self):
        """The :class:`~persuasive.simulation.RunRecord` of the steps taken so far (all of
        them once :attr:`done`)."""
        k = self.k
        return make_record(self.setup, self.states[:k + 1], self.world_log[:k], self.av_log[:k],
                           self.hv_log[:k], self.av_ms[:k] if self.timed else None,
                           tuple(self.av.log_columns), tuple(self.hv.log_columns),
                           self.games.work)


def run_compiled(s, av_prm: np.ndarray, hv_prm: np.ndarray, timed: bool = False):
    """The compiled loop (:func:`run_loop`) over the setup ``s``
    (:class:`persuasive.record.Setup`) with the two policies' parameter vectors: the run's
    :class:`~persuasive.simulation.RunRecord` and the AV's final state vector (which holds an
    online posterior over ``p_a``)."""
    arrays, _ = _run_arrays(s, av_prm, hv_prm, timed)
    states, world_log, av_log, hv_log, av_ns, work, av_st = arrays
    record = make_record(s, states, world_log, av_log, hv_log,
                         av_ns / 1e6 if timed else None, work=work)
    return record, av_st


def _run_arrays(s, av_prm: np.ndarray, hv_prm: np.ndarray, timed: bool = False,
                stop_av_m: float = math.inf, stop_hv_m: float = math.inf):
    """:func:`run_loop` over the setup ``s``: its arrays ``(states, world_log, av_log,
    hv_log, av_time_ns, work, av_st)`` and the steps taken (``stop_*``: :func:`run_loop`)."""
    from .packing import N_WORK
    from .policies import kind_of, state_size

    config = s.config
    n = config.simulation.n_steps
    av, hv = kind_of(config, kd.AV), kind_of(config, kd.HV)
    states = np.empty((n + 1, 4))
    world_log = np.full((n, len(WORLD_LOG)), np.nan)
    av_log, hv_log = np.full((n, kd.LOG_SIZE), np.nan), np.full((n, kd.LOG_SIZE), np.nan)
    av_ns = np.zeros(n, np.int64)
    work = np.zeros(N_WORK, np.int64)
    needs = np.array([av.needs_game or hv.needs_game,
                      av.needs_av_library or hv.needs_av_library,
                      av.needs_game or av.needs_av_library])
    st = s.streams
    av_st = np.zeros(state_size(av_prm, av.kind))
    steps = run_loop(s.P_av, s.P_hv, s.disc, s.x0, config.simulation.dt_s, av.kind, av_prm,
                     hv.kind, hv_prm, st.draws_av, st.draws_hv, needs, st.noisy,
                     st.meas_noise, st.accel_noise, timed, states, world_log, av_log, hv_log,
                     av_ns, work, av_st, float(stop_av_m), float(stop_hv_m))
    return (states, world_log, av_log, hv_log, av_ns, work, av_st), steps


def predicted_summary(config: Config, seed: int, interaction: int, x0: np.ndarray) -> dict:
    """The summary of the compiled run of ``config`` from ``x0``: a prediction of foresight
    (``persuasive.safety.foresight``), which both loops hand to ``persuasive.record.setup``."""
    from .policies import policy_params

    s = setup(config, seed, interaction=interaction, x0=x0)
    return run_compiled(s, policy_params(config, kd.AV), policy_params(config, kd.HV))[0] \
        .summary()


def predicted_states(config: Config, seed: int, interaction: int, x0: np.ndarray,
                     stop_av_m: float, stop_hv_m: float):
    """The run :func:`predicted_summary` predicts, up to the first state at which both
    vehicles are at or past ``stop_av_m`` and ``stop_hv_m`` (:func:`run_loop`): its setup
    (:class:`persuasive.record.Setup`) and states ``(steps + 1, 4)``, those of the whole
    run's first states (foresight's fast path, ``persuasive.safety.foresight``)."""
    from .policies import policy_params

    s = setup(config, seed, interaction=interaction, x0=x0)
    arrays, steps = _run_arrays(s, policy_params(config, kd.AV), policy_params(config, kd.HV),
                                False, stop_av_m, stop_hv_m)
    return s, arrays[0][:steps + 1]


def score_states(scenario, states: np.ndarray, dt: float, run_s: float
                 ) -> tuple[bool, bool, float]:
    """Foresight's score (``persuasive.safety.foresight.score``) of a run of ``scenario``
    from its states ``(k + 1, 4)``: the whole run's, or a first part of it that ends with both
    vehicles past their clearing position and the conflict point (foresight's module
    docstring, "Cost"), computed as ``persuasive.record.outcome`` computes those fields."""
    from .record import _first_time
    from .safety import measures
    from .safety.foresight import score
    from .scenarios import first_arrival

    cleared_av = scenario.cleared("av", states[:, 0])
    cleared_hv = scenario.cleared("hv", states[:, 2])
    both = bool(cleared_av[-1] and cleared_hv[-1])
    after = states[1:]
    conflict, _ = first_arrival(scenario.at_conflict_point(after[:, 0]),
                                scenario.at_conflict_point(after[:, 2]))
    stood = measures.standoff(states[:, 0], states[:, 2], cleared_av, cleared_hv, dt)
    return score({"both_cleared": both, "deadlock": not math.isnan(stood),
                  "av_first_through": both and conflict == 1,
                  "av_time_to_clear_s": _first_time(cleared_av[1:], dt)}, run_s)


def predicted_score(config: Config, seed: int, interaction: int, x0: np.ndarray,
                    run_s: float) -> tuple[bool, bool, float]:
    """``score(predicted_summary(config, seed, interaction, x0), run_s)`` from the compiled
    run stopped once both vehicles are past their clearing position and the conflict point
    (:func:`predicted_states`); foresight reads it as ``predicted_summary.score``."""
    from .record import static_setup

    scenario = static_setup(config)[0]  # the run's own (cached): where it may stop
    s, states = predicted_states(config, seed, interaction, x0,
                                 max(scenario.av.clear_s, 0.0), max(scenario.hv.clear_s, 0.0))
    return score_states(s.scenario, states, config.simulation.dt_s, run_s)


#: foresight scores the compiled loop's predictions with the run stopped once decided
#: (``persuasive.safety.foresight.choose_line``)
predicted_summary.score = predicted_score


def run_python(config: Config, seed: int, av=None, hv=None, timed: bool = False):
    """One whole run of the Python loop (:class:`PythonWorld`); returns its
    :class:`~persuasive.simulation.RunRecord`. With the configuration's own kinds it equals
    :func:`persuasive.simulation.simulate` bit for bit."""
    world = PythonWorld(config, seed, av, hv, timed)
    while not world.done:
        world.step()
    return world.record()


def _draws_per_step(policy) -> int:
    if hasattr(policy, "draws_per_step"):
        return int(policy.draws_per_step)
    spec = getattr(policy, "spec", None)
    return spec.draws if spec is not None else 0


def _last_log(policy) -> np.ndarray:
    values = np.asarray(getattr(policy, "last_log", ()), dtype=np.float64)
    return values[:len(policy.log_columns)]
