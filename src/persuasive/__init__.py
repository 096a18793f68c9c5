"""persuasive: persuasive trajectory planning with an adaptive leader-follower game.

A robot (an autonomous vehicle) predicts a human driver's reaction with a leader-follower game
whose roles adapt, and plans with a branch MPC that shapes the human's intention under a chance
constraint on safety (He, Dong, Li, MECC 2025).

The main entry points:

- :class:`Config` — every parameter, validated, the paper's values by default;
- :func:`simulate` — one closed-loop run (the paper's intersection, or another scenario);
- :class:`Planner` — the AV's planner inside your own loop;
- :func:`reproduce` — the paper's Tables 1 and 2.

The method as implemented is described in ``docs/method.md``.
"""

from ._version import __version__
from ._compile import ensure_fresh_cache  # noqa: E402

ensure_fresh_cache()  # before any compiled kernel is loaded (see persuasive._compile)

from .config import Config, ConfigError  # noqa: E402
from .experiments import reproduce  # noqa: E402
from .planner import Plan, Planner  # noqa: E402
from .simulation import RunRecord, simulate  # noqa: E402

__all__ = ["Config", "ConfigError", "Plan", "Planner", "RunRecord", "reproduce", "simulate",
           "__version__"]
