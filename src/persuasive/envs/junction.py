"""The four-way junction as a PettingZoo ``ParallelEnv`` and a gymnasium environment
(docs/guide/junction.md).

:class:`JunctionParallelEnv`: any vehicles of a junction run (``persuasive.many``) are agents,
named ``vehicle_<i>`` (``vehicle_0`` is the AV); the others keep their built-in policies (the
AV's adapter-style planner, the humans' pair games). Each agent's action is its acceleration
[m/s^2] (a ``Box`` of shape ``(1,)`` within its limits); with ``shield=True`` (the default) it
goes through the shield over the agent's conflicts, as the AV's does. Seeded like gymnasium:
``reset(seed=s)`` draws run ``s``'s arrivals and streams; ``reset()`` without a seed draws a
new seed from the environment's own generator (itself seeded by the first seeded reset).

Observation of an agent (``float32``, shape ``(4 + 4 * K,)``, ``K =`` :data:`N_NEAREST`): its
distance to its stop line [m] (negative before it), its speed [m/s], its distance to leaving
the box [m] and its acceleration limit ratio ``u / u_max`` of the last step; then for its
``K`` nearest conflicts (by its own distance to the conflict point): its and the other's
position relative to the conflict point [m], the other's speed [m/s] and the kind (1 follow,
2 merge, 3 crossing; 0 and zeros: no conflict).

Reward per step: the distance driven over ``v_max * dt`` (1 at full speed), less
:data:`COLLISION_PENALTY` in the step the agent collides. An agent terminates when it leaves
the map or crashes (an agent that has not arrived yet, with Poisson arrivals, waits: its
actions are ignored until it is on the road); every agent is truncated when the run's duration has passed (or the AV
crashed).

:class:`JunctionEnv` is the gymnasium single-agent view: one vehicle (the AV by default) is
the agent, ``n_vehicles`` and the junction's variant are its parameters (id
``persuasive/Junction-v0``).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from ..config import Config, ConfigError
from ..envs.external import CROSSING, FOLLOW, MERGE
from ..many.junction import JunctionSpec
from ..many.world import ACTIVE, CRASHED, DONE, JunctionWorld

#: Conflicts in an observation.
N_NEAREST = 4
#: Subtracted from the reward in the step an agent collides.
COLLISION_PENALTY = 100.0
_KIND_CODE = {FOLLOW: 1.0, MERGE: 2.0, CROSSING: 3.0}


def _spec(spec: JunctionSpec | dict | None, variant: str | None, n_vehicles: int | None
          ) -> JunctionSpec:
    if isinstance(spec, JunctionSpec):
        base = spec if n_vehicles is None else spec.with_(n_vehicles=n_vehicles)
        return base
    fields = dict(spec or {})
    if n_vehicles is not None:
        fields["n_vehicles"] = n_vehicles
    return JunctionSpec.of(variant, **fields)


def _agent_ids(agents, n: int) -> list[int]:
    if agents == "all":
        return list(range(n))
    out = []
    for a in agents:
        i = int(a.rsplit("_", 1)[1]) if isinstance(a, str) else int(a)
        if not 0 <= i < n:
            raise ConfigError(f"agents has vehicle {a!r}; allowed: vehicle_0 .. "
                              f"vehicle_{n - 1} (n_vehicles = {n}) or 'all'")
        out.append(i)
    if not out:
        raise ConfigError("agents is empty; allowed: at least one vehicle, or 'all'")
    return sorted(set(out))


try:  # the multi extra; without it the class works alone, with the same protocol
    from pettingzoo import ParallelEnv as _ParallelBase
except ImportError:
    _ParallelBase = object


class JunctionParallelEnv(_ParallelBase):
    """PettingZoo ``ParallelEnv`` over the junction (module docstring).

    ``config``: the vehicles, the AV's planner and shield (default corrected mode); ``spec``
    (a :class:`~persuasive.many.junction.JunctionSpec` or its fields) and ``variant``,
    ``n_vehicles`` over it; ``agents``: vehicle indices or names, or ``"all"``;
    ``shield``: filter the agents' actions (default True).
    """

    metadata = {"name": "persuasive_junction_v0", "render_modes": ["rgb_array"],
                "is_parallelizable": True}

    def __init__(self, config: Config | None = None, spec: JunctionSpec | dict | None = None,
                 *, variant: str | None = None, n_vehicles: int | None = None,
                 agents=("vehicle_0",), shield: bool = True, render_mode: str | None = None):
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode = {render_mode!r} is out of range; allowed: "
                              "rgb_array | None")
        self.config = config if config is not None else Config(mode="corrected")
        self.spec = _spec(spec, variant, n_vehicles)
        self._ids = _agent_ids(agents, self.spec.n_vehicles)
        self.possible_agents = [f"vehicle_{i}" for i in self._ids]
        self.agents: list[str] = []
        self.shield = bool(shield)
        self.render_mode = render_mode
        self.world: JunctionWorld | None = None
        self._rng = np.random.Generator(np.random.PCG64())
        self._last = {}

    # PettingZoo reads these as methods with an lru_cache (the spaces never change)
    @functools.lru_cache(maxsize=None)
    def observation_space(self, agent: str):
        from gymnasium import spaces

        return spaces.Box(-np.inf, np.inf, shape=(4 + 4 * N_NEAREST,), dtype=np.float32)

    @functools.lru_cache(maxsize=None)
    def action_space(self, agent: str):
        from gymnasium import spaces

        who = "av" if agent == "vehicle_0" else "hv"
        v = self.config.vehicle_of(who)
        return spaces.Box(np.float32(v.u_min_mps2), np.float32(v.u_max_mps2), shape=(1,),
                          dtype=np.float32)

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.Generator(np.random.PCG64(seed))
            run_seed = int(seed)
        else:
            run_seed = int(self._rng.integers(0, 2**31 - 1))
        self.world = JunctionWorld(self.config, self.spec, run_seed)
        self.agents = list(self.possible_agents)
        self._last = {a: 0.0 for a in self.agents}
        return ({a: self._observe(int(a.rsplit("_", 1)[1])) for a in self.agents},
                {a: {"seed": run_seed} for a in self.agents})

    def _observe(self, i: int) -> np.ndarray:
        w = self.world
        r = w.routes[i]
        lim = w.limits[i]
        s = float(w.s[i])
        obs = np.zeros(4 + 4 * N_NEAREST, np.float32)
        obs[0] = s - r.entry_m
        obs[1] = float(w.v[i])
        obs[2] = w.through_m(i) - s
        obs[3] = self._last.get(f"vehicle_{i}", 0.0) / lim.u_max_mps2
        if w.status[i] != ACTIVE:
            return obs
        conflicts = sorted(w.conflicts_of(i), key=lambda c: abs(c.ego_s_m))[:N_NEAREST]
        for n, c in enumerate(conflicts):
            obs[4 + 4 * n: 8 + 4 * n] = (c.ego_s_m, c.other_s_m, c.other_v_mps,
                                         _KIND_CODE[c.kind])
        return obs

    def step(self, actions: dict[str, Any]):
        w = self.world
        if w is None:
            raise RuntimeError("call reset() before step()")
        acts = {}
        for a in self.agents:
            if a not in actions:
                raise ConfigError(f"actions has no action for the live agent {a!r}")
            acts[int(a.rsplit("_", 1)[1])] = float(np.asarray(actions[a], float).reshape(-1)[0])
        s_before = w.s.copy()
        info_step = w.step(acts, shield=self.shield)
        hit = {v for i, j, _ in info_step.collisions for v in (i, j)}
        obs, rew, term, trunc, infos = {}, {}, {}, {}, {}
        for a in self.agents:
            i = int(a.rsplit("_", 1)[1])
            self._last[a] = float(w.a[i])
            lim = w.limits[i]
            rew[a] = float((w.s[i] - s_before[i]) / (lim.v_max_mps * w.dt)) - (
                COLLISION_PENALTY if i in hit else 0.0)
            term[a] = bool(w.status[i] in (DONE, CRASHED) or i in hit)
            trunc[a] = bool(info_step.done and not term[a])
            obs[a] = self._observe(i)
            infos[a] = {"accel_mps2": float(w.a[i]), "collided": i in hit,
                        "crashed": bool(w.status[i] == CRASHED),
                        "verdict": info_step.verdict if i == 0 else None}
        self.agents = [a for a in self.agents if not (term[a] or trunc[a])]
        return obs, rew, term, trunc, infos

    def state(self) -> np.ndarray:
        """Every vehicle's ``(s, v)`` along its route, and its status, ``(n, 3)``."""
        w = self.world
        return np.column_stack([w.s, w.v, w.status]).astype(np.float32)

    def render(self):
        if self.render_mode != "rgb_array" or self.world is None:
            return None
        from ..plots.junction import topview_figure

        fig = topview_figure(self.world)
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        self.world = None


