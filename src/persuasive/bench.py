"""Benchmarks of the planner and the simulator (``persuasive bench``).

Figures, each over states visited by real closed-loop runs (paper mode, Table 2's first row,
seeds ``1..n_runs``, with the chosen AV kind and scenario), after a warm-up, timed call by call
with ``time.perf_counter_ns`` from Python (so they include the cost of calling the compiled
code, as a user pays it):

- ``game_solve_us_median``: one full prediction of a joint state (both trajectory libraries,
  both reward matrices, both leader-follower solves), microseconds;
- ``mpc_decision_ms_median`` / ``_p99``: one decision of the AV's planner
  (:meth:`Planner.plan`: for the persuasive MPC, the human-view prediction, the branch MPC with
  its re-solves, the belief update), replayed along the runs' states, milliseconds;
- ``mpc_run_ms_median``: one whole closed-loop run (61 steps) with :func:`simulate`;
- ``shield_us_median`` / ``_p99``: the safety shield alone (the worst-case kind, as the
  Python worlds and ``Planner`` call it: ``persuasive.safety.filter.ShieldFilter.one``, call
  overhead included) around the decision each state's run took, microseconds; and
  ``shielded_decision_ms_median`` / ``_p99``: the planner's decision with the shield on (the
  MPC then also checks its candidates against the shield and tracks its confidence in the
  human model, docs/method.md §12.3), replayed along the same states;
- ``online_update_us_median`` / ``_p99``: the online posterior over ``p_a``
  (``mpc.p_a_hat = "online"``, docs/method.md §13.9, 21 grid points) alone: one step of its
  filter and its posterior mean, timed as batches of 61 steps (one run each, compiled loop,
  residuals drawn ``N(0, 0.3^2)``) per step, microseconds; and
  ``online_decision_ms_median``: the planner's decision with it, replayed along the same
  states as ``mpc_decision_ms_median`` (the difference of the two medians is within the
  decision's noise: compare the update's own cost);
- ``work_per_decision``: the kernels' work counters per decision (pair tests of the games and
  of the MPC, re-solves done and skipped by the pruning, libraries built), so that a change
  that loses the pruning shows even when the machine's timings are noisy;
- with ``full``: ``reproduce_all_s``, the wall time of reproducing Tables 1 and 2 (16,000 runs),
  and ``reproduce_peak_rss_mb``, an upper bound of the memory held at once (this process's
  peak plus each worker at the largest worker peak; Linux ``ru_maxrss``).
- with ``reference``: the same game solve and MPC decision on the plain NumPy path
  (``persuasive.reference``), the "before" of the compiled kernels.
"""

from __future__ import annotations

import os
import platform
import resource
import time
from typing import Any

import numpy as np

from .config import Config
from .game import predict_buffers
from .library import lib_buffers
from .packing import N_WORK, WORK_NAMES, discounts, pack
from .planner import Planner
from .scenarios import build_scenario
from .simulation import simulate


def bench_config(av: str = "persuasive", scenario: str = "intersection") -> Config:
    """Paper mode, Table 2's first row (HV starts as leader, p_a = p_a_hat = 1), with the AV
    kind and the scenario given."""
    return Config().with_overrides({"av.kind": av, "scenario.kind": scenario})


def _game_times_ns(config: Config, runs: list, repeats: int) -> np.ndarray:
    P_av, P_hv = pack(config, build_scenario(config))
    disc = discounts(config)
    n, n_traj = config.library.n_samples, config.library.n_traj
    (be, we), (bo, wo) = lib_buffers(n, n_traj), lib_buffers(n, n_traj)
    idx, q_values, work = np.empty(4, np.int64), np.empty((4, n_traj)), np.zeros(N_WORK, np.int64)
    joint = [tuple(float(x) for x in row) for run in runs for row in run.states[:-1]]
    for s_av, v_av, s_hv, v_hv in joint[:20]:  # warm-up
        predict_buffers(s_hv, v_hv, s_av, v_av, P_hv, P_av, disc, be, we, bo, wo, idx, q_values,
                        work)
    times = []
    clock = time.perf_counter_ns
    for _ in range(repeats):
        for s_av, v_av, s_hv, v_hv in joint:
            t = clock()
            predict_buffers(s_hv, v_hv, s_av, v_av, P_hv, P_av, disc, be, we, bo, wo, idx,
                            q_values, work)
            times.append(clock() - t)
    return np.array(times)


