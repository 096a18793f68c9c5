"""``persuasive compile``: load, or compile once, every kernel any command calls.

Numba compiles a kernel the first time it is called with a new signature (the types,
dimensions and memory layout of its arguments) and caches it on disk (``cache=True``; see
:mod:`persuasive._compile`). Without this command each command compiles its own kernels on
first use, in the middle of its work. This command drives every path a command or a library
call takes into compiled code, on tiny inputs, phase by phase:

- ``closed loop``: ``world.run_loop`` (one signature covers every AV, human, scenario and
  shield kind: they are run-time ids) and what a record computes from a run (the outcome's
  measures, ``path_points`` on scalars and arrays, a saved run read back), for every
  scenario in both modes, the replay human, repeated interactions with the online ``p_a``;
- ``python loop``: the Python loop (``PythonWorld``: the drive page, ``run_python``) and the
  gymnasium environments, which call the compiled policy step (``policy_step_buffers``,
  ``policy_init``, ``policy_role``), the game (``build_buffers``, ``solve_buffers``) and the
  world's steps from Python;
- ``planner``: ``Planner`` (every AV kind, every scenario, the online ``p_a``) and the
  adapter of outside simulators (``envs/external.py``: highway-env, SUMO), whose shield calls
  ``shield_filter`` and ``shield_filter_one``; the junction's joint AV (``many/joint.py``:
  ``shifted_into``, ``allowed_of``); ``bench``'s kernels;
- ``fit``: the fit's kernels, the parallel ones too (``fitting.estimate.warm_up``), and a
  fit of every model to two runs;
- ``recordings``: runs exported as tracks, the pair search (``recordings.geometry``), logs of
  the pairs, their fit, the held-out evaluation and the AV in a recorded driver's seat.

One line per phase says its time and whether it compiled. Everything runs in this one
process: each phase after the first reuses the kernels the earlier ones compiled (the game,
the policies and the shield compile once, with the closed loop). Two processes at once, the
closed loop in one and the rest in the other, took longer (626 s against 422 s on the shared
2-core machine, 378 s of CPU against 211 s): the second compiles those shared kernels again.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Callable

import click


def _closed_loop(tmp: Path) -> None:
    from ..config import AV_KINDS, SCENARIO_KINDS, SHIELD_KINDS, SIMULATED_HV_KINDS, Config
    from ..simulation import load_record, simulate, simulate_interactions

    for scenario in SCENARIO_KINDS:
        for mode in ("paper", "corrected"):
            simulate(Config(mode=mode).with_overrides({"scenario.kind": scenario}), 3)
    for shield in SHIELD_KINDS:
        simulate(Config(mode="corrected").with_overrides({"av.shield": shield}), 3)
    short = {"simulation.n_steps": 5}
    for av in AV_KINDS:  # run-time kind ids: the same signature, checked all the same
        for hv in (k for k in SIMULATED_HV_KINDS if k != "replay"):  # replay: below
            simulate(Config().with_overrides({**short, "av.kind": av, "hv.kind": hv}), 1)
    simulate_interactions(Config().with_overrides({"mpc.p_a_hat": "online"}), 2, 2)
    log = tmp / "run.parquet"
    record = simulate(Config(mode="corrected").with_overrides({"scenario.kind": "crossing"}), 1)
    record.save(log)
    load_record(log)  # the outcome computed again from a saved run (plot --from)
    simulate(Config(mode="corrected").with_overrides(
        {"scenario.kind": "crossing", "hv.kind": "replay", "hv.replay.file": str(log)}), 4)


def _python_loop(tmp: Path) -> None:
    from ..config import AV_KINDS, SCENARIO_KINDS, Config
    from ..world import run_python

    class Steady:
        """A Python policy for the HV (as the person at the drive page is)."""

        log_columns = ()

        def reset(self, context, rng=None) -> None:
            pass

        def act(self, observation) -> float:
            return 0.0

    for scenario in SCENARIO_KINDS:
        for av in AV_KINDS:
            config = Config(mode="corrected").with_overrides(
                {"scenario.kind": scenario, "av.kind": av, "simulation.n_steps": 20})
            run_python(config, 1)
            run_python(config, 2, hv=Steady())
    try:
        import gymnasium as gym
    except ImportError:  # the gym extra is not installed: no environment to warm
        return
    from ..envs import ENV_IDS

    for env_id in ENV_IDS.values():
        for controlled in ("av", "hv"):
            env = gym.make(env_id, controlled=controlled)
            env.reset(seed=1)
            for _ in range(3):
                env.step(env.action_space.sample())
            env.close()


def _planner(tmp: Path) -> None:
    import math

    from .. import bench
    from ..config import AV_KINDS, SCENARIO_KINDS, SHIELD_KINDS, Config
    from ..envs.external import CROSSING, FOLLOW, MERGE, Conflict, ExternalPlanner
    from ..many.joint import JointPlanner
    from ..planner import Planner
    from ..simulation import simulate

    for scenario in SCENARIO_KINDS:
        for av in AV_KINDS:
            p = Planner(Config(mode="corrected").with_overrides(
                {"scenario.kind": scenario, "av.kind": av}))
            p.plan(av=(-20.0, 4.0), hv=(-22.0, 4.3))
            p.accel((-19.6, 4.0), (-21.5, 4.3))
    Planner(Config(mode="corrected").with_overrides({"mpc.p_a_hat": "online"})).plan(
        av=(-20.0, 4.0), hv=(-22.0, 4.3))
    conflicts = [Conflict(0, CROSSING, -30.0, -30.0, 8.0, (-5.0, 0.0), (-5.0, 5.0)),
                 Conflict(1, MERGE, -25.0, -28.0, 7.0, (-math.inf, 0.0), (-4.0, 4.0)),
                 Conflict(2, FOLLOW, 10.0, 30.0, 8.0),
                 Conflict(3, CROSSING, -40.0, -45.0, 9.0, (-5.0, 0.0), (-5.0, 5.0),
                          extra={"stand_in": True}),
                 Conflict(4, FOLLOW, 5.0, 25.0, 0.0, extra={"wreck": True})]
    for av in AV_KINDS:
        for shield in SHIELD_KINDS:
            config = Config(mode="corrected").with_overrides({"av.kind": av,
                                                              "av.shield": shield})
            p = ExternalPlanner(config, 0)
            for k in range(3):
                p.act(8.0, conflicts, 0.1)
                p.act(8.0, conflicts[:1], 0.1, shield_lead_m=lambda a: 0.01 * a)
                p.shield(8.0, 0.5, conflicts, 0.1, driven=True)
            JointPlanner(config, 0).act(8.0, conflicts, 0.1)  # one plan against two
    config = Config()
    bench._game_times_ns(config, [simulate(config.with_overrides({"simulation.n_steps": 3}),
                                           1)], 1)
    bench._online_times_ns(batches=1, steps=2)


def _fit(tmp: Path) -> None:
    from ..config import Config
    from ..fitting import evidence_of, fit_models, smooth
    from ..fitting.estimate import MODELS, warm_up
    from ..fitting.evidence import run_log_of
    from ..simulation import simulate

    warm_up()
    config = Config(mode="corrected").with_overrides({"scenario.kind": "crossing"})
    ev = evidence_of([run_log_of(simulate(config, seed)) for seed in (1, 2)])
    report = fit_models(ev, MODELS, 1e-3, True)
    smooth(ev, report.fits["lfg"])


def _recordings(tmp: Path) -> None:
    from ..config import Config
    from ..fitting import evidence_of, fit_models, load_logs
    from ..recordings.evaluate import EvalParams, Split, evaluate, read_sites
    from ..recordings.export import export_runs
    from ..recordings.formats import read_tracks
    from ..recordings.logs import write_logs
    from ..recordings.pairs import PairParams, find_pairs, read_pairs, write_pairs
    from ..recordings.replay import ReplaySettings, replay_pairs
    from ..recordings.tracks import SmoothingParams, smooth_tracks
    from ..simulation import simulate

    config = Config(mode="corrected").with_overrides({"scenario.kind": "crossing",
                                                      "simulation.n_steps": 120})
    runs = []
    for seed in (1, 2):
        runs.append(tmp / f"rec{seed}.parquet")
        simulate(config, seed).save(runs[-1])
    tracks = tmp / "tracks"
    tracks.mkdir()
    export_runs(runs, tracks, 0.05, 3, 0.1)
    result = find_pairs(smooth_tracks(read_tracks([tracks]), SmoothingParams()), PairParams())
    pairs = tmp / "pairs.parquet"
    write_pairs(pairs, result, [str(tracks)])
    frame, _ = read_pairs(pairs)
    logs = tmp / "logs"
    logs.mkdir()
    written = write_logs(frame, logs, Config(mode="corrected"))
    runs_logs = load_logs([str(logs / w.name) for w in written])
    fit_models(evidence_of(runs_logs), ["lfg"], 1e-3, False)
    evaluate(read_sites([pairs]), Split("folds", k=2), None, EvalParams())
    replay_pairs(frame, ReplaySettings(), Config(mode="corrected"), str(pairs))


#: The phases, in the order they run.
PHASES: dict[str, Callable[[Path], None]] = {
    "closed loop": _closed_loop, "python loop": _python_loop, "planner": _planner,
    "fit": _fit, "recordings": _recordings}


def _run_phases(names: list[str]) -> None:
    """Run the phases ``names``, one line each: its time and whether it compiled."""
    from .._compile import StudyClock

    with tempfile.TemporaryDirectory(prefix="persuasive-compile-") as tmp:
        for name in names:
            clock = StudyClock()
            folder = Path(tmp) / name.replace(" ", "-")
            folder.mkdir()
            PHASES[name](folder)
            compiled = clock.compile_s
            what = f"compiled in {compiled:.1f} s" if compiled > 0 else "all cached"
            click.echo(f"{name}: {clock.seconds + compiled:.1f} s ({what})")
            sys.stdout.flush()


@click.command("compile")
def compile_command() -> None:
    """Load, or compile once, every kernel any command calls (make setup runs it).

    One line per phase with its time, then the total. With every kernel cached it only
    loads them; afterwards no command compiles.
    """
    from .._compile import StudyClock

    clock = StudyClock()
    _run_phases(list(PHASES))
    compiled = clock.compile_s
    click.echo(f"total: {clock.seconds + compiled:.1f} s, of which compiling {compiled:.1f} s")


__all__ = ["PHASES", "compile_command"]
