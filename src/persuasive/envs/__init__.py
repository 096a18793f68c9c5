"""Environments: the conflict as a gymnasium environment, the planner in highway-env (issue 13).

- :mod:`~persuasive.envs.conflict`: :class:`ConflictEnv`, one vehicle driven by the agent,
  the other by the package's planner or a human model, over the closed loop of
  :class:`persuasive.world.PythonWorld`. One id per scenario of the registry
  (:data:`persuasive.scenarios.SCENARIOS`; :data:`ENV_IDS`), its kind in CamelCase:
  ``persuasive/Intersection-v0``, ``persuasive/Crossing-v0``, ``persuasive/LeftTurn-v0``,
  ``persuasive/Merge-v0``; a new scenario gets its id with no edit here.
- :mod:`~persuasive.envs.junction`: the four-way junction with N vehicles
  (``persuasive.many``): a PettingZoo ``ParallelEnv`` (any vehicles are agents) and the
  gymnasium id ``persuasive/Junction-v0`` (one agent, ``n_vehicles`` and ``variant``).
- :mod:`~persuasive.envs.highway`: the planner driving highway-env's ego at its intersection,
  against highway-env's own traffic (``persuasive highway``).

Registration: :func:`register_envs` registers the ids with gymnasium. It is the package's
``gymnasium.envs`` entry point (which gymnasium before 1.0 calls when it is imported) and runs
when this module is imported, so with gymnasium >= 1.0, which no longer reads entry points,
either ``import persuasive.envs`` first or name the module in the id:
``gymnasium.make("persuasive.envs:persuasive/Intersection-v0")``.

Needs the ``gym`` extra (``pip install -e '.[gym]'`` in the checkout) and, for highway-env, the
``highway`` extra.
"""

from __future__ import annotations

from ..scenarios import SCENARIOS


def env_id(scenario: str) -> str:
    """The gymnasium id of a scenario kind: ``"left-turn"`` -> ``"persuasive/LeftTurn-v0"``."""
    return "persuasive/" + "".join(part.capitalize() for part in scenario.split("-")) + "-v0"


#: The registered ids, by scenario kind (``[scenario] kind``), in the registry's order.
ENV_IDS = {scenario: env_id(scenario) for scenario in SCENARIOS}

#: Where the environment class lives (gymnasium imports it when an id is first made).
ENTRY_POINT = "persuasive.envs.conflict:ConflictEnv"
#: The four-way junction with N vehicles, one of them the agent (:mod:`.junction`; its
#: PettingZoo ``ParallelEnv`` is :class:`persuasive.envs.junction.JunctionParallelEnv`).
JUNCTION_ID = "persuasive/Junction-v0"


def register_envs() -> None:
    """Register :data:`ENV_IDS` with gymnasium (ids already registered are left alone)."""
    from gymnasium.envs.registration import register, registry

    for scenario, env_id in ENV_IDS.items():
        if env_id not in registry:
            register(id=env_id, entry_point=ENTRY_POINT, kwargs={"scenario": scenario})
    if JUNCTION_ID not in registry:
        register(id=JUNCTION_ID, entry_point="persuasive.envs.junction:JunctionEnv")


def __getattr__(name: str):
    if name == "ConflictEnv":
        from .conflict import ConflictEnv

        return ConflictEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


try:
    register_envs()
except ImportError:  # gymnasium is not installed: nothing to register with
    pass

__all__ = ["ENV_IDS", "JUNCTION_ID", "ConflictEnv", "env_id", "register_envs"]