def _decision_times_ns(config: Config, runs: list, repeats: int) -> tuple[np.ndarray, Planner]:
    """Each run's AV decisions replayed with a :class:`Planner` (same states, same HV roles)."""
    planner = Planner(config, seed=0)
    times = []
    clock = time.perf_counter_ns
    has_role = "hv_next_role" in runs[0].log
    for rep in range(repeats + 1):
        if rep == 1:
            planner.work[:] = 0  # count the timed passes only
        for run in runs:
            planner.reset()
            # quirk Q3 reads the HV's role after its own step, as in the closed loop
            roles = run.log["hv_next_role"] if has_role else [None] * len(run.states)
            for row, role in zip(run.states[:-1], roles):
                s_av, v_av, s_hv, v_hv = row
                t = clock()
                planner.plan((s_av, v_av), (s_hv, v_hv),
                             human_role=None if role is None else str(role))
                if rep:  # the first pass is the warm-up
                    times.append(clock() - t)
    return np.array(times), planner


def _shield_times_ns(config: Config, runs: list, repeats: int) -> np.ndarray:
    """The worst-case shield around each state's logged AV acceleration, as every Python
    world applies it (:meth:`persuasive.safety.filter.ShieldFilter.one`)."""
    from .record import static_setup
    from .safety.filter import ShieldFilter

    shielded = config.with_overrides({"av.shield": "worst-case"})
    _, P_av, P_hv, _ = static_setup(shielded)
    one = ShieldFilter.closed_loop(P_av, P_hv, config.simulation.dt_s).one
    cases = [((float(r[0]), float(r[1])), float(a), (float(r[2]), float(r[3])))
             for run in runs for r, a in zip(run.states[:-1], run.log["av_accel_mps2"])]
    for x_R, a, x_H in cases[:20]:  # warm-up
        one(a, x_R, x_H)
    times = []
    clock = time.perf_counter_ns
    for _ in range(repeats):
        for x_R, a, x_H in cases:
            t = clock()
            one(a, x_R, x_H)
            times.append(clock() - t)
    return np.array(times)


def _online_times_ns(batches: int = 2000, steps: int = 61, n_grid: int = 21) -> np.ndarray:
    """Per-step cost of the online posterior's update: batches of ``steps`` steps from a
    fresh state (Beta(7, 3) prior on ``n_grid`` points)."""
    from .online import online_init, online_params, online_replay, prior_masses, state_size

    prm = online_params(*prior_masses(7.0, 3.0, n_grid))
    st = np.zeros(state_size(n_grid))
    rng = np.random.default_rng(0)
    obs = np.empty((batches, steps, 3))
    obs[:, :, :2] = rng.normal(0.0, 0.3, (batches, steps, 2))
    obs[:, :, 2] = rng.choice([0.0, 1.0, 0.5], (batches, steps), p=[0.45, 0.45, 0.1])
    means = np.empty(steps)
    for b in range(min(20, batches)):  # warm-up
        online_init(st, 0, prm, 0, 0.5)
        online_replay(st, 0, prm, 0, obs[b], 0.3, 0.5, means)
    times = np.empty(batches)
    clock = time.perf_counter_ns
    for b in range(batches):
        online_init(st, 0, prm, 0, 0.5)
        t = clock()
        online_replay(st, 0, prm, 0, obs[b], 0.3, 0.5, means)
        times[b] = (clock() - t) / steps
    return times


def bench(n_runs: int = 10, repeats: int = 3, full: bool = False, reference: bool = False,
          workers: int | None = None, av: str = "persuasive",
          scenario: str = "intersection") -> dict[str, Any]:
    """Measure the figures of the module docstring; returns them as a flat dict."""
    config = bench_config(av, scenario)
    simulate(config, 1)  # load the compiled code
    runs = [simulate(config, seed) for seed in range(1, n_runs + 1)]
    game = _game_times_ns(config, runs, repeats)
    decision, planner = _decision_times_ns(config, runs, repeats)
    shield = _shield_times_ns(config, runs, repeats)
    shielded, _ = _decision_times_ns(config.with_overrides({"av.shield": "worst-case"}), runs,
                                     repeats)
    online = _online_times_ns()
    online_decision = None
    if av == "persuasive":
        online_decision, _ = _decision_times_ns(
            config.with_overrides({"mpc.p_a_hat": "online"}), runs, repeats)
    run_times = []
    for seed in range(1, n_runs + 1):
        t = time.perf_counter()
        simulate(config, seed)
        run_times.append(time.perf_counter() - t)
    out: dict[str, Any] = {
        "av": av,
        "scenario": scenario,
        "game_solve_us_median": float(np.median(game) / 1e3),
        "game_solve_us_p99": float(np.percentile(game, 99) / 1e3),
        "mpc_decision_ms_median": float(np.median(decision) / 1e6),
        "mpc_decision_ms_p99": float(np.percentile(decision, 99) / 1e6),
        "mpc_run_ms_median": float(np.median(run_times) * 1e3),
        "shield_us_median": float(np.median(shield) / 1e3),
        "shield_us_p99": float(np.percentile(shield, 99) / 1e3),
        "shielded_decision_ms_median": float(np.median(shielded) / 1e6),
        "shielded_decision_ms_p99": float(np.percentile(shielded, 99) / 1e6),
        "online_update_us_median": float(np.median(online) / 1e3),
        "online_update_us_p99": float(np.percentile(online, 99) / 1e3),
        "online_decision_ms_median": None if online_decision is None else
        float(np.median(online_decision) / 1e6),
        "work_per_decision": {name: float(w) / decision.size
                              for name, w in zip(WORK_NAMES, planner.work)},
        "samples": {"game_solves": int(game.size), "mpc_decisions": int(decision.size),
                    "runs": n_runs},
        "machine": {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine(),
                    "python": platform.python_version()},
    }
    if reference:
        out.update(_reference_times(config, runs[0]))
    if full:
        from .experiments import reproduce

        workers = workers or os.cpu_count() or 1
        t = time.perf_counter()
        reproduce("all", 1000, workers, "paper")
        out["reproduce_all_s"] = time.perf_counter() - t
        out["reproduce_workers"] = workers
        # an upper bound of the memory in use at once: this process at its peak plus every
        # worker at the largest peak of any worker
        own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        out["reproduce_peak_rss_mb"] = (own + workers * child) / 1024
    return out


