"""The two-vehicle conflict as a gymnasium environment: :class:`ConflictEnv` (issue 13).

The agent drives one vehicle's longitudinal acceleration; the other vehicle is driven by one of
the package's policies (the persuasive planner by default, or a human model). The closed loop
is :class:`persuasive.world.PythonWorld`, the same loop as :func:`persuasive.simulation.simulate`
(bit for bit): the controlled vehicle's policy (:class:`ActionPolicy`) returns the action given
to :meth:`ConflictEnv.step`, and a seed drives the run's random streams exactly as
``simulate(config, seed)`` does.

Decisions are simultaneous, as in the loop: at step ``k`` both vehicles decide on the states
measured at ``x_k``, neither sees the other's action of that step. The environment therefore
lets the other vehicle decide as soon as ``x_k`` is measured (:class:`DecidedPolicy`), before
the agent's action arrives, and reports what a planner needs of that decision in ``info``
(the human's role after its decision, which the persuasive planner reads under quirk Q3).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ..config import AV_KIND_ALIASES, AV_KINDS, HV_KINDS, Config, ConfigError
from ..policies import CompiledPolicy, Observation
from ..policies import kinds as kd
from ..policies import kind_of
from ..roles import LEADER
from ..world import W_AV_A, W_HV_A, PythonWorld, measure_states

#: The vehicle the agent may drive.
CONTROLLED = ("hv", "av")
#: Other-vehicle kinds whose observation can carry a role belief (state slot 0: P(HV = L)).
BELIEF_KINDS = ("persuasive", "passive")
#: Side of the rendered frame [in] and its resolution [dots/in]: frames are 400 x 400 pixels.
RENDER_SIZE_IN, RENDER_DPI = 4.0, 100
#: Margin added to the position bounds for Gaussian measurement noise [standard deviations].
GAUSSIAN_MARGIN = 10.0


class ActionPolicy:
    """The agent's vehicle: :meth:`act` returns the action last given to
    :meth:`ConflictEnv.step` (as ``float64``).

    It declares as many uniforms per step (``draws_per_step``) as the configured kind of its
    vehicle draws, and ignores them, so that the other vehicle's draws and the world's noise
    are those of ``simulate(config, seed)``.
    """

    log_columns: tuple[str, ...] = ()
    needs_game = False
    last_log: tuple[float, ...] = ()

    def __init__(self, draws_per_step: int):
        self.draws_per_step = draws_per_step
        self.action = math.nan

    def reset(self, context, rng=None) -> None:
        self.action = math.nan

    def act(self, observation: Observation) -> float:
        return self.action


class DecidedPolicy:
    """A policy that decides when the state is measured (:meth:`decide`) and hands that
    decision to the loop when the loop asks (:meth:`act`).

    Both vehicles decide on the same measured state, so deciding before the agent's action
    arrives changes nothing (the loop asks the human first, then the AV, and neither reads the
    other's action of that step). Everything else (log columns, log row, role, draws, whether
    the loop must compute the game) is the wrapped policy's.
    """

    def __init__(self, policy: CompiledPolicy):
        self.policy = policy
        self.log_columns = policy.log_columns
        self.needs_game = policy.needs_game
        self.spec = policy.spec
        self._pending: tuple[int, float] | None = None

    def reset(self, context, rng=None) -> None:
        self.policy.reset(context, rng)
        self._pending = None

    @property
    def last_log(self):
        return self.policy.last_log

    @property
    def role(self) -> int:
        return self.policy.role

    def decide(self, observation: Observation) -> float:
        accel = float(self.policy.act(observation))
        self._pending = (observation.step, accel)
        return accel

    def act(self, observation: Observation) -> float:
        if self._pending is None or self._pending[0] != observation.step:
            raise RuntimeError(f"no decision for step {observation.step}")
        return self._pending[1]


def _as_config(config: Config | dict | str | Path | None) -> Config:
    if config is None:  # Planner()'s default: corrected mode, the worst-case shield on
        return Config(mode="corrected")
    if isinstance(config, Config):
        return config
    if isinstance(config, dict):
        return Config.from_dict(config)
    if isinstance(config, (str, Path)):
        return Config.from_toml(config)
    raise ConfigError(f"config = {config!r} is not a Config, a dict or a TOML file name")


class ConflictEnv(gym.Env):
    """Two vehicles, one conflict (``persuasive.scenarios``); the agent drives one of them.

    Registered as ``persuasive/Intersection-v0``, ``persuasive/Crossing-v0``,
    ``persuasive/LeftTurn-v0`` and ``persuasive/Merge-v0`` (one per scenario kind).

    Parameters
    ----------
    config : Config, dict or str, optional
        All parameters (a :class:`~persuasive.config.Config`, a dict as in a TOML file, or a
        TOML file name); default ``Config(mode="corrected")``, as :class:`~persuasive.Planner`:
        the worst-case shield filters the AV's accelerations, the planner's or the agent's
        (``{"mode": "paper"}`` runs the paper's unshielded closed loop, as ``simulate``'s
        default). The registered id's scenario replaces ``scenario.kind``.
    scenario : str, optional
        Scenario kind (set by the registered id).
    controlled : {"hv", "av"}
        The vehicle the agent drives; default the human-driven one, the AV being the
        configured planner (``av.kind``, default the persuasive branch MPC). With ``"av"`` the
        other is a human model (``hv.kind``, default the paper's adaptive-role LFG human).
    other_kind : str, optional
        The other vehicle's kind, replacing ``av.kind`` (``controlled="hv"``) or ``hv.kind``
        (``controlled="av"``) in the configuration (:attr:`config` is the result).
    observe_belief : bool
        Append the other vehicle's role belief to the observation; only for an AV planner that
        keeps one (``persuasive``, ``passive``).
    render_mode : {None, "rgb_array"}
        ``"rgb_array"``: :meth:`render` returns the top view as RGB ``(400, 400, 3)`` uint8.

    Spaces
    ------
    Action: ``Box([u_min], [u_max])``, float32, the controlled vehicle's acceleration
    [m/s^2]. The action is read as float64 (a float64 array is used unrounded) and clipped
    to the bounds.

    Observation: float32 ``[s_AV, v_AV, s_HV, v_HV]`` (+ ``[P(HV = leader)]`` with
    ``observe_belief``), the states measured at the current step (equal to the true states
    without measurement noise; the true state once the run has ended). ``s`` [m] is the
    position along the vehicle's own path, negative before the conflict point; ``v`` [m/s].
    Bounds: speeds ``[v_min, v_max]`` of each vehicle (speeds saturate, measured ones are
    clipped); positions from ``s0 - max_init_draws * s0_halfwidth`` (the lowest start the
    initial-state draw can reach) to ``zone_lo + v_max * n_steps * dt`` (a start lies before
    the conflict zone, then at most ``v_max`` for the whole run), widened by the measurement
    noise (its half-width, or 10 standard deviations when Gaussian; a measurement beyond is
    clipped in the observation only); the belief ``[0, 1]``. The belief is the AV's after
    its update at this step's measurement (its decision for the step is already made).

    Reward
    ------
    The paper's step reward of the controlled vehicle (docs/method.md §3), undiscounted, for
    the step from ``x_k`` to ``x_{k+1}``::

        r_k = (s_{k+1} - s_0) - w_c c_{k+1} - w_u |u_k|,
        c_{k+1} = [d_{k+1} < min_dist] (1 + v_{k+1}),

    with ``s_0`` the controlled vehicle's position at reset, ``s, v`` its true position and
    speed, ``u_k`` the acceleration it applied at step ``k`` (the clipped action, plus the
    acceleration noise when configured), ``d`` the distance between the vehicles as the
    scenario measures it (:meth:`~persuasive.scenarios.Scenario.distance`:
    ``sqrt(s_AV^2 + s_HV^2)`` at the paper's intersection, between the centres otherwise),
    ``min_dist`` the pair's safety distance (7.5 m) and ``w_c``, ``w_u`` from
    ``config.reward`` (100, 0.1). ``info`` holds the three terms.

    Episode end
    -----------
    Terminated when the footprints overlap (:meth:`~persuasive.scenarios.Scenario.collides`)
    or when both vehicles have cleared the conflict (``cleared``); truncated after
    ``simulation.n_steps`` steps (61). ``reset(seed=s)`` starts the run that ``simulate(config,
    s)`` runs (same initial state, same random streams); without a seed, the run's seed is
    drawn from :attr:`np_random`. Seeds are integers in ``[0, 2^32 - 1]``.

    Info
    ----
    ``step``, ``t_s``; ``av_state``, ``hv_state``: the measured ``(s, v)`` at this step as
    float64 arrays (what the policies decide on; hand them to :class:`~persuasive.Planner`);
    ``true_state`` ``(4,)``; ``human_role``: the human's role after its decision at this step
    (``"leader"``/``"follower"``, ``None`` for a human without a role or for the agent's HV);
    ``distance_m``, ``collision``, ``av_cleared``, ``hv_cleared``; after a step also
    ``reward_progress_m``, ``reward_collision``, ``reward_effort`` (the three terms, each as
    it enters ``r_k`` with its sign removed) and ``accel_mps2`` (the applied ``u_k``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: Config | dict | str | Path | None = None, *,
                 scenario: str | None = None, controlled: str = "hv",
                 other_kind: str | None = None, observe_belief: bool = False,
                 render_mode: str | None = None):
        if controlled not in CONTROLLED:
            raise ConfigError(f"controlled = {controlled!r} is out of range; allowed: "
                              f"{' | '.join(CONTROLLED)}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(f"render_mode = {render_mode!r} is out of range; allowed: "
                              f"None | {' | '.join(self.metadata['render_modes'])}")
        config = _as_config(config)
        other = "av" if controlled == "hv" else "hv"
        overrides: dict[str, Any] = {}
        if scenario is not None:
            overrides["scenario.kind"] = scenario
        if other_kind is not None:
            allowed = (*AV_KINDS, *AV_KIND_ALIASES) if other == "av" else HV_KINDS
            if other_kind not in allowed:
                raise ConfigError(f"other_kind = {other_kind!r} is out of range; allowed: "
                                  f"{' | '.join(allowed)}")
            overrides[f"{other}.kind"] = other_kind
        self.config = config.with_overrides(overrides) if overrides else config
        self.controlled = controlled
        self.other = other
        self._side = kd.HV if controlled == "hv" else kd.AV
        self._col = 2 if controlled == "hv" else 0
        other_spec = kind_of(self.config, kd.AV if other == "av" else kd.HV)
        if observe_belief and other_spec.name not in BELIEF_KINDS:
            raise ConfigError(f"observe_belief needs the other vehicle to keep a role belief "
                              f"({' | '.join(BELIEF_KINDS)} AV); it is a {other_spec.name!r} "
                              f"{other.upper()}")
        self.observe_belief = bool(observe_belief)
        self.render_mode = render_mode
        sim = self.config.simulation
        self.metadata = {**self.metadata, "render_fps": max(1, round(1.0 / sim.dt_s))}
        from ..record import static_setup

        self.scenario = static_setup(self.config)[0]
        veh = self.config.vehicle_of(controlled)
        self.action_space = spaces.Box(np.array([veh.u_min_mps2], np.float32),
                                       np.array([veh.u_max_mps2], np.float32), dtype=np.float32)
        low, high = self._bounds()
        self.observation_space = spaces.Box(low.astype(np.float32), high.astype(np.float32),
                                            dtype=np.float32)
        self._obs_low, self._obs_high = low, high
        self.world: PythonWorld | None = None  #: the closed loop of the current run
        self.run_seed: int | None = None
        self._figure = None

    # -- spaces ----------------------------------------------------------------------------

    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Observation bounds (float64), as the class docstring states them."""
        c, sc, sim = self.config, self.config.scenario, self.config.simulation
        if sim.measurement_noise == "uniform":
            margin_s = sim.noise_s_m
        elif sim.measurement_noise == "gaussian":
            margin_s = GAUSSIAN_MARGIN * sim.noise_s_m
        else:
            margin_s = 0.0
        low, high = [], []
        for who in ("av", "hv"):
            veh = c.vehicle_of(who)
            s0 = self.scenario.nominal_s0(who)
            lo = s0 - sc.max_init_draws * getattr(sc, f"{who}_s0_halfwidth_m")
            hi = getattr(self.scenario, who).zone[0] + veh.v_max_mps * sim.n_steps * sim.dt_s
            low += [lo - margin_s, veh.v_min_mps]
            high += [hi + margin_s, veh.v_max_mps]
        if self.observe_belief:
            low.append(0.0)
            high.append(1.0)
        return np.array(low), np.array(high)

    # -- the episode -----------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start the run of ``seed`` (see the class docstring); returns ``(observation,
        info)``."""
        super().reset(seed=seed)
        run_seed = seed if seed is not None else int(self.np_random.integers(2**32))
        draws = kind_of(self.config, self._side).draws
        self._agent = ActionPolicy(draws)
        other_side = kd.AV if self.other == "av" else kd.HV
        self._decided = DecidedPolicy(CompiledPolicy(
            (self.config.av if self.other == "av" else self.config.hv).kind, other_side))
        av, hv = (self._decided, self._agent) if self.other == "av" else \
            (self._agent, self._decided)
        self.world = PythonWorld(self.config, run_seed, av=av, hv=hv)
        self.run_seed = run_seed  # the run simulate(config, run_seed) runs
        self._need_game = bool(self._decided.needs_game)
        self._s0 = float(self.world.x[self._col])
        self._measure_and_decide()
        return self._observation(), self._info()

    def _measure_and_decide(self) -> None:
        """Measure ``x_k`` as the loop will, and let the other vehicle decide on it."""
        w = self.world
        if w.done:
            self._measured = w.x.copy()
            return
        s, st, k = w.setup, w.setup.streams, w.k
        m = measure_states(w.x, k, st.noisy, st.meas_noise, s.P_av, s.P_hv)
        self._measured = np.array(m, dtype=np.float64)
        ms_av, mv_av, ms_hv, mv_hv = m
        # The loop asks the game cache again for the same state and gets this very view.
        game = w.games((ms_av, mv_av), (ms_hv, mv_hv)) if self._need_game else None
        self._decided.decide(Observation(k, k * w.dt, (ms_av, mv_av), (ms_hv, mv_hv), game))

    def step(self, action):
        """Apply ``action`` to the controlled vehicle for one step; returns ``(observation,
        reward, terminated, truncated, info)``."""
        w = self.world
        if w is None:
            raise RuntimeError("call reset() before step()")
        if w.done:
            raise RuntimeError(f"the run has ended after {w.n_steps} steps "
                               "(simulation.n_steps); call reset()")
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.size != 1 or not np.isfinite(a[0]):
            raise ValueError(f"action = {action!r} is not one finite acceleration [m/s^2]")
        veh = self.config.vehicle_of(self.controlled)
        self._agent.action = min(max(float(a[0]), veh.u_min_mps2), veh.u_max_mps2)
        k = w.k
        x = w.step()
        s, v = float(x[self._col]), float(x[self._col + 1])
        u = float(w.world_log[k, W_HV_A if self.controlled == "hv" else W_AV_A])
        sc, r = self.scenario, self.config.reward
        d = float(sc.distance(x[0], x[2]))
        coll = (1.0 + v) if d < sc.min_dist_m else 0.0
        progress, effort = s - self._s0, abs(u)
        reward = progress - r.w_c * coll - r.w_u * effort
        collision = bool(sc.collides(x[0], x[2]))
        cleared = bool(sc.cleared("av", x[0])) and bool(sc.cleared("hv", x[2]))
        terminated = collision or cleared
        truncated = w.done and not terminated
        self._measure_and_decide()
        info = self._info()
        info.update(reward_progress_m=progress, reward_collision=coll, reward_effort=effort,
                    accel_mps2=u)
        return self._observation(), float(reward), terminated, truncated, info

    def _observation(self) -> np.ndarray:
        obs = self._measured
        if self.observe_belief:
            obs = np.append(obs, self._decided.policy.state[0])
        return np.clip(obs, self._obs_low, self._obs_high).astype(np.float32)

    def _info(self) -> dict[str, Any]:
        w, m, x = self.world, self._measured, self.world.x
        sc = self.scenario
        role = None
        if self.other == "hv" and self._decided.spec.has_role and not w.done:
            role = "leader" if self._decided.role == LEADER else "follower"
        return {
            "step": w.k,
            "t_s": w.k * w.dt,
            "av_state": m[0:2].copy(),
            "hv_state": m[2:4].copy(),
            "true_state": x.copy(),
            "human_role": role,
            "distance_m": float(sc.distance(x[0], x[2])),
            "collision": bool(sc.collides(x[0], x[2])),
            "av_cleared": bool(sc.cleared("av", x[0])),
            "hv_cleared": bool(sc.cleared("hv", x[2])),
        }

    def record(self):
        """The :class:`~persuasive.simulation.RunRecord` of the steps taken so far (over all
        ``n_steps`` it equals ``simulate(config, seed)`` when the agent's actions are the
        configured policy's)."""
        if self.world is None:
            raise RuntimeError("call reset() first")
        return self.world.record()

    # -- rendering -------------------------------------------------------------------------

    def render(self):
        """The top view at the current state (``render_mode="rgb_array"``): RGB ``(400, 400,
        3)`` uint8, drawn as the package's figures (``persuasive.plots.topview``)."""
        if self.render_mode is None:
            gym.logger.warn("render() needs render_mode='rgb_array' at construction")
            return None
        if self.world is None:
            raise RuntimeError("call reset() before render()")
        from ..plots.frame import render_frame

        if self._figure is None:
            from ..plots.frame import new_frame_figure

            self._figure = new_frame_figure(RENDER_SIZE_IN, RENDER_DPI)
        return render_frame(self._figure, self.world, self.controlled)

    def close(self) -> None:
        self._figure = None
        super().close()
