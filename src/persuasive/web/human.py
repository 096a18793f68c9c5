"""The person at the browser as the HV's policy (:class:`LiveHuman`), and their raw input.

The page sends the raw state of its controls (:class:`HumanInput`): the arrow keys or the
on-screen pedals (``up``, ``down``) and a gamepad value (``axis`` in [-1, 1]: > 0 throttle,
< 0 brake). :func:`command_of` maps it to an acceleration: braking wins over throttle
(``down`` gives ``u_min``), then ``up`` gives ``u_max``, then the gamepad's axis scales
``u_max`` or ``|u_min|``; nothing pressed is coasting (0). The result is bounded to the HV's
``[u_min, u_max]`` (``Config.vehicle_of("hv")``). A late or missing message keeps the last
input: the policy reads whatever input is current when the server's clock ticks.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

#: Where an input came from (the page says which control changed last).
INPUT_SOURCES = ("none", "keyboard", "touch", "gamepad")


@dataclass(frozen=True)
class HumanInput:
    """The raw state of the person's controls, as last received."""

    up: bool = False  #: throttle held (ArrowUp or the Go button)
    down: bool = False  #: brake held (ArrowDown or the Brake button)
    axis: float = math.nan  #: gamepad value in [-1, 1] (> 0 throttle), NaN without a gamepad
    source: str = "none"  #: one of :data:`INPUT_SOURCES`
    received_s: float = math.nan  #: ``time.monotonic()`` when it arrived [s]


def command_of(inp: HumanInput, u_min: float, u_max: float) -> float:
    """The acceleration [m/s^2] an input asks for, within ``[u_min, u_max]``."""
    if inp.down:
        a = u_min
    elif inp.up:
        a = u_max
    elif math.isfinite(inp.axis):
        a = inp.axis * u_max if inp.axis >= 0.0 else -inp.axis * u_min
    else:
        a = 0.0
    return float(min(max(a, u_min), u_max))


class LiveHuman:
    """The HV's policy in the browser: the acceleration the person's current input asks for.

    Follows the Python policy protocol (:class:`persuasive.policies.Policy`): no log columns of
    its own and no game; it draws no random numbers. Per step it keeps the input it used
    (:meth:`columns`), which the trial adds to the run's log.
    """

    log_columns: tuple[str, ...] = ()
    needs_game = False
    draws_per_step = 0

    def __init__(self) -> None:
        self.input = HumanInput()
        self.u_min, self.u_max = -math.inf, math.inf
        self._alloc(0)

    def _alloc(self, n: int) -> None:
        self.key_up = np.zeros(n, bool)
        self.key_down = np.zeros(n, bool)
        self.axis = np.full(n, np.nan)
        self.source = np.full(n, "none", dtype=object)
        self.command = np.full(n, np.nan)
        self.age_ms = np.full(n, np.nan)

    def reset(self, context, rng=None) -> None:
        veh = context.config.vehicle_of("hv")
        self.u_min, self.u_max = veh.u_min_mps2, veh.u_max_mps2
        self._alloc(context.n_steps)

    def act(self, observation) -> float:
        k, inp = observation.step, self.input
        a = command_of(inp, self.u_min, self.u_max)
        self.key_up[k], self.key_down[k], self.axis[k] = inp.up, inp.down, inp.axis
        self.source[k], self.command[k] = inp.source, a
        self.age_ms[k] = (time.monotonic() - inp.received_s) * 1e3
        return a

    def columns(self, n: int) -> dict[str, np.ndarray]:
        """The inputs of the first ``n`` steps as log columns (``hv_key_up``, ...)."""
        return {"hv_key_up": self.key_up[:n].copy(), "hv_key_down": self.key_down[:n].copy(),
                "hv_axis": self.axis[:n].copy(), "hv_input_source": self.source[:n].astype(str),
                "hv_command_mps2": self.command[:n].copy(),
                "hv_command_age_ms": self.age_ms[:n].copy()}


__all__ = ["HumanInput", "INPUT_SOURCES", "LiveHuman", "command_of"]
