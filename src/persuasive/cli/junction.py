"""``persuasive junction``: the AV among N vehicles at a four-way unsignalised junction.

Seeds of one junction (``persuasive.many``): each seed's run with the AV and the same seed
without it (the delay the AV causes), on worker processes; one row per seed and the study's
summary (or one JSON object). ``--out`` writes ``runs.parquet`` (one row per seed),
``summary.json`` and ``summary.md``; ``--plot`` draws the first seed's run from above,
``--video`` makes a video of it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import click

from .._compile import StudyClock
from .._files import check_output_file, check_replaceable_folder, json_safe
from ..config import AV_KINDS
from ..many.junction import ARMS, MOVEMENTS, VARIANTS, JunctionSpec
from ._common import (Count, check_workers, compile_report, config_options,
                      junction_compile_notice, lock_output, progress_bar, shield_option,
                      workers_type)

#: The files ``--out`` writes: with --force these are replaced and every other file is kept.
OUT_FILES = ("runs.parquet", "summary.json", "summary.md")


def _num(value, digits: int = 2) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) \
        else f"{value:.{digits}f}"


def summary_lines(agg: dict) -> list[str]:
    """The study's summary as Markdown rows."""
    head = ("| vehicles | runs | AV through | AV first (conflicts) | AV-caused collisions | "
            "uncertified steps | "
            "deadlocks (AV in) | human collisions | AV delay [s] | delay caused [s] | "
            "throughput [veh/h] | min PET AV [s] | min gap AV [m] | step ms median / p99 |")
    return [head, "|" + "---|" * head.count(" | ") + "---|",
            f"| {agg['n_vehicles']} | {agg['runs']} | {agg['av_through_pct']:.1f} % | "
            f"{agg['av_first_pct']:.1f} % ({agg['av_conflicts_passed']}) | "
            f"{agg['av_caused_collisions']} | {agg['uncertified_steps']} | "
            f"{agg['deadlock_runs']} ({agg['av_in_deadlock_runs']}) | "
            f"{agg['human_collisions']} | {_num(agg['mean_av_delay_s'])} | "
            f"{_num(agg['mean_caused_delay_s'])} | {_num(agg['median_throughput_veh_h'], 0)} | "
            f"{_num(agg['min_pet_av_s'])} | {_num(agg['min_gap_av_m'])} | "
            f"{_num(agg['step_ms_median'], 3)} / {_num(agg['step_ms_p99'], 3)} |"]


_SPEC = JunctionSpec()  # the defaults the help names


@click.command()
@click.option("--vehicles", type=Count(1, 64), default=None,
              help=f"Vehicles in each run, the AV included [{_SPEC.n_vehicles}].")
@click.option("--variant", type=click.Choice(list(VARIANTS)), default=None,
              help="major: the east-west road has priority; all-way: first come; "
                   "right-before-left; left-heavy: first come, 60 % left turns [major].")
@click.option("--lanes", type=Count(1, 2), default=None,
              help=f"Lanes per direction on every arm [{_SPEC.lanes}].")
@click.option("--hv", "hv_kinds", default=None, metavar="KIND[:SHARE],..",
              help="The humans' kinds and shares, e.g. lfg:0.8,aggressive:0.2 [lfg].")
@click.option("--opponents", type=click.Choice(["next", "all"]), default=None,
              help="Whom each human plays its pair game against: the vehicle it conflicts "
                   f"with next, or every one within reach [{_SPEC.opponents}].")
@click.option("--arrival", type=click.Choice(["placed", "poisson"]), default=None,
              help="placed: every human on the road at the start, queued in its lane; "
                   "poisson: a Poisson flow of --flow vehicles per hour on each arm "
                   f"[{_SPEC.arrival}].")
@click.option("--flow", "flow_veh_h", type=click.FloatRange(1.0, 3600.0), default=None,
              help=f"Vehicles per hour on each arm (--arrival poisson) [{_SPEC.flow_veh_h:g}].")
@click.option("--av-arrival", "av_arrival_s", type=click.FloatRange(0.0, 3600.0), default=None,
              help="When the AV enters its approach, into the flow [s] (--arrival poisson) "
                   f"[{_SPEC.av_arrival_s:g}].")
@click.option("--av-arm", type=click.Choice(list(ARMS)), default=None,
              help=f"The arm the AV comes from [{ARMS[_SPEC.av_arm]}].")
@click.option("--av-movement", type=click.Choice(list(MOVEMENTS)), default=None,
              help=f"The AV's movement [{_SPEC.av_movement}].")
@click.option("--duration", "duration_s", type=click.FloatRange(1.0, 3600.0), default=None,
              help=f"Run length [s] [{_SPEC.duration_s:g}].")
@click.option("--seeds", type=Count(1, 100_000), default=20, show_default=True,
              help="Seeds SEED .. SEED + SEEDS - 1.")
@click.option("--seed", type=Count(0, 2**31 - 2), default=1, show_default=True,
              help="First seed.")
@click.option("--workers", type=workers_type(), default=None,
              help="Worker processes [all cores].")
@click.option("--av", "av_kind", type=click.Choice(list(AV_KINDS)), default=None,
              help="The AV's planner (one per conflicting human) [persuasive].")
@shield_option
@config_options
@click.option("--out", type=click.Path(file_okay=False), default=None,
              help="Write " + ", ".join(OUT_FILES) + " to this folder.")
@click.option("--force", is_flag=True,
              help="Replace this command's own files in --out (" + ", ".join(OUT_FILES)
                   + "); other files are kept.")
