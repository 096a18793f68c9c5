"""``persuasive sumo``: the planner drives an ego vehicle in Eclipse SUMO.

Episodes of one SUMO scenario (``persuasive.envs.sumo``), each driven by the planner with every
shield asked for and by SUMO's own driver on the same seed, on worker processes; one table row
per driver (or one JSON object). ``--out`` writes the episodes, the per-step logs of every
vehicle, the planner's decisions, the network and the summary as one folder; ``--video`` draws
the planner's first episode from those logs. SUMO comes with the ``sumo`` extra.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import click

from .._compile import StudyClock
from .._files import check_replaceable_folder
from ..config import AV_KIND_ALIASES, AV_KINDS, SHIELD_KINDS
from ..envs.sumo import MAX_EPISODES, SCENARIOS
from ._common import (Count, check_workers, compile_notice, compile_report, kinds_text,
                      lock_output, progress_bar, workers_type)

#: The files ``--out`` writes: with --force these are replaced and every other file is kept.
OUT_FILES = ("episodes.parquet", "steps.parquet", "decisions.parquet", "net.nod.xml",
             "net.edg.xml", "net.net.xml", "summary.json", "summary.md")


def _num(value, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def summary_lines(report) -> list[str]:
    """The summary table of a :class:`~persuasive.envs.sumo.SumoReport`, as Markdown rows."""
    head = ("| driver | episodes | collision episodes | collisions (ego collider / junction) "
            "| crossed | mean time to cross [s] | min TTC [s] | min PET [s] | max DRAC "
            "[m/s^2] | time loss caused [s/episode] | shield overrides / uncertified "
            "| decide ms median (10+ in view) |")
    rows = [head, "|" + "---|" * head.count(" | ") + "---|"]
    for driver, s in report.summary().items():
        ten = (f"{_num(s['decide_ms_median'], 3)} ({_num(s['decide_ms_median_10_in_view'], 3)}"
               f", {s['decisions_10_in_view']} steps)" if s["decisions"] else "-")
        rows.append(
            f"| {driver} | {s['episodes']} | {s['collision_episodes']} | {s['collisions']} "
            f"({s['ego_collider']} / {s['junction_collisions']}) | {s['crossed']} | "
            f"{_num(s['mean_time_to_cross_s'])} | {_num(s['min_ttc_s'])} | "
            f"{_num(s['min_pet_s'])} | {_num(s['max_drac_mps2'])} | "
            f"{_num(s['mean_caused_time_loss_s'])} | "
            f"{s['shield_overrides']} / {s['uncertified']} | {ten} |")
    return rows


@click.command()
@click.option("--scenario", type=click.Choice(list(SCENARIOS)),
              default="intersection", show_default=True,
              help="intersection: cross a priority road; merge: a highway on-ramp.")
@click.option("--episodes", type=Count(1, MAX_EPISODES), default=10, show_default=True,
              help=f"Episodes, seeds SEED .. SEED + EPISODES - 1, at most {MAX_EPISODES}.")
@click.option("--seed", type=Count(0, 2**31 - 2), default=1, show_default=True,
              help="Seed of the first episode (SUMO's --seed, the traffic's and the planner's).")
@click.option("--planner", type=click.Choice([*AV_KINDS, *AV_KIND_ALIASES]),
              default="persuasive", show_default=True, help="The AV planner (corrected mode).")
@click.option("--shield", "shields", default="worst-case", show_default=True,
              help="Shields around the planner, comma-separated (each one is a driver): "
                   f"{kinds_text(SHIELD_KINDS)}.")
@click.option("--flow", type=float, default=300.0, show_default=True,
              help="SUMO traffic on each conflicting route [vehicles per hour], in (0, 3600].")
@click.option("--ignore-foes", type=float, default=0.0, show_default=True,
              help="Fraction of SUMO's vehicles that never yield (jmIgnoreFoeProb, "
                   "jmIgnoreJunctionFoeProb = 1), in [0, 1].")
@click.option("--workers", type=workers_type(), default=None,
              help="Worker processes, one SUMO each [all cores].")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--out", type=click.Path(file_okay=False), default=None,
              help="Write episodes, per-step logs and the summary into this folder (a new or "
                   "empty one; with --force, one holding an earlier run's results).")
@click.option("--force", is_flag=True,
              help="Replace this command's own earlier results in the --out folder ("
                   + ", ".join(OUT_FILES) + "); other files are kept.")
@click.option("--video", type=click.Path(dir_okay=False), default=None,
              help="Draw the planner's first episode as .mp4 or .gif (the folder must exist).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def sumo(scenario, episodes, seed, planner, shields, flow, ignore_foes, workers, as_json, out,
         force, video, quiet) -> None:
    """Drive an ego vehicle in Eclipse SUMO with the planner, against SUMO's own traffic,
    beside SUMO's own driver as the ego on the same seeds."""
    import shutil

    from ..envs import sumo as S
    from ..plots.files import check_animation_path

    shield_list = tuple(s.strip() for s in shields.split(",") if s.strip())
    S.check_study(scenario, episodes, seed, flow, ignore_foes, planner, shield_list, workers)
    if out:
        check_replaceable_folder(out, force, owned=OUT_FILES)
    if video:
        check_animation_path(video)
    for path, what in ((out, "results folder"), (video, "video")):
        if path:
            lock_output(path, what)
    S.sumo_binaries()  # the extra, before any work
    workers = check_workers(workers, episodes)
    compile_notice(*S.planner_kernels())
    progress = progress_bar(quiet, unit="seed")
    clock = StudyClock()
    try:
        report, outputs, folder = S.run_study(scenario, episodes, seed, flow, ignore_foes,
                                              planner, shield_list, workers,
                                              logs=bool(out or video), progress=progress)
    finally:
        if progress is not None:
            progress.close()  # type: ignore[attr-defined]
    # the study's own time: a first run's compile is said apart (compile_report)
    report = replace(report, wall_time_s=max(0.0, report.wall_time_s - clock.compile_s))
    try:
        if video:
            _video(report, outputs, folder, video)
        if out:
            _write(report, outputs, folder, out)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    compile_report(clock)
    if as_json:
        data = report.to_dict()
        data.update({"out": out, "video": video})
        click.echo(json.dumps(data))
        return
    n = len(report.seeds)
    seeds = f"seed {report.seeds[0]}" if n == 1 else f"seeds {report.seeds[0]}..{report.seeds[-1]}"
    click.echo(f"SUMO {scenario}: {n} episode{'s' if n != 1 else ''} ({seeds}), "
               f"{flow:g} veh/h per conflicting route, "
               f"{ignore_foes:g} ignoring foes; {report.workers} "
               f"worker{'s' if report.workers != 1 else ''}, "
               f"{report.wall_time_s:.1f} s")
    for line in summary_lines(report):
        click.echo(line)
    click.echo("collisions: SUMO's (junction collisions on, physical overlaps); TTC, PET, "
               "DRAC: SUMO's SSM device on the ego; time loss caused: SUMO's vehicles' time "
               "loss minus the same episode without the ego; decide ms: the planner plus the "
               "shield per step, median (over the steps with 10 or more vehicles in view)")
    if out:
        click.echo(f"results written to {out}")
    if video:
        click.echo(f"video of seed {report.seeds[0]} ({report.drivers[0]}) written to {video}")


