"""How much of highway-env's own driving a shield admits, and what holds the worst case back
(issue 25 item 4: "measure the ceilings before you tune"; docs/results.md §15.16).

    python benchmarks/highway_ceiling.py [--episodes 20] [--seed 1]
                                         [--variants as-is,exact,no-stand-ins,u-max-3,responsive]
                                         [--full-throttle worst-case,responsive]

Drives highway-env's own ego (``persuasive highway``'s ``default`` driver) on seeds
``SEED .. SEED + EPISODES - 1`` and judges every step it drove by a shield it does not use
(``persuasive.envs.highway.DefaultJudge``): the step that took it into the junction admitted
or not, and the share of all its steps admitted. A planner behind that shield cannot enter
where the shield refuses, so the admitted entries bound how often it can cross in the same
traffic. The variants change one assumption each:

- ``as-is``: the worst-case shield as ``persuasive highway`` applies it (the planner's limits,
  highway-env's Euler lead, the stand-ins for the vehicles not spawned yet);
- ``exact``: no Euler lead, as if the ego moved by the exact kinematics (the
  enter-then-follow fallback then joins where a lane is shared; the ego's occupancy keeps its
  widening for the Euler lag; not what highway-env does: a what-if of the fallback family);
- ``no-stand-ins``: without the stand-ins (not safe once a vehicle spawns: a what-if of their
  cost);
- ``u-max-3``: the ego's ``u_max`` 3 m/s^2 instead of the paper's 1 (highway-env's own cars'
  ``COMFORT_ACC_MAX``);
- ``responsive``: the ``responsive`` shield (any other driver brakes after a fixed time).

Prints, per variant, entries admitted of entries judged and the steps admitted.

``--full-throttle SHIELDS`` (comma-separated shield kinds; empty: none) adds a second table:
the ego driven through ``persuasive highway``'s adapter and shield on the same seeds, but
proposing full throttle at every step (``u_max``, capped by the IDM gap to a leader on its
own lane, as the planner's proposal is) instead of planning: the shield alone decides when it
enters. Crossings, collisions and uncertified steps, beside what the planner does behind the
same shield, tell whether the planner or the shield holds the ego back.
"""

from __future__ import annotations

import argparse
import time

VARIANTS = ("as-is", "exact", "no-stand-ins", "u-max-3", "responsive")


def judge_of(variant: str):
    """The judge class of ``variant`` (module docstring)."""
    from persuasive.envs.highway import DefaultJudge

    if variant == "exact":
        class Exact(DefaultJudge):
            def lead(self, v, first):
                return 0.0
        return Exact
    if variant == "no-stand-ins":
        class NoStandIns(DefaultJudge):
            def make_stand_ins(self, env):
                return []
        return NoStandIns
    return DefaultJudge


def full_throttle_class():
    """The adapter whose every per-vehicle proposal is full throttle (module docstring)."""
    from persuasive.envs.external import ExternalPlanner

    class FullThrottle(ExternalPlanner):
        class _Throttle:
            def __init__(self, u_max: float):
                self.u_max = u_max

            def accel(self, ego, other) -> float:
                return self.u_max

        def planner_for(self, key):
            return self._Throttle(self.ego.u_max_mps2)

    return FullThrottle


def config_of(variant: str):
    from persuasive.envs.highway import planner_config

    if variant == "responsive":
        return planner_config("persuasive", "responsive")
    config = planner_config("persuasive", "worst-case")
    if variant == "u-max-3":
        config = config.with_overrides({"av.vehicle.u_max_mps2": 3.0})
    return config


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--full-throttle", default="",
                    help="shield kinds to drive the full-throttle ego behind (comma-separated)")
    args = ap.parse_args()
    variants = [v for v in args.variants.split(",") if v]
    for v in variants:
        if v not in VARIANTS:
            raise SystemExit(f"--variants: {v!r} is not one of {', '.join(VARIANTS)}")
    from persuasive.config import SHIELD_KINDS
    from persuasive.envs.highway import DEFAULT_DRIVER, planner_config, run_episode

    shields = [k for k in args.full_throttle.split(",") if k]
    for k in shields:
        if k not in SHIELD_KINDS or k == "off":
            raise SystemExit(f"--full-throttle: {k!r} is not one of "
                             f"{', '.join(x for x in SHIELD_KINDS if x != 'off')}")

    seeds = range(args.seed, args.seed + args.episodes)
    if variants:
        print(f"highway-env's own ego, seeds {seeds.start}..{seeds.stop - 1}, judged by a "
              "shield it does not use")
        print("| variant | crossed | entries admitted | steps admitted % | wall s |")
        print("|---|---|---|---|---|")
    for variant in variants:
        t0 = time.perf_counter()
        config, judge = config_of(variant), judge_of(variant)
        eps = [run_episode(s, DEFAULT_DRIVER, config, judge_class=judge) for s in seeds]
        entries = [e for e in eps if e.entry_admitted is not None]
        steps = sum(e.judged_steps for e in eps)
        print(f"| {variant} | {sum(e.crossed for e in eps)} of {len(eps)} | "
              f"{sum(e.entry_admitted for e in entries)} of {len(entries)} | "
              f"{100.0 * sum(e.judged_admitted for e in eps) / max(1, steps):.1f} | "
              f"{time.perf_counter() - t0:.0f} |", flush=True)
    if shields:
        print(f"\nThe ego behind the shield, seeds {seeds.start}..{seeds.stop - 1}: the planner "
              "and a proposer that always asks for full throttle")
        print("| shield | proposer | crossed | collisions | uncertified steps | wall s |")
        print("|---|---|---|---|---|---|")
        throttle = full_throttle_class()
    for shield in shields:
        config = planner_config("persuasive", shield)
        for name, cls in (("planner", None), ("full throttle", throttle)):
            t0 = time.perf_counter()
            eps = [run_episode(s, "persuasive", config, planner_class=cls) for s in seeds]
            print(f"| {shield} | {name} | {sum(e.crossed for e in eps)} of {len(eps)} | "
                  f"{sum(e.collision for e in eps)} | {sum(e.uncertified_steps for e in eps)} | "
                  f"{time.perf_counter() - t0:.0f} |", flush=True)


if __name__ == "__main__":
    main()
