"""Scripted participants drive the built-in ``drive`` study, recorded as ``drive`` records.

    python examples/scripted_participant.py [--participants 4] [--out results/drive-scripted]
                                            [--p-a 0.2,0.5,0.8,1.0] [--role leader]

Each participant thinks like the paper's human (an LFG player with a role, a belief about the
AV and a willingness ``p_a`` to change role; participant ``i`` takes the ``i``-th value of
``--p-a``, cyclically) but drives with the arrow keys, a step late: it
holds ArrowUp when its LFG acceleration of the step before was above 0.3 m/s^2, ArrowDown when
below -0.6 m/s^2, and nothing otherwise (coasting). The trials go through the ``drive`` page's
own :class:`persuasive.web.session.Trial` (the built-in study's practice and its four
conditions, in each participant's Latin-square order), so the files are those a person at the
page leaves: ``P01-t00-practice.parquet``, ``P01-t01-<condition>.parquet``, ... Fit them with

    persuasive fit results/drive-scripted/*.parquet --per-participant
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from persuasive.policies import CompiledPolicy, Context, Observation
from persuasive.policies import kinds as kd
from persuasive.web.human import HumanInput
from persuasive.web.session import Trial
from persuasive.web.study import default_study

UP_ABOVE, DOWN_BELOW = 0.3, -0.6  #: the LFG accelerations [m/s^2] that press a key


def drive_trial(trial: Trial, p_a: float, role: str, rng: np.random.Generator) -> None:
    """Drive one trial with the keys of an LFG mind (see the module docstring)."""
    trial.build()
    world = trial.world
    s = world.setup
    mind_config = trial.config.with_overrides({"hv.kind": "lfg", "roles.p_a": p_a,
                                               "hv.role": role})
    mind = CompiledPolicy("lfg", kd.HV)
    mind.reset(Context(mind_config, s.scenario, s.P_av, s.P_hv, s.disc, kd.HV, trial.n,
                       rng.random((trial.n, 1)), world.games))
    last = 0.0
    for k in range(trial.n):
        x = world.x
        obs = Observation(k, k * trial.dt, (float(x[0]), float(x[1])),
                          (float(x[2]), float(x[3])))
        obs.game = world.games(obs.av, obs.hv)
        trial.human.input = HumanInput(up=last > UP_ABOVE, down=last < DOWN_BELOW,
                                       source="keyboard", received_s=time.monotonic())
        world.step()
        last = mind.act(obs)  # pressed at the next step: a step's reaction time
    trial.save(complete=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--participants", type=int, default=4)
    ap.add_argument("--out", default="results/drive-scripted")
    ap.add_argument("--p-a", default="0.2,0.5,0.8,1.0",
                    help="p_a of each participant, comma-separated, used cyclically")
    ap.add_argument("--role", choices=("leader", "follower"), default="leader")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    study = default_study()
    p_values = [float(v) for v in args.p_a.split(",")]
    for i in range(1, args.participants + 1):
        p_a = p_values[(i - 1) % len(p_values)]
        participant = f"P{i:02d}"
        _, order = study.order_for(participant)
        plan = [(study.practice, True)] + [(c, False) for c in order]
        rng = np.random.default_rng(i)
        for index, (condition, practice) in enumerate(plan):
            trial = Trial(index, condition, practice, participant, out, index + 1, len(plan))
            drive_trial(trial, p_a, args.role, rng)
        print(f"{participant} (p_a = {p_a:g}): {len(plan)} trials in {out}")


if __name__ == "__main__":
    main()
