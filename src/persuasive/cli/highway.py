"""``persuasive highway``: the planner drives highway-env's ego at its intersection.

Episodes of highway-env's ``intersection-v2`` (``-v1`` where v2 is missing), each run twice
on the same seed: the ego driven by the planner (``persuasive.envs.highway``) and by
highway-env's own IDM driver; one table row per episode and driver, then a summary per driver
(or one JSON object). highway-env is imported inside the command (the ``highway`` extra).
"""

from __future__ import annotations

import json

import click

from ..config import AV_KIND_ALIASES, AV_KINDS, SHIELD_KINDS, ConfigError
from ._common import Count, compile_notice, kinds_text

#: Most episodes one command runs (each twice: about 5-10 s a pair on one core, so up to a
#: day): a slip of the keyboard (1e9) is refused instead of running for ever.
MAX_EPISODES = 10_000
#: Every episode's seed is below this, the last one's included (``envs.highway.run_highway``).
SEED_LIMIT = 2**31 - 1


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def _num(value, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


@click.command()
@click.option("--episodes", type=Count(1, MAX_EPISODES), default=5, show_default=True,
              help="Episodes, seeds SEED .. SEED + EPISODES - 1.")
@click.option("--planner", type=click.Choice([*AV_KINDS, *AV_KIND_ALIASES]),
              default="persuasive", show_default=True,
              help=f"The AV planner driving the ego (corrected mode): {kinds_text(AV_KINDS)}.")
@click.option("--seed", type=Count(0, SEED_LIMIT - 1), default=1, show_default=True,
              help="Seed of the first episode (highway-env's reset seed; the last, "
                   "SEED + EPISODES - 1, below 2^31 - 1).")
@click.option("--shield", type=click.Choice(list(SHIELD_KINDS)), default=None,
              help=f"Safety shield over every vehicle the ego can meet (docs/method.md §12): "
                   f"{kinds_text(SHIELD_KINDS)} [worst-case].")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--video", type=click.Path(dir_okay=False), default=None,
              help="Write the planner's first episode as .mp4 or .gif (the folder must exist).")
