"""A falsifier for the shield: a search for the bounded human that comes closest to the AV
(docs/method.md §12.2).

Random humans rarely find the edge of a guarantee; a steered search does. :func:`falsify` is a
cross-entropy search over piecewise-constant human accelerations within the human's limits,
with a fixed budget (``samples * rounds`` closed-loop runs): each round draws accelerations from
a Gaussian per piece (clipped to the limits), runs the compiled closed loop against a human that
replays them (:func:`run_against`), keeps the ``elite`` that came closest
(:func:`closest_approach`) and refits the Gaussian to them. It returns the smallest footprint
gap it found: 0 means a human touched the AV (a collision the AV caused, since rear-ends the
human is at fault for, after a fair cut-in in a shared lane, are left out: docs/method.md §12.10).
"""

from __future__ import annotations

import math

import numpy as np

from .. import packing as slot
from ..config import Config
from ..policies import kinds as kd
from ..policies import policy_params
from ..record import W_AV_A, W_HV_A, WORLD_LOG, setup
from . import measures


def run_against(config: Config, accels: np.ndarray, seed: int = 1):
    """The compiled closed loop of ``config``'s AV (its shield included) against a human that
    replays ``accels`` (one per step, within its limits), from seed ``seed``'s initial state:
    ``(scenario, states (n_steps + 1, 4), world log)``."""
    from ..world import predicted_summary, run_loop

    s = setup(config, seed, None, 0, predict=predicted_summary)  # (foresight, if in force)
    n = config.simulation.n_steps
    av = kd.KINDS[config.av.kind]
    states = np.empty((n + 1, 4))
    world_log = np.full((n, len(WORLD_LOG)), np.nan)
    av_log, hv_log = np.full((n, kd.LOG_SIZE), np.nan), np.full((n, kd.LOG_SIZE), np.nan)
    needs = np.array([av.needs_game, av.needs_av_library, av.needs_game or av.needs_av_library])
    st = s.streams
    hv_prm = np.concatenate([[float(accels.size)], np.asarray(accels, float)])
    run_loop(s.P_av, s.P_hv, s.disc, s.x0, config.simulation.dt_s, av.kind,
             policy_params(config, kd.AV), kd.REPLAY, hv_prm, st.draws_av, np.zeros((n, 0)),
             needs, False, st.meas_noise, st.accel_noise, False, states, world_log, av_log,
             hv_log, np.zeros(n, np.int64), np.zeros(slot.N_WORK, np.int64),
             np.zeros(kd.STATE_SIZE), math.inf, math.inf)  # never stops: the whole run
    return s.scenario, states, world_log


def closest_approach(config: Config, accels: np.ndarray, seed: int = 1) -> float:
    """The smallest footprint gap [m] of :func:`run_against` (0: they touched), up to the
    first rear-end by the human if there is one (the human's fault, not the AV's)."""
    scenario, states, world_log = run_against(config, accels, seed)
    gaps = measures.min_gap(scenario, states[:, 0], states[:, 2])
    after = states[1:]
    rear = np.r_[False, measures.human_at_fault(scenario, states, world_log[:, W_AV_A],
                                                config.simulation.dt_s, world_log[:, W_HV_A])
                 & scenario.collides(after[:, 0], after[:, 2])]
    if rear.any():
        gaps = gaps[:int(np.argmax(rear))]
    return float(gaps.min()) if gaps.size else float("inf")


def falsify(config: Config, pieces: int = 8, samples: int = 30, elite: int = 6,
            rounds: int = 5, seed: int = 0, run_seed: int = 1) -> float:
    """The smallest footprint gap [m] a cross-entropy search of ``samples * rounds`` runs
    finds (module docstring): ``pieces`` constant accelerations, each held for an equal part of
    the run, within the human's limits; ``seed`` seeds the search (deterministic),
    ``run_seed`` the runs' initial state."""
    rng = np.random.default_rng(seed)
    if config.yield_line_choices is not None:
        # foresight's pick depends on the configuration, the seed and the measured start,
        # never on the human it meets (its predictions put model humans in the seat): one
        # pick serves every run of the search, each then the run with that line, bit for bit
        from ..world import predicted_summary

        line = setup(config, run_seed, predict=predicted_summary).yield_line_m
        config = config.with_overrides({"av.yield_line_choices_m": [],
                                         "av.yield_line_m": line})
    veh = config.vehicle_of("hv")
    lo, hi = veh.u_min_mps2, veh.u_max_mps2
    n = config.simulation.n_steps
    hold = -(-n // pieces)
    mean, std = np.full(pieces, 0.5 * (lo + hi)), np.full(pieces, hi - lo)
    best = float("inf")
    for _ in range(rounds):
        draws = np.clip(rng.normal(mean, std, size=(samples, pieces)), lo, hi)
        scores = np.array([closest_approach(config, np.repeat(d, hold)[:n], run_seed)
                           for d in draws])
        best = min(best, float(scores.min()))
        top = draws[np.argsort(scores, kind="stable")[:elite]]
        mean, std = top.mean(axis=0), top.std(axis=0) + 0.05
    return best


__all__ = ["closest_approach", "falsify", "run_against"]
