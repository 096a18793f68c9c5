"""``persuasive simulate``: one closed-loop run, as text, JSON or a per-step log file."""

from __future__ import annotations

import json
import os

import click

from .._compile import StudyClock
from ..config import ROLES
from ._common import (INTERACTIONS_HELP, KIND_OPTIONS, Count, check_input_files,
                      check_kind_options, compile_notice, compile_report, config_of,
                      ignored_fields, junction_compile_notice, kind_configs, lock_output,
                      run_options, unread_options)

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


def write_vehicles(frame, path: str) -> None:
    """Write a run per step and vehicle (the tables' long format,
    ``persuasive.tables.Trace.frame``): Parquet or CSV, by extension, atomically."""
    from .._files import atomic_write

    if path.endswith(".csv"):
        atomic_write(path, lambda p: frame.to_csv(p, index=False))
    else:
        atomic_write(path, lambda p: frame.to_parquet(p, index=False))


@click.command()
@run_options(seed_help="Run seed.")
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Write the per-step log here: .parquet or .csv (the folder must exist).")
@click.option("--vehicles-out", type=click.Path(dir_okay=False), default=None,
              help="Write the run per step and vehicle here, in the same columns for two "
                   "vehicles and for a junction (.parquet or .csv; a junction's --out writes "
                   "the same).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--interactions", type=Count(1, 1000), default=None, help=INTERACTIONS_HELP)
def simulate(out, vehicles_out, as_json, interactions, **run) -> None:
    """Simulate one closed-loop run (two vehicles, one conflict; or, with --scenario
    junction, the AV among --vehicles vehicles at a four-way junction, docs/guide/junction.md).

    --pa, --pa-hat and --hv-role given for kinds that ignore them are refused (exit status
    2); the same fields from --config or --set are run as given, and the summary line says
    which of them the run ignores.
    """
    from ..simulation import ARRIVAL_LABELS, simulate as simulate_run

    config = config_of(run)
    check_kind_options(run, kind_configs(config))
    check_input_files(config)
    if config.scenario.kind == "junction":
        if interactions is not None:
            raise click.UsageError("--interactions repeats one human's encounter with the AV; "
                                   "a junction run has many humans (--scenario junction)")
        _junction(config, run["seed"], out, vehicles_out, as_json)
        return
    if interactions is not None:
        config = config.with_overrides({"simulation.interactions": interactions})
    if (config.simulation.interactions or 1) > 1:
        if out or vehicles_out:
            raise click.UsageError("--out and --vehicles-out write one run; with several "
                                   "interactions use "
                                   "persuasive.simulation.simulate_interactions")
        compile_notice()
        _interactions(config, run["seed"], as_json)
        return
    outputs = _check_outputs(out, vehicles_out)
    compile_notice()
    clock = StudyClock()
    record = simulate_run(config, run["seed"])
    elapsed = clock.seconds
    if out:
        write_log(record, out)
    if vehicles_out:
        write_vehicles(record.vehicles_frame(), vehicles_out)
    summary = record.summary()
    compile_report(clock)
    if as_json:
        click.echo(json.dumps(json_summary(summary, config)))
        return
    o = record.outcome
    dt = config.simulation.dt_s
    line = ARRIVAL_LABELS[o.first_at_line]
    where = ""
    if o.first_at_line:
        where = f" (after step {o.idx_end}, t = {(o.idx_end + 1) * dt:.1f} s)"
    click.echo(f"{_agents(config)}, {config.scenario.kind}, seed {record.seed}, "
               f"{config.mode} mode{_ignored(config)}")
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
    click.echo(f"time: {elapsed:.3f} s" + outputs)


def _check_outputs(*paths: str | None) -> str:
    """Check and lock the output files before any work (``--out``, ``--vehicles-out``; they
    may not be one file); the summary line's words for them."""
    from .._files import check_output_file

    given = [p for p in paths if p]
    if len(given) == 2 and os.path.abspath(given[0]) == os.path.abspath(given[1]):
        raise click.UsageError(f"--out and --vehicles-out name the same file {given[0]}; "
                               "allowed: two different files")
    for p in given:
        check_output_file(p, LOG_EXTENSIONS, "log")
        lock_output(p, "log")
    words = []
    if paths[0]:
        words.append(f"per-step log written to {paths[0]}")
    if len(paths) > 1 and paths[1]:
        words.append(f"per-vehicle table written to {paths[1]}")
    return "".join("; " + w for w in words)