def highway(episodes, planner, seed, shield, as_json, video) -> None:
    """Drive highway-env's intersection ego with the planner, against its IDM traffic,
    beside highway-env's own ego driver on the same seeds.

    At most 10,000 episodes (each runs twice), and every seed below 2^31 - 1: a count or
    seed beyond is refused before highway-env is imported.
    """
    if seed + episodes > SEED_LIMIT:
        raise ConfigError(f"--seed = {seed} is out of range; allowed: integer in "
                          f"[0, {SEED_LIMIT - episodes}] for {episodes} episodes (every "
                          f"episode's seed below {SEED_LIMIT})")
    from ..envs.highway import (CONTEST_RANGE_M, DEFAULT_DRIVER, run_highway, write_video)

    if video:
        from ..plots.files import check_animation_path

        check_animation_path(video)  # before any work
    compile_notice()
    frames = [] if video else None
    report = run_highway(episodes, planner, seed, frames=frames, shield=shield)
    if video:
        write_video(frames, video)
    if as_json:
        out = report.to_dict()
        if video:
            out["video"] = video
        click.echo(json.dumps(out))
        return
    first, last = report.seeds[0], report.seeds[-1]
    click.echo(f"highway-env {report.env_id}: the ego goes straight (o0 -> o2) at 10 Hz; "
               f"{report.planner} planner (shield: {report.shield}) vs highway-env's IDM ego "
               f"({DEFAULT_DRIVER}); "
               f"seeds {first}..{last}")
    head = (f"{'seed':>6}  {'driver':<11}{'collision':<11}{'crossed':<9}{'arrived':<9}"
            f"{'first':<7}{'ego/other':<11}{'time to cross [s]':>18}{'min dist [m]':>14}"
            f"{'min conflict dist [m]':>23}")
    click.echo(head)
    for e in report.episodes:
        click.echo(f"{e.seed:>6}  {e.driver:<11}{_yes(e.collision):<11}{_yes(e.crossed):<9}"
                   f"{_yes(e.arrived):<9}{e.first:<7}{f'{e.ego_first}/{e.other_first}':<11}"
                   f"{_num(e.time_to_cross_s, 1):>18}{_num(e.min_distance_m):>14}"
                   f"{_num(e.min_conflict_distance_m):>23}")
    click.echo("")
    click.echo(f"{'driver':<11}{'episodes':>9}{'collisions':>11}{'crossed':>9}{'arrived':>9}"
               f"{'ego first':>10}{'other first':>12}{'mean time to cross [s]':>24}"
               f"{'min dist [m]':>14}{'median min conflict dist [m]':>30}"
               f"{'shield interventions':>22}")
    for driver, s in report.summary().items():
        click.echo(f"{driver:<11}{s['episodes']:>9}{s['collisions']:>11}{s['crossed']:>9}"
                   f"{s['arrived']:>9}{s['ego_first']:>10}{s['other_first']:>12}"
                   f"{_num(s['mean_time_to_cross_s'], 2):>24}{_num(s['min_distance_m']):>14}"
                   f"{_num(s['median_min_conflict_distance_m']):>30}"
                   f"{s['shield_interventions']:>22}")
    click.echo(f"first: who reached the conflict point first against the vehicles that were "
               f"within {CONTEST_RANGE_M:g} m of it with the ego; min dist: to any vehicle "
               f"(oncoming traffic passes 4 m beside); min conflict dist: to vehicles whose "
               f"lanes enter the ego's path or share its lane")
    for driver, s in report.summary().items():  # the envelope the shield assumed (docs §12.7)
        kinds = ", ".join(f"{k} {n}" for k, n in s["envelope_excess_kinds"].items() if n)
        click.echo(f"guarantee ({driver}): held whole in {s['guarantee_held_episodes']} of "
                   f"{s['episodes']} episodes; {s['uncertified_steps']} uncertified steps; "
                   f"{s['envelope_excesses']} vehicle-steps of other vehicles outside the "
                   f"envelope the shield assumes"
                   + (f" ({kinds}; largest {s['max_envelope_excess_mps']:.2f} m/s)"
                      if kinds else "")
                   + f"; {s['crash_stops']} vehicle-steps of crash stops between other "
                     f"vehicles in {s['crash_stop_episodes']} episodes (outside the guarantee)"
                   + f"; {s['wrecks']} other vehicles wrecked in crashes not the ego's, in "
                     f"{s['wreck_episodes']} episodes (outside the guarantee)")
    for driver, s in report.summary().items():
        cost = "" if driver == DEFAULT_DRIVER else (
            f"; the shield's overrides cost {_num(s['override_mps2_mean'], 3)} m/s^2 per step "
            f"(mean |applied - proposed|)")
        click.echo(f"time to cross ({driver}): restricted mean "
                   f"{_num(s['restricted_mean_time_to_cross_s'], 2)} s over all episodes (one "
                   f"that never crossed counts the episode's length){cost}")
    for driver, s in report.summary().items():  # the ceiling: the shield judging the default
        if "entries_judged" in s:
            click.echo(f"ceiling ({driver}, judged by the {report.shield} shield it does not "
                       f"use): the shield would admit {s['entries_admitted']} of the "
                       f"{s['entries_judged']} steps that took its ego into the junction, and "
                       f"{s['steps_admitted_pct']:.1f} % of all its steps")
    for driver, s in report.summary().items():  # the rule's fault (docs/method.md §12.13)
        if "collisions_ego_at_fault" in s:
            click.echo(f"responsibility rule ({driver}): {s['collisions_ego_at_fault']} "
                       f"collisions at the ego's fault, {s['collisions_other_at_fault']} at "
                       f"the other's, {s['collisions_wreck_at_fault']} into a wreck "
                       f"without a certified answer; {s['duty_breaches']} vehicle-steps in "
                       f"which another vehicle broke its duty (the guarantee assumes none)")
    if video:
        click.echo(f"video of seed {first} ({report.planner}) written to {video}")
