"""Environments: the conflict as a gymnasium environment, the planner in highway-env (issue 13).

- :mod:`~persuasive.envs.conflict`: :class:`ConflictEnv`, one vehicle driven by the agent,
  the other by the package's planner or a human model, over the closed loop of
  :class:`persuasive.world.PythonWorld`. One id per scenario (:data:`ENV_IDS`):
  ``persuasive/Intersection-v0``, ``persuasive/Crossing-v0``, ``persuasive/LeftTurn-v0``,
  ``persuasive/Merge-v0``.
- :mod:`~persuasive.envs.highway`: the planner driving highway-env's ego at its intersection,
  against highway-env's own traffic (``persuasive highway``).

Registration: :func:`register_envs` registers the ids with gymnasium. It is the package's
``gymnasium.envs`` entry point (which gymnasium before 1.0 calls when it is imported) and runs
when this module is imported, so with gymnasium >= 1.0, which no longer reads entry points,
either ``import persuasive.envs`` first or name the module in the id:
``gymnasium.make("persuasive.envs:persuasive/Intersection-v0")``.

Needs the ``gym`` extra (``pip install 'persuasive[gym]'``) and, for highway-env, the
``highway`` extra.
"""

from __future__ import annotations

#: The registered ids, by scenario kind (``[scenario] kind``).
ENV_IDS = {
    "intersection": "persuasive/Intersection-v0",
    "crossing": "persuasive/Crossing-v0",
    "left-turn": "persuasive/LeftTurn-v0",
    "merge": "persuasive/Merge-v0",
}

#: Where the environment class lives (gymnasium imports it when an id is first made).
ENTRY_POINT = "persuasive.envs.conflict:ConflictEnv"


def register_envs() -> None:
    """Register :data:`ENV_IDS` with gymnasium (ids already registered are left alone)."""
    from gymnasium.envs.registration import register, registry

    for scenario, env_id in ENV_IDS.items():
        if env_id not in registry:
            register(id=env_id, entry_point=ENTRY_POINT, kwargs={"scenario": scenario})


def __getattr__(name: str):
    if name == "ConflictEnv":
        from .conflict import ConflictEnv

        return ConflictEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


try:
    register_envs()
except ImportError:  # gymnasium is not installed: nothing to register with
    pass

__all__ = ["ENV_IDS", "ConflictEnv", "register_envs"]