def parallel_env(**kwargs) -> JunctionParallelEnv:
    """The PettingZoo convention's constructor."""
    return JunctionParallelEnv(**kwargs)


try:
    import gymnasium as _gym
except ImportError:  # the gym extra is not installed
    _gym = None

if _gym is not None:
    class JunctionEnv(_gym.Env):
        """The junction with one agent (module docstring): ``agent`` (default 0, the AV),
        ``n_vehicles``, ``variant``, ``spec``, ``config``, ``shield`` as
        :class:`JunctionParallelEnv`."""

        metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

        def __init__(self, config: Config | None = None, spec=None, *, variant=None,
                      n_vehicles: int | None = None, agent: int = 0, shield: bool = True,
                      render_mode: str | None = None):
            self._env = JunctionParallelEnv(config, spec, variant=variant,
                                            n_vehicles=n_vehicles, agents=(agent,),
                                            shield=shield, render_mode=render_mode)
            self._agent = self._env.possible_agents[0]
            self.observation_space = self._env.observation_space(self._agent)
            self.action_space = self._env.action_space(self._agent)
            self.render_mode = render_mode

        def reset(self, *, seed: int | None = None, options: dict | None = None):
            super().reset(seed=seed)
            if seed is None:
                seed = int(self.np_random.integers(0, 2**31 - 1))
            obs, infos = self._env.reset(seed=seed, options=options)
            return obs[self._agent], infos[self._agent]

        def step(self, action):
            obs, rew, term, trunc, infos = self._env.step({self._agent: action})
            a = self._agent
            return obs[a], rew[a], term[a], trunc[a], infos[a]

        def render(self):
            return self._env.render()

        @property
        def world(self) -> JunctionWorld | None:
            return self._env.world


__all__ = ["COLLISION_PENALTY", "JunctionEnv", "JunctionParallelEnv", "N_NEAREST",
           "parallel_env"]
