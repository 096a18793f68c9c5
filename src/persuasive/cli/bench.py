"""``persuasive bench``: timings of the game solve, the MPC decision and the reproduction."""

from __future__ import annotations

import json

import click

from ..config import AV_KINDS, MANY_SCENARIO_KINDS, SCENARIO_KINDS
from ._common import Count, compile_notice, junction_compile_notice, workers_type


@click.command()
@click.option("--runs", "n_runs", type=Count(1, 1000), default=10, show_default=True,
              help="Closed-loop runs (seeds 1..N, at most 1000) whose states are replayed.")
@click.option("--repeats", type=Count(1, 100), default=3, show_default=True,
              help="Passes over those states (at most 100: the medians settle long before).")
@click.option("--full", is_flag=True, help="Also time 'reproduce all' (16,000 runs).")
@click.option("--workers", type=workers_type(), default=None,
              help="Workers for --full [all cores].")
@click.option("--reference", is_flag=True, help="Also time the plain NumPy reference path.")
@click.option("--sweep", "sweep", is_flag=True,
              help="Only compare a Dask sweep (2 workers, or --workers) with the process pool "
                   "on the same 2,000 and 8,000 runs: runs/s and the client's peak memory.")
@click.option("--av", type=click.Choice(list(AV_KINDS)), default="persuasive",
              show_default=True, help="The AV planner whose decisions are timed.")
@click.option("--scenario", type=click.Choice([*SCENARIO_KINDS, *MANY_SCENARIO_KINDS]), default="intersection",
              show_default=True,
              help="The scenario the runs are drawn from (junction: --vehicles vehicles, "
                   "every closed-loop step timed over --runs 30-s runs in corrected mode with "
                   "the worst-case shield).")
@click.option("--vehicles", type=Count(1, 64), default=None,
              help="Vehicles at the junction, the AV included (--scenario junction) [4].")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def bench(n_runs, repeats, full, workers, reference, sweep, av, scenario, vehicles,
          as_json) -> None:
    """Time a game solve, an MPC decision, a run and (--full) the whole reproduction; with
    --scenario junction, the closed-loop step of N vehicles and the AV's decision in it."""
    from ..bench import bench as run_bench

    if scenario == "junction" or vehicles is not None:
        _bench_junction(scenario, vehicles, av, n_runs, full, reference, sweep, as_json)
        return
    compile_notice()
    if sweep:
        _bench_sweep(workers or 2, repeats, as_json)
        return
    result = run_bench(n_runs, repeats, full, reference, workers, av, scenario)
    if as_json:
        click.echo(json.dumps(result))
        return
    _echo_machine(result)
    click.echo(f"game solve (libraries included): median {result['game_solve_us_median']:.1f} us,"
               f" p99 {result['game_solve_us_p99']:.1f} us")
    click.echo(f"{av} AV decision ({scenario}): median "
               f"{result['mpc_decision_ms_median']:.3f} ms, "
               f"p99 {result['mpc_decision_ms_p99']:.3f} ms")
    click.echo(f"the same decisions with the worst-case shield: median "
               f"{result['shielded_decision_ms_median']:.3f} ms, p99 "
               f"{result['shielded_decision_ms_p99']:.3f} ms; the shield alone: median "
               f"{result['shield_us_median']:.2f} us, p99 {result['shield_us_p99']:.2f} us")
    online = (f"; the decision with it: median {result['online_decision_ms_median']:.3f} ms"
              if result["online_decision_ms_median"] is not None else "")
    click.echo(f"online p_a posterior (21 points) update: median "
               f"{result['online_update_us_median']:.2f} us, p99 "
               f"{result['online_update_us_p99']:.2f} us per decision{online}")
    click.echo(f"closed-loop run (61 steps): median {result['mpc_run_ms_median']:.2f} ms")
    work = ", ".join(f"{k} {v:.1f}" for k, v in result["work_per_decision"].items())
    click.echo(f"work per decision: {work}")
    if reference:
        click.echo("reference NumPy path: game solve "
                   f"{result['reference_game_solve_us_median']:.0f} us, MPC decision "
                   f"{result['reference_mpc_decision_ms_median']:.1f} ms")
    if full:
        click.echo(f"reproduce all (16,000 runs, {result['reproduce_workers']} workers): "
                   f"{result['reproduce_all_s']:.1f} s, peak memory at most "
                   f"{result['reproduce_peak_rss_mb']:.0f} MB")