def _junction(config, seed: int, out: str | None, vehicles_out: str | None,
              as_json: bool) -> None:
    """``simulate --scenario junction``: one seed of the junction (the AV's run and, for the
    delay it causes, the same seed without it), its row as text or JSON; ``--out`` writes
    the AV's run per step and vehicle (``JunctionWorld.frame``), and so does
    ``--vehicles-out``."""
    import math

    from .._files import json_safe
    from ..many.world import JunctionWorld

    outputs = _check_outputs(out, vehicles_out)
    spec = config.junction_spec
    junction_compile_notice()
    clock = StudyClock()
    world = JunctionWorld.of(config, seed).run()
    reference = JunctionWorld.of(config, seed, with_av=False).run()
    elapsed = clock.seconds
    row = world.summary(reference)
    if out or vehicles_out:
        frame = world.frame()
        for path in (out, vehicles_out):
            if path:
                write_vehicles(frame, path)
    compile_report(clock)
    if as_json:
        click.echo(json.dumps(json_safe({
            "scenario": "junction", "variant": config.junction.variant or "major",
            "av": config.av.kind, "shield": config.shield, "mode": config.mode, **row}),
            allow_nan=False))
        return

    def secs(x: float) -> str:
        return f"{x:.1f} s" if math.isfinite(x) else "-"

    kinds = ",".join(f"{k}:{w:g}" if len(spec.hv_kinds) > 1 else k for k, w in spec.hv_kinds)
    plan = ("the rule's role per human, the worst pair decides" if config.av.kind == "lfg-rule"
            else "one plan against all, " + spec.joint_bound if spec.av_plan == "joint"
            else "one planner per human")
    plan += ", yielding " + ("outside the junction" if row["av_line"] == "outside" else
                             "at the stop line") + (" (picked by foresight)" if
                                                    spec.av_line == "foresight" else "")
    click.echo(f"{config.av.kind} AV ({plan}) among {spec.n_vehicles} vehicles at the junction "
               f"({config.junction.variant or 'major'}, {spec.lanes} lane(s), {kinds} humans "
               f"playing {spec.opponents}), seed {seed}, {config.mode} mode, shield "
               f"{config.shield}, {spec.duration_s:g}-s run")
    through = (f"yes, clear at t = {row['av_clear_s']:.1f} s (delay {row['av_delay_s']:.1f} s)"
               if row["av_through"] else "no")
    click.echo(f"AV through: {through}; first through {row['av_first_conflicts']} of the "
               f"{row['av_conflicts_passed']} conflicts both passed")
    click.echo(f"collisions: AV-caused {row['av_caused_collisions']}, AV in any "
               f"{row['av_collisions']}, between humans {row['human_collisions']}; uncertified "
               f"steps {row['uncertified_steps']}; shield overrides {row['shield_overrides']}")
    who = (" (the AV in it, of its own making)" if row["av_caused_deadlock"] else
           " (the AV in it)" if row["av_in_deadlock"] else "")
    lock = (f"at t = {row['deadlock_t_s']:.1f} s, vehicles {row['deadlock_vehicles']}{who}"
            if row["deadlock"] else "none")
    click.echo(f"deadlock: {lock}; waiting: AV {row['av_wait_s']:.1f} s, humans mean "
               f"{row['mean_wait_s']:.1f} s, max {row['max_wait_s']:.1f} s; delay caused to "
               f"the humans {row['caused_delay_s']:.2f} s")
    click.echo(f"AV stood inside the junction {row['av_inside_stood_s']:.1f} s (a human waiting "
               f"for it {row['av_inside_blocking_s']:.1f} s)")
    click.echo(f"vehicles through {row['vehicles_through']} of {spec.n_vehicles}, throughput "
               f"{row['throughput_veh_h']:.0f} veh/h; min PET of the AV "
               f"{secs(row['min_pet_av_s'])}, of all {secs(row['min_pet_s'])}; AV's closest "
               f"gap {row['min_gap_av_m']:.2f} m")
    click.echo(f"time: {elapsed:.3f} s (both runs)" + outputs)


