"""``persuasive simulate``: one closed-loop run, as text, JSON or a per-step log file."""

from __future__ import annotations

import json
import time

import click

from ._common import INTERACTIONS_HELP, compile_notice, config_of, run_options

#: Per-step log formats ``--out`` writes, by extension.
LOG_EXTENSIONS = (".parquet", ".csv")


def write_log(record, path: str) -> None:
    """Write a run's per-step log: Parquet (with the record's metadata, so that ``plot
    --from`` and the replay human can read it back) or CSV, by extension, atomically."""
    from .._files import atomic_write, check_output_file

    ext = check_output_file(path, LOG_EXTENSIONS, "log")
    if ext == ".csv":
        frame = record.frame()
        atomic_write(path, lambda p: frame.to_csv(p, index=False))
    else:
        record.save(path)


@click.command()
@run_options(seed_help="Run seed.")
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Write the per-step log here: .parquet or .csv (the folder must exist).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--interactions", type=click.IntRange(1, 1000), default=None,
              help=INTERACTIONS_HELP)
def simulate(out, as_json, interactions, **run) -> None:
    """Simulate one closed-loop run (two vehicles, one conflict)."""
    from .._files import check_output_file
    from ..simulation import ARRIVAL_LABELS, simulate as simulate_run

    config = config_of(run)
    if interactions is not None:
        config = config.with_overrides({"simulation.interactions": interactions})
    if (config.simulation.interactions or 1) > 1:
        if out:
            raise click.UsageError("--out writes one run's log; with several interactions use "
                                   "persuasive.simulation.simulate_interactions")
        compile_notice()
        _interactions(config, run["seed"], as_json)
        return
    if out:
        check_output_file(out, LOG_EXTENSIONS, "log")  # before any work
    compile_notice()
    t0 = time.perf_counter()
    record = simulate_run(config, run["seed"])
    elapsed = time.perf_counter() - t0
    if out:
        write_log(record, out)
    summary = record.summary()
    if as_json:
        click.echo(json.dumps(summary))
        return
    o = record.outcome
    dt = config.simulation.dt_s
    line = ARRIVAL_LABELS[o.first_at_line]
    where = ""
    if o.first_at_line:
        where = f" (after step {o.idx_end}, t = {(o.idx_end + 1) * dt:.1f} s)"
    pa_hat_text = f", p_a_hat = {config.p_a_hat:g}" if config.av.kind == "persuasive" else ""
    human = f"{config.hv.kind} HV" + (f" starting as {config.hv.role}"
                                      if config.hv.kind in ("lfg", "stubborn", "noisy") else "")
    click.echo(f"{config.av.kind} AV, {human}, p_a = {config.roles.p_a:g}{pa_hat_text}, "
               f"{config.scenario.kind}, seed {record.seed}, {config.mode} mode")
    s0, v0 = record.hv_initial_state
    click.echo(f"HV initial state: s = {s0:.3f} m, v = {v0:.3f} m/s")
    click.echo(f"first at the crossing line: {line}{where}; "
               f"first at the conflict point: {ARRIVAL_LABELS[o.first_at_conflict_point]}")
    click.echo(f"collision: {'yes' if o.collision else 'no'}; minimum distance "
               f"{o.min_distance_to_line_m:.2f} m up to the line, {o.min_distance_m:.2f} m over "
               f"the run ({summary['distance_measured']}; safe set "
               f"{summary['safety_distance_m']:g} m)")
    changes = f"HV role changes: {o.hv_role_changes}"
    if config.av.kind == "lfg":
        changes += f"; AV role changes: {o.av_role_changes}"
    elif config.av.kind in ("persuasive", "passive", "cv"):
        changes += f"; steps where the chance constraint failed: {o.infeasible_steps}"
    click.echo(changes)
    click.echo(f"time: {elapsed:.3f} s" + (f"; per-step log written to {out}" if out else ""))


def _interactions(config, seed: int, as_json: bool) -> None:
    """K interactions with the human of ``seed``: one line each (or one JSON object)."""
    from ..simulation import ARRIVAL_LABELS, BY_INTERACTION, simulate_interactions

    t0 = time.perf_counter()
    records = simulate_interactions(config, seed)
    elapsed = time.perf_counter() - t0
    summaries = [r.summary() for r in records]
    if as_json:
        out = dict(summaries[-1])
        out["interactions"] = len(records)
        out["by_interaction"] = {name: [s[name] for s in summaries] for name in BY_INTERACTION
                                 if name in summaries[0]}
        click.echo(json.dumps(out))
        return
    online = config.p_a_online and config.av.kind == "persuasive"
    if online:
        import numpy as np

        a, b = config.p_a_prior
        w = records[0].p_a_prior
        start = float(w @ np.linspace(0.0, 1.0, w.size) / w.sum())
    click.echo(f"{config.av.kind} AV, {config.hv.kind} HV starting as {config.hv.role}, "
               f"p_a = {config.roles.p_a:g}, "
               + (f"p_a_hat online (prior Beta({a:g}, {b:g}) on {config.p_a_grid} points, "
                  f"mean {start:.4f})" if online else f"p_a_hat = {config.p_a_hat:g}")
               + f", seed {seed}, {len(records)} interactions, {config.mode} mode")
    for r, s in zip(records, summaries):
        o = r.outcome
        text = (f"interaction {r.interaction + 1}: first at the line: "
                f"{ARRIVAL_LABELS[o.first_at_line]}; chance constraint failed on "
                f"{o.infeasible_steps} steps; collision: {'yes' if o.collision else 'no'}")
        if online:
            text += f"; p_a_hat at the end {s['pa_hat_final']:.4f}"
        click.echo(text)
    click.echo(f"time: {elapsed:.3f} s")