def _video(report, outputs, folder: Path, path: str) -> None:
    from ..envs import sumo as S
    from ..plots.files import write_frames
    from ..plots.sumo import sumo_frames

    first = next(o for o in outputs if o.result.driver == report.drivers[0])
    frames = S.frames_of([first])["steps"]
    ego_t = frames.loc[frames["vehicle"] == "ego", "t_s"]
    if len(ego_t):  # from a second before the ego appears to a second after it leaves
        frames = frames[(frames["t_s"] >= ego_t.min() - 1.0) & (frames["t_s"] <= ego_t.max() + 1.0)]
    lanes = S.lane_shapes(folder / "net.net.xml")
    ego = S.planner_config(scenario=report.scenario).vehicle_of("av")
    sizes = {"ego": (ego.length_m, ego.width_m),
             "other": (S.HUMAN_TYPE["length"], S.HUMAN_TYPE["width"])}
    title = f"SUMO {report.scenario}, seed {first.result.seed}, {first.result.driver}"
    write_frames(sumo_frames(frames, lanes, sizes, title), path, int(round(1 / S.DT_S)))


def _write(report, outputs, folder: Path, out: str) -> None:
    import shutil

    import pandas as pd

    from .._files import atomic_folder
    from ..envs import sumo as S

    frames = S.frames_of(outputs)
    with atomic_folder(out, owned=OUT_FILES) as tmp:
        pd.DataFrame([e.to_dict() for e in report.episodes]).to_parquet(
            tmp / "episodes.parquet", index=False)
        frames["steps"].to_parquet(tmp / "steps.parquet", index=False)
        frames["decisions"].to_parquet(tmp / "decisions.parquet", index=False)
        for name in ("net.nod.xml", "net.edg.xml", "net.net.xml"):
            shutil.copyfile(folder / name, tmp / name)
        data = report.to_dict()
        del data["episodes"]
        (tmp / "summary.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
        (tmp / "summary.md").write_text("\n".join(summary_lines(report)) + "\n",
                                        encoding="utf-8")


__all__ = ["summary_lines", "sumo"]


