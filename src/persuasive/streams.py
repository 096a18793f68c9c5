"""The random streams of a run (docs/method.md §7.5): every random number, drawn up front.

The initial state, each agent's uniforms and the world's noise come in one of two layouts
(``Config.streams``): ``legacy``, the reference's single MT19937 stream
(``numpy.random.RandomState(seed)``) in the order of docs/method.md §7.5, used by paper mode so
that the published tables stay exact; ``per-agent``, independent streams from
``numpy.random.SeedSequence(seed).spawn(4)`` (initial state, HV, AV, world noise), so that the
human's draws and the initial state do not depend on which AV drives (what ``compare``
needs). None of the draws depends on the state, so they are drawn up front.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from . import packing as slot
from .config import Config


@dataclass(frozen=True)
class Streams:
    """Every random number of a run, drawn up front."""

    layout: str  #: "legacy" or "per-agent"
    x_av: tuple[float, float]  #: initial (s [m], v [m/s])
    x_hv: tuple[float, float]
    draws_av: np.ndarray  #: (n_steps, k_av) uniforms of the AV's policy
    draws_hv: np.ndarray  #: (n_steps, k_hv) uniforms of the HV's policy
    meas_noise: np.ndarray  #: (n_steps, 4): AV s, v, HV s, v
    accel_noise: np.ndarray  #: (n_steps, 2): AV, HV
    noisy: bool  #: whether any noise is on
    av_rng: Any = None  #: the AV's own generator after its draws (per-agent layout)
    hv_rng: Any = None


#: First entry of the spawn key of a repeated interaction's root seed sequence (see
#: :func:`interaction_seed`).
INTERACTION_KEY = 0x19A


def interaction_seed(seed: int, interaction: int) -> np.random.SeedSequence:
    """The root seed sequence of interaction ``k`` with the human of ``seed``: ``seed`` itself
    for ``k = 0`` (today's run of the seed), else ``SeedSequence(seed, spawn_key=
    (INTERACTION_KEY, k))``, independent of the seed's own streams and of every other
    interaction."""
    if interaction == 0:
        return np.random.SeedSequence(seed)
    return np.random.SeedSequence(seed, spawn_key=(INTERACTION_KEY, int(interaction)))


def draw_streams(config: Config, seed: int, scenario, k_av: int, k_hv: int,
                 interaction: int = 0) -> Streams:
    """The random numbers of a run (see the module docstring for the two layouts).

    Legacy order (one ``RandomState(seed)``): the initial state's uniforms; then per step the
    measurement noise (AV s, v, HV s, v, when enabled), the HV policy's ``k_hv`` uniforms, the
    AV policy's ``k_av``, the acceleration noise (AV, HV, when enabled). Per-agent: the initial
    state from child 0; the HV's uniforms from child 1 and the AV's from child 2, one column
    (all steps) after the other, so that a policy's first column does not depend on how many it
    draws; the noise from child 3, measurement then acceleration.

    ``interaction`` ``k > 0`` (a repeated interaction with the same human, fresh initial state
    and draws): the same layout from :func:`interaction_seed` (the legacy stream seeded with
    its first 32-bit word); ``k = 0`` is the seed's own run.
    """
    sim = config.simulation
    n = sim.n_steps
    layout = config.streams
    kind, w_acc = sim.measurement_noise, sim.accel_noise_mps2
    noisy = kind != "none" or w_acc > 0.0
    widths = (sim.noise_s_m, sim.noise_v_mps) * 2
    meas, accel = np.zeros((n, 4)), np.zeros((n, 2))
    if layout == "legacy":
        rng = np.random.RandomState(
            seed if interaction == 0 else interaction_seed(seed, interaction).generate_state(1))
        x_av, x_hv = scenario.initial_states(rng.random_sample)
        draws = np.zeros((n, k_hv + k_av))
        if not noisy:
            if k_hv + k_av:
                draws[:] = rng.random_sample((n, k_hv + k_av))
        else:
            for k in range(n):
                if kind == "uniform":
                    meas[k] = [-w + 2.0 * w * rng.random_sample() for w in widths]
                elif kind == "gaussian":
                    meas[k] = [w * rng.standard_normal() for w in widths]
                draws[k] = [rng.random_sample() for _ in range(k_hv + k_av)]
                if w_acc > 0.0:
                    accel[k] = [-w_acc + 2.0 * w_acc * rng.random_sample() for _ in range(2)]
        return Streams(layout, x_av, x_hv, draws[:, k_hv:].copy(), draws[:, :k_hv].copy(),
                       meas, accel, noisy)
    init, hv, av, world = (np.random.Generator(np.random.PCG64(s))
                           for s in interaction_seed(seed, interaction).spawn(4))
    x_av, x_hv = scenario.initial_states(init.random)
    draws_hv = np.stack([hv.random(n) for _ in range(k_hv)], axis=1) if k_hv else np.zeros((n, 0))
    draws_av = np.stack([av.random(n) for _ in range(k_av)], axis=1) if k_av else np.zeros((n, 0))
    if kind == "uniform":
        meas[:] = -np.array(widths) + (2.0 * np.array(widths)) * world.random((n, 4))
    elif kind == "gaussian":
        meas[:] = np.array(widths) * world.standard_normal((n, 4))
    if w_acc > 0.0:
        accel[:] = -w_acc + (2.0 * w_acc) * world.random((n, 2))
    return Streams(layout, x_av, x_hv, draws_av, draws_hv, meas, accel, noisy, av, hv)


@njit(cache=True, _nrt=False)
def measure_states(x: np.ndarray, k: int, noisy: bool, meas_noise: np.ndarray,
                   P_av: np.ndarray, P_hv: np.ndarray) -> tuple[float, float, float, float]:
    """The measured ``(s_av, v_av, s_hv, v_hv)`` of the true state ``x`` at step ``k``."""
    ms_av, mv_av, ms_hv, mv_hv = x[0], x[1], x[2], x[3]
    if noisy:
        ms_av += meas_noise[k, 0]
        mv_av = min(max(mv_av + meas_noise[k, 1], P_av[slot.V_MIN]), P_av[slot.V_MAX])
        ms_hv += meas_noise[k, 2]
        mv_hv = min(max(mv_hv + meas_noise[k, 3], P_hv[slot.V_MIN]), P_hv[slot.V_MAX])
    return ms_av, mv_av, ms_hv, mv_hv


__all__ = ["INTERACTION_KEY", "Streams", "draw_streams", "interaction_seed", "measure_states"]