@click.option("--plot", type=click.Path(dir_okay=False), default=None,
              help="Draw the first seed's run from above (PNG, PDF or SVG).")
@click.option("--video", type=click.Path(dir_okay=False), default=None,
              help="The first seed's run as a video, one frame per step (MP4 or GIF).")
@click.option("--json", "as_json", is_flag=True, help="Print the rows and summary as JSON.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def junction(vehicles, variant, lanes, hv_kinds, opponents, arrival, flow_veh_h, av_arrival_s,
             av_arm, av_movement, duration_s, seeds, seed, workers, av_kind, shield, mode,
             config_file, sets, out, force, plot, video, as_json, quiet):
    """The AV among N vehicles at a four-way unsignalised junction (docs/guide/junction.md).

    The AV drives as the outside-simulator adapters do (one planner per conflicting human, the
    lowest acceleration, one shield over every conflict); each human plays its own pair game
    against the vehicle it conflicts with next and follows the car ahead
    (docs/method.md §15). Each option sets a field of the configuration's [junction] section
    (--config, --set junction.FIELD=VALUE); corrected mode unless a mode is given."""
    from ..many.study import aggregate, run_study
    from ._common import build_config, mode_given

    explicit = {"scenario.kind": "junction", "av.shield": shield, "av.kind": av_kind,
                "junction.n_vehicles": vehicles, "junction.variant": variant,
                "junction.lanes": lanes, "junction.hv_kinds": hv_kinds,
                "junction.opponents": opponents, "junction.arrival": arrival,
                "junction.flow_veh_h": flow_veh_h, "junction.av_arrival_s": av_arrival_s,
                "junction.av_arm": av_arm, "junction.av_movement": av_movement,
                "junction.duration_s": duration_s}
    if not mode_given({"mode": mode, "sets": sets, "config_file": config_file}):
        explicit["mode"] = "corrected"
    else:
        explicit["mode"] = mode
    config = build_config(config_file, sets, explicit)
    spec = config.junction_spec
    variant = config.junction.variant or "major"
    hv_kinds = ",".join(k if len(spec.hv_kinds) == 1 else f"{k}:{w:g}"
                        for k, w in spec.hv_kinds)
    opponents, arrival, flow_veh_h = spec.opponents, spec.arrival, spec.flow_veh_h
    av_arm, av_movement, duration_s, lanes = (ARMS[spec.av_arm], spec.av_movement,
                                              spec.duration_s, spec.lanes)
    if plot:
        check_output_file(plot, (".png", ".pdf", ".svg"), "--plot")
    if video:
        from ..plots.files import check_animation_path

        check_animation_path(video)
    if out:
        path = check_replaceable_folder(out, force, owned=OUT_FILES)
        lock_output(path, "results folder")
    n_workers = check_workers(workers, seeds)
    seeds_ = range(seed, seed + seeds)
    junction_compile_notice()
    clock = StudyClock()
    bar = progress_bar(quiet)
    try:
        rows, step_ms = run_study(config, spec, seeds_, n_workers, bar)
    finally:
        if bar is not None:
            bar.close()
    compile_report(clock)
    agg = aggregate(rows, step_ms)
    agg.update({"variant": variant, "lanes": lanes, "hv": hv_kinds, "opponents": opponents,
                "arrival": arrival, "flow_veh_h": flow_veh_h, "av_arm": av_arm,
                "av_movement": av_movement, "duration_s": duration_s,
                "seeds": [seed, seed + seeds - 1], "workers": n_workers,
                "shield": config.shield, "mode": config.mode})
    if out:
        _write(out, rows, agg)
    if plot or video:
        from ..many.world import JunctionWorld
        from ..plots import junction as draw

        first = JunctionWorld(config, spec, seed).run()
        if plot:
            draw.topview(first, plot)
        if video:
            draw.video(first, video)
    if as_json:
        click.echo(json.dumps(json_safe({"summary": agg, "runs": rows}), allow_nan=False))
        return
    click.echo(f"junction ({variant}, {lanes} lane(s), humans {hv_kinds} playing "
               f"{opponents}): the AV from the "
               f"{av_arm} goes {av_movement}; {config.av.kind} AV, shield {config.shield}; "
               f"seeds {seed}..{seed + seeds - 1}, {duration_s:g}-s runs")
    for line in summary_lines(agg):
        click.echo(line)
    click.echo("AV first: of the AV's crossings and merges both vehicles passed, the share it "
               "passed first (how many in parentheses); "
               "deadlocks: runs with a cycle of waiting vehicles that lasted 5 s (AV in: the "
               "AV was in it); delay caused: the humans' mean time to leave the box less "
               "the same seed without the AV")
    if out:
        click.echo(f"runs and summary written to {out}")
    if plot:
        click.echo(f"top view of seed {seed} written to {plot}")
    if video:
        click.echo(f"video of seed {seed} written to {video}")


def _write(out: str, rows: list[dict], agg: dict) -> None:
    import pandas as pd

    from .._files import atomic_folder

    with atomic_folder(out, owned=OUT_FILES) as tmp:
        pd.DataFrame(rows).to_parquet(Path(tmp) / "runs.parquet", index=False)
        (Path(tmp) / "summary.json").write_text(json.dumps(json_safe(agg), indent=2, allow_nan=False) + "\n")
        (Path(tmp) / "summary.md").write_text("\n".join(summary_lines(agg)) + "\n")


__all__ = ["junction", "summary_lines"]
