"""The shield over random configurations: does any AV-caused collision or uncertified step happen?

    python benchmarks/explore_configs.py [--configs 1000] [--seed 1]
    python benchmarks/explore_configs.py --set KEY=VALUE [--set ...] [--seeds 1000]

Draws ``--configs`` random configurations in corrected mode with the worst-case shield: a
scenario kind (with a random crossing or merge angle, or left-turn radius), an AV kind, a human
kind that tests the shield (adversary, random, aggressive, deceptive, idm, lfg), the vehicles'
length, width and safety factor, both vehicles' nominal start and the AV's start half-widths,
and, each with probability 1/2, a yield line, a clearance, acceleration noise, and the
vehicles' speed and acceleration limits with the step ``dt``;
runs one seed of each for 150 steps, and prints how many ran and how many were refused (a clear
``ConfigError`` or no admissible initial state), then every run with an AV-caused collision or an
uncertified step, with its overrides and seed, so that it can be run again with ``persuasive
simulate --set ...``. Exits 1 when there is an AV-caused collision. (An exploration that
pointed at holes, not the falsifier that issue 24 asks for: the draws are uniform, not steered.)
With ``--set``, one configuration over seeds 1..``--seeds`` instead: how many drew a start and
how many of those had an AV-caused collision or an uncertified step.
"""

from __future__ import annotations

import argparse
import random
import sys
from collections import Counter

from persuasive.config import Config, ConfigError
from persuasive.scenarios import InitialStateError
from persuasive.simulation import simulate

AV_KINDS = ("persuasive", "passive", "cv", "lfg", "yield")
HUMANS = ("adversary", "random", "aggressive", "deceptive", "idm", "lfg")


def draw(rng: random.Random) -> dict:
    """One random configuration's overrides."""
    kind = rng.choice(["intersection", "crossing", "left-turn", "merge"])
    over = {"scenario.kind": kind, "av.shield": "worst-case", "av.kind": rng.choice(AV_KINDS),
            "hv.kind": rng.choice(HUMANS), "vehicle.safety_factor": rng.uniform(0.5, 2.5),
            "vehicle.length_m": rng.uniform(3.5, 6.0), "vehicle.width_m": rng.uniform(1.5, 2.2),
            "scenario.av_s0_halfwidth_m": rng.uniform(0.0, 6.0),
            "scenario.av_v0_halfwidth_mps": rng.uniform(0.0, 2.0), "simulation.n_steps": 150,
            "scenario.av_s0_m": rng.uniform(-35.0, -8.0), "scenario.av_v0_mps": rng.uniform(0, 8),
            "scenario.hv_s0_m": rng.uniform(-35.0, -8.0), "scenario.hv_v0_mps": rng.uniform(0, 8)}
    if kind == "crossing":
        over["scenario.angle_deg"] = rng.uniform(15.0, 165.0)
    elif kind == "merge":
        over["scenario.angle_deg"] = rng.uniform(15.0, 90.0)
    elif kind == "left-turn":
        over["scenario.turn_radius_m"] = rng.uniform(4.0, 90.0)
    # as tests/test_shield_configs.py draws them: each of these with probability 1/2
    if rng.random() < 0.5:
        over["av.yield_line_m"] = rng.uniform(0.0, 6.0)
    if rng.random() < 0.5:
        over["av.shield_margin_m"] = rng.uniform(0.0, 0.5)
    if rng.random() < 0.5:
        over["simulation.accel_noise_mps2"] = rng.uniform(0.0, 0.5)
    if rng.random() < 0.5:  # the vehicles' limits and the step
        over["vehicle.v_max_mps"] = rng.uniform(5.0, 20.0)
        over["vehicle.u_max_mps2"] = rng.uniform(0.5, 3.0)
        over["vehicle.u_min_mps2"] = rng.uniform(-6.0, -1.5)
        over["simulation.dt_s"] = over["library.sample_dt_s"] = rng.choice([0.05, 0.1, 0.2])
    return over


def one_configuration(settings: list[str], seeds: int) -> None:
    """Every seed 1..``seeds`` of one configuration (``--set KEY=VALUE``, values as TOML
    reads them, on corrected mode with the worst-case shield, 100 steps): how many could
    draw a start, and how many of those had an AV-caused collision or an uncertified step."""
    import tomllib

    over = {"av.shield": "worst-case", "simulation.n_steps": 100}
    for item in settings:
        key, _, value = item.partition("=")
        over[key] = tomllib.loads(f"v = {value}")["v"]
    config = Config(mode="corrected").with_overrides(over)
    ran = caused = uncertified = 0
    for seed in range(1, seeds + 1):
        try:
            o = simulate(config, seed).outcome
        except InitialStateError:
            continue
        ran += 1
        caused += o.collision_caused_by_av
        uncertified += o.uncertified_steps > 0
    print(f"seeds 1..{seeds}: {ran} drew a start; AV-caused collisions: {caused}, runs with "
          f"uncertified steps: {uncertified}")
    sys.exit(1 if caused else 0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="run this one configuration over seeds 1..--seeds instead")
    parser.add_argument("--seeds", type=int, default=1000)
    args = parser.parse_args()
    if args.set:
        one_configuration(args.set, args.seeds)
        return
    rng = random.Random(args.seed)
    ran = refused = 0
    found: Counter = Counter()
    for _ in range(args.configs):
        over = draw(rng)
        seed = rng.randrange(10_000)
        try:
            record = simulate(Config(mode="corrected").with_overrides(over), seed)
        except (ConfigError, InitialStateError):
            refused += 1
            continue
        ran += 1
        o = record.outcome
        if o.collision_caused_by_av or o.uncertified_steps:
            what = "AV-caused collision" if o.collision_caused_by_av else "uncertified"
            found[what] += 1
            print(f"{what}: seed {seed}, {o.uncertified_steps} uncertified steps, rear-end by "
                  f"the human: {o.rear_end_by_human}; "
                  + " ".join(f"--set {k}={v!r}" for k, v in over.items()), flush=True)
    print(f"{ran} ran, {refused} refused; AV-caused collisions: "
          f"{found['AV-caused collision']}, runs with uncertified steps: {found['uncertified']}")
    sys.exit(1 if found["AV-caused collision"] else 0)


if __name__ == "__main__":
    main()
