"""One closed-loop run and its record (docs/method.md §7): :func:`simulate` and :class:`RunRecord`.

:func:`simulate` builds the scenario and both vehicles' parameter vectors from the
configuration, draws the run's random numbers (``persuasive.streams.draw_streams``), runs the
compiled loop (``persuasive.world.run_loop``) with the two policies the configuration names,
and returns a :class:`RunRecord`: the configuration, the seed, the states, the per-step log
and the outcome (:class:`RunOutcome`); the setup and the record are ``persuasive.record``'s.
:func:`persuasive.world.run_python` gives the same record for Python policies.

States are indexed ``x_0 .. x_N`` (``N = n_steps``): step ``k`` decides at ``x_k`` and advances
to ``x_{k+1}``; collision and arrival are tested on ``x_{k+1}``. ``idx_end`` is the first step
after which a vehicle is at its first-arrival line (the last step if none is), and the "up to
the line" minimum distance runs over ``x_0 .. x_{idx_end + 1}``. Measured speeds with noise are
clipped to the vehicle's ``[v_min, v_max]`` before a policy sees them.
"""

from __future__ import annotations

import numpy as np

from .config import Config
from .packing import N_WORK
from .policies import kinds as kd
from .policies import kind_of, policy_params
from .record import (ARRIVAL_LABELS, WORLD_LOG, RunOutcome, RunRecord, check_seed, load_record,
                     make_record, setup)


def simulate(config: Config, seed: int, timed: bool = False) -> RunRecord:
    """Run one closed loop for ``seed``; bit-identical for equal inputs.

    ``timed``: also measure the AV's decision time per step (``RunRecord.av_decision_ms``).
    """
    from .world import run_loop

    s = setup(config, seed)
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
    run_loop(s.P_av, s.P_hv, s.disc, s.x0, config.simulation.dt_s, av.kind,
             policy_params(config, kd.AV), hv.kind, policy_params(config, kd.HV), st.draws_av,
             st.draws_hv, needs, st.noisy, st.meas_noise, st.accel_noise, timed, states,
             world_log, av_log, hv_log, av_ns, work)
    return make_record(s, states, world_log, av_log, hv_log,
                       av_ns / 1e6 if timed else None, work=work)


__all__ = ["ARRIVAL_LABELS", "RunOutcome", "RunRecord", "check_seed", "load_record", "simulate"]