def bench_junction(config: Config, seeds: int = 20) -> dict[str, Any]:
    """How fast a junction of ``config`` (``scenario.kind = "junction"``) steps: ``seeds``
    runs (seeds ``1..seeds``) in this process after a warm-up run, every closed-loop step
    timed (every vehicle decides, all advance, every conflict checked) and, inside it, the
    AV's decision (its planners and the shield) and the humans' decisions. Medians and 99th
    percentiles [ms], and each part's share of the step time."""
    from .many.world import JunctionWorld

    JunctionWorld.of(config, 0).run()  # load the kernels
    step, av, humans = [], [], []
    clock = time.perf_counter_ns
    for seed in range(1, seeds + 1):
        w = JunctionWorld.of(config, seed)
        planner_act, human_accel = w.planner.act, w._human_accel
        spent = {"av": 0, "hv": 0}

        def timed_act(*a, _act=planner_act, **k):
            t0 = clock()
            out = _act(*a, **k)
            spent["av"] += clock() - t0
            return out

        def timed_human(*a, _accel=human_accel, **k):
            t0 = clock()
            out = _accel(*a, **k)
            spent["hv"] += clock() - t0
            return out

        w.planner.act, w._human_accel = timed_act, timed_human
        while True:
            spent["av"] = spent["hv"] = 0
            t0 = clock()
            done = w.step().done
            step.append((clock() - t0) * 1e-6)
            av.append(spent["av"] * 1e-6)
            humans.append(spent["hv"] * 1e-6)
            if done:
                break
    step_, av_, hv_ = map(np.asarray, (step, av, humans))
    spec = config.junction_spec
    return {"scenario": "junction", "vehicles": spec.n_vehicles, "av": config.av.kind,
            "shield": config.shield, "runs": seeds, "steps": int(step_.size),
            "step_ms_median": float(np.median(step_)),
            "step_ms_p99": float(np.percentile(step_, 99)),
            "av_ms_median": float(np.median(av_)), "av_ms_p99": float(np.percentile(av_, 99)),
            "humans_ms_median": float(np.median(hv_)),
            "av_share": float(av_.sum() / step_.sum()),
            "humans_share": float(hv_.sum() / step_.sum()),
            "machine": {"cpus": os.cpu_count(),
                        "processor": platform.processor() or platform.machine(),
                        "python": platform.python_version()}}


def _reference_times(config: Config, run, n: int = 5) -> dict[str, float]:
    """The straightforward NumPy path on ``n`` states of one run (it is slow)."""
    from . import reference

    P_av, P_hv = pack(config, build_scenario(config))
    disc = discounts(config)
    states = run.states
    picks = states[np.linspace(0, len(states) - 2, n).astype(int)]
    games, decisions = [], []
    for s_av, v_av, s_hv, v_hv in picks:
        t = time.perf_counter_ns()
        reference.full_prediction((s_hv, v_hv), (s_av, v_av), P_hv, P_av, disc)
        games.append(time.perf_counter_ns() - t)
        t = time.perf_counter_ns()
        reference.mpc((s_av, v_av), (s_hv, v_hv), (0.5, 0.5), True, 1.0, P_av, P_hv, disc)
        decisions.append(time.perf_counter_ns() - t)
    return {"reference_game_solve_us_median": float(np.median(games) / 1e3),
            "reference_mpc_decision_ms_median": float(np.median(decisions) / 1e6)}