def _echo_machine(result: dict) -> None:
    m = result["machine"]
    click.echo(f"machine: {m['cpus']} cpus, {m['processor']}, Python {m['python']}")


def _bench_junction(scenario: str, vehicles: int | None, av: str, runs: int, full: bool,
                    reference: bool, sweep: bool, as_json: bool) -> None:
    """``bench --scenario junction``: :func:`persuasive.bench.bench_junction`."""
    from ..bench import bench_junction
    from ..config import Config

    if scenario != "junction":
        raise click.UsageError(f"--vehicles is read only with --scenario junction (the "
                               f"{scenario} holds two vehicles)")
    for flag, given in (("--full", full), ("--reference", reference), ("--sweep", sweep)):
        if given:
            raise click.UsageError(f"{flag} times the two-vehicle planner; it does not go with "
                                   "--scenario junction")
    config = Config(mode="corrected").with_overrides(
        {"scenario.kind": "junction", "av.kind": av,
         **({"junction.n_vehicles": vehicles} if vehicles is not None else {})})
    junction_compile_notice()
    result = bench_junction(config, runs)
    if as_json:
        click.echo(json.dumps(result))
        return
    _echo_machine(result)
    click.echo(f"junction, {result['vehicles']} vehicles, {av} AV with the {result['shield']} "
               f"shield, {result['runs']} runs ({result['steps']} steps)")
    click.echo(f"closed-loop step (every vehicle decides, all advance, every conflict "
               f"checked): median {result['step_ms_median']:.3f} ms, p99 "
               f"{result['step_ms_p99']:.3f} ms")
    click.echo(f"the AV's decision in it: median {result['av_ms_median']:.3f} ms, p99 "
               f"{result['av_ms_p99']:.3f} ms ({100 * result['av_share']:.0f} % of the step "
               f"time); the humans' decisions: median {result['humans_ms_median']:.3f} ms "
               f"({100 * result['humans_share']:.0f} %)")


def _bench_sweep(workers: int, repeats: int, as_json: bool) -> None:
    """``bench --sweep``: the Dask sweep against the process pool (persuasive.bench_sweep),
    each timed ``repeats`` times, the best time kept."""
    from ..bench_sweep import bench_sweep

    result = bench_sweep(workers=workers, repeats=repeats)
    if as_json:
        click.echo(json.dumps(result))
        return
    click.echo(f"Table 1's runs (2-LFG), {workers} workers, best of {repeats}: process pool "
               "(reproduce) vs Dask sweep (LocalCluster, Parquet parts written)")
    for s in result["sizes"]:
        click.echo(f"{s['runs']:>6} runs: pool {s['pool_runs_per_s']:.0f} runs/s "
                   f"({s['pool_s']:.1f} s), sweep {s['sweep_runs_per_s']:.0f} runs/s "
                   f"({s['sweep_s']:.1f} s, chunks of {s['sweep_chunk']}), "
                   f"ratio {100 * s['ratio']:.0f} %; client memory "
                   f"{s['client_rss_before_mb']:.0f} MB before, peak "
                   f"{s['client_peak_rss_mb']:.0f} MB; same results: "
                   f"{'yes' if s['same_results'] else 'NO'}")
    click.echo(f"sweep throughput {100 * result['ratio']:.0f} % of the process pool's "
               f"(target >= 90 %)")