def _interactions(config, seed: int, as_json: bool) -> None:
    """K interactions with the human of ``seed``: one line each (or one JSON object)."""
    from ..simulation import ARRIVAL_LABELS, BY_INTERACTION, simulate_interactions

    clock = StudyClock()
    records = simulate_interactions(config, seed)
    elapsed = clock.seconds
    summaries = [r.summary() for r in records]
    compile_report(clock)
    if as_json:
        out = json_summary(summaries[-1], config)
        out["interactions"] = len(records)
        out["by_interaction"] = {name: [s[name] for s in summaries] for name in BY_INTERACTION
                                 if name in summaries[0]}
        click.echo(json.dumps(out))
        return
    online = config.p_a_online and KIND_OPTIONS["pa_hat"].used_by(config)
    start = None
    if online:
        import numpy as np

        w = records[0].p_a_prior
        start = float(w @ np.linspace(0.0, 1.0, w.size) / w.sum())
    click.echo(f"{_agents(config, start)}, seed {seed}, {len(records)} interactions, "
               f"{config.mode} mode{_ignored(config)}")
    for r, s in zip(records, summaries):
        o = r.outcome
        text = (f"interaction {r.interaction + 1}: first at the line: "
                f"{ARRIVAL_LABELS[o.first_at_line]}; chance constraint failed on "
                f"{o.infeasible_steps} steps; collision: {'yes' if o.collision else 'no'}")
        if online:
            text += f"; p_a_hat at the end {s['pa_hat_final']:.4f}"
        click.echo(text)
    click.echo(f"time: {elapsed:.3f} s")


def _agents(config, online_start: float | None = None) -> str:
    """The summary's agents: the AV, the human with its initial role and ``p_a`` where it
    has them, and the persuasive AV's estimate (an online one with its prior; its mean over
    the prior's grid, ``online_start``, where known)."""
    roles = KIND_OPTIONS["hv_role"]
    av, human = f"{config.av.kind} AV", f"{config.hv.kind} HV"
    if config.av.kind in roles.av_kinds:  # an LFG AV: its own role, else the human's other
        other = ROLES[1 - ROLES.index(config.hv.role)]
        av += f" starting as {config.av.role or other}"
    if config.hv.kind in roles.hv_kinds:
        human += f" starting as {config.hv.role}"
    parts = [av, human]
    if KIND_OPTIONS["pa"].used_by(config):
        parts.append(f"p_a = {config.roles.p_a:g}")
    if KIND_OPTIONS["pa_hat"].used_by(config):
        if config.p_a_online:
            a, b = config.p_a_prior
            mean = "" if online_start is None else f", mean {online_start:.4f}"
            parts.append(f"p_a_hat online (prior Beta({a:g}, {b:g}) on {config.p_a_grid} "
                         f"points{mean})")
        else:
            parts.append(f"p_a_hat = {config.p_a_hat:g}")
    return ", ".join(parts)


def json_summary(summary: dict, config) -> dict:
    """The run's summary as ``--json`` prints it: what no kind of the run reads (``pa``,
    ``pa_hat``, ``hv_role``; :func:`~persuasive.cli._common.unread_options`) is ``null``
    rather than a value that played no part, and ``ignored_fields`` (only when there are any)
    names the fields a configuration set that the run ignores. Otherwise it is
    :meth:`RunRecord.summary <persuasive.record.RunRecord.summary>` as it is."""
    out = dict(summary)
    for name in unread_options(config):
        out[name] = None
    ignored = ignored_fields(config)
    if ignored:
        out["ignored_fields"] = ignored
    return out


def _ignored(config) -> str:
    """``"; ignored, as no kind here reads them: ..."``, naming the fields set (by --config or
    --set) that no kind of the run reads, or nothing."""
    fields = ignored_fields(config)
    return f"; ignored, as no kind here reads them: {', '.join(fields)}" if fields else ""
