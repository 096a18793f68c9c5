"""The planner plus the shield per step in SUMO, two source trees in one run.

    python benchmarks/ab_sumo_step.py OLD_SRC NEW_SRC [--scenario intersection] [--flow 900]
        [--ignore-foes 0.3] [--seeds 1,2,4] [--rounds 5]

OLD_SRC and NEW_SRC are ``src`` folders (e.g. ``git archive`` of the previous commit unpacked,
and this checkout's ``src``). The episodes are run once in SUMO with NEW_SRC's shielded
planner (``persuasive/worst-case``), recording what every planner step is handed (the ego and
every SUMO vehicle, as ``persuasive sumo`` reads them from libsumo). Each round then replays
the recording in a fresh process for each tree, in alternating order so that both see the
same machine load: per episode a fresh ``ExternalPlanner``, and per step what that tree's
``persuasive sumo`` times (the projection, ``conflicts_of``, and ``ExternalPlanner.act``; in a
tree that has them, ``decide`` with the stand-ins for vehicles not inserted yet, which do not
count as in view). The replay counts the decisions (acceleration and verdict) that differ from
the recorded ones (0 when the two trees decide alike). Prints, per tree, the median over the
rounds of the per-step median over all steps and over the steps with 10 or more vehicles in
view. Needs the ``sumo`` extra.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

RECORD = r"""
import os, pickle, sys
from dataclasses import astuple
from persuasive.envs import sumo as S
scenario, flow, ignore, seeds, out = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), \
    [int(s) for s in sys.argv[4].split(",")], sys.argv[5]
net = S.build_network(S.NETWORKS[scenario], os.path.dirname(out))
# what the planner is handed once per step: decide(planner, projector, ego, others, ...)
# in a tree that has it, else conflicts_of(projector, ego, others, ...)
target = "decide" if hasattr(S, "decide") else "conflicts_of"
real, episodes = getattr(S, target), []

def plain(v):
    return (*astuple(v)[:-1], astuple(v.limits))

def spy(*args):
    ego, others = args[1:3] if target == "conflicts_of" else args[2:4]
    steps.append((plain(ego), [plain(o) for o in others
                               if not str(o.vehicle).startswith("entry:")]))
    return real(*args)

setattr(S, target, spy)
for seed in seeds:
    steps = []
    o = S.run_episode(scenario, seed, "persuasive/worst-case", flow, ignore, net, logs=True)
    episodes.append({"seed": seed, "steps": steps, "accel": o.decisions["accel_mps2"],
                     "verdict": o.decisions["verdict"]})
with open(out, "wb") as fh:
    pickle.dump({"scenario": scenario, "net": net.read_text(), "episodes": episodes}, fh)
"""

REPLAY = r"""
import json, pickle, sys, time
import xml.etree.ElementTree as ET
import numpy as np
from persuasive.envs import external as X
from persuasive.envs import sumo as S
with open(sys.argv[1], "rb") as fh:
    data = pickle.load(fh)
scenario = data["scenario"]
root = ET.fromstring(data["net"])
shapes, lengths, links = {}, {}, {}
for lane in root.iter("lane"):
    shapes[lane.get("id")] = [tuple(map(float, p.split(","))) for p in lane.get("shape").split()]
    lengths[lane.get("id")] = float(lane.get("length"))
for c in root.iter("connection"):  # libsumo's getLinks rows: (to lane, ..., via lane, ...)
    links.setdefault(f'{c.get("from")}_{c.get("fromLane")}', []).append(
        (f'{c.get("to")}_{c.get("toLane")}', True, True, True, c.get("via") or "", "M", "s", 0.0))

def state(t):
    return S.VehicleState(t[0], tuple(t[1]), *t[2:-1], X.Limits(*t[-1]))

cfg = S.planner_config("persuasive", "worst-case", scenario)
ego_limits = X.Limits.of(cfg, "av")
rows, differ = [], 0
for ep in data["episodes"]:
    steps = [(state(e), [state(o) for o in others]) for e, others in ep["steps"]]
    projector = S.Projector(S.NETWORKS[scenario].ego_route,
                            (ego_limits.length_m, ego_limits.width_m),
                            lambda ln: links.get(ln, []), shapes.__getitem__, lengths.__getitem__)
    planner = S.ExternalPlanner(cfg, ep["seed"], plan_horizon_s=S.horizon_s(cfg))
    clear, slack = planner._clear_m, S.ballistic_slack(ego_limits)
    entries = []
    if hasattr(S, "entry_vehicles"):  # a tree with the stand-ins for vehicles not inserted
        entries = S.entry_vehicles(S.NETWORKS[scenario], X.Limits(
            S.HUMAN_TYPE["length"], S.HUMAN_TYPE["width"], -S.HUMAN_TYPE["emergencyDecel"],
            S.HUMAN_TYPE["accel"], 0.0, S.HUMAN_TYPE["maxSpeed"]))
    for ego, others in steps:  # the routes' geometry, built once per route in an episode too
        S.conflicts_of(projector, ego, others + entries, clear, slack)
    for k, (ego, others) in enumerate(steps):
        t0 = time.perf_counter()
        if hasattr(S, "decide"):  # what this tree's run_episode times
            d, conflicts = S.decide(planner, projector, ego, others + entries, clear, slack)
        else:
            conflicts = S.conflicts_of(projector, ego, others, clear, slack)
            d = planner.act(ego.speed_mps, conflicts, S.DT_S)
        ms = 1e3 * (time.perf_counter() - t0)
        rows.append((sum(not str(c.key).startswith("entry:") for c in conflicts), ms))
        differ += (d.accel_mps2 != ep["accel"][k]) or ((d.verdict or "") != ep["verdict"][k])
a = np.array(rows)
ten = a[a[:, 0] >= 10, 1]
print(json.dumps({"ms_median": float(np.median(a[:, 1])), "steps": len(a),
                  "ms_median_10_in_view": float(np.median(ten)) if len(ten) else None,
                  "steps_10_in_view": int(len(ten)), "decisions_differ": int(differ)}))
"""


def _python(src: str, code: str, *args: str) -> str:
    env = dict(os.environ, PYTHONPATH=os.path.abspath(src))
    out = subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True,
                         text=True, check=True)
    return out.stdout.strip().splitlines()[-1] if out.stdout.strip() else ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old_src")
    parser.add_argument("new_src")
    parser.add_argument("--scenario", default="intersection")
    parser.add_argument("--flow", type=float, default=900.0)
    parser.add_argument("--ignore-foes", type=float, default=0.3)
    parser.add_argument("--seeds", default="1,2,4")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="persuasive-sumo-ab-") as tmp:
        rec = os.path.join(tmp, "steps.pkl")
        _python(args.new_src, RECORD, args.scenario, str(args.flow), str(args.ignore_foes),
                args.seeds, rec)
        _python(args.old_src, REPLAY, rec)  # compile and cache the old tree's kernels
        results: dict[str, list[dict]] = {"old": [], "new": []}
        for i in range(args.rounds):
            for name in (("old", "new") if i % 2 == 0 else ("new", "old")):
                results[name].append(json.loads(_python(getattr(args, f"{name}_src"), REPLAY,
                                                        rec)))
    first = results["new"][0]
    print(f"{args.scenario}, {args.flow:g} veh/h, ignore foes {args.ignore_foes:g}, seeds "
          f"{args.seeds}: {first['steps']} steps, {first['steps_10_in_view']} with 10 or more "
          f"vehicles in view; medians over {args.rounds} rounds [ms]")
    summary = {}
    for name in ("old", "new"):
        rs = results[name]
        summary[name] = {
            "ms_median": statistics.median(r["ms_median"] for r in rs),
            "ms_median_10_in_view": statistics.median(r["ms_median_10_in_view"] for r in rs)
            if rs[0]["ms_median_10_in_view"] is not None else None,
            "decisions_differ": max(r["decisions_differ"] for r in rs)}
        s = summary[name]
        ten = "-" if s["ms_median_10_in_view"] is None else f"{s['ms_median_10_in_view']:.3f}"
        print(f"{name}: all steps {s['ms_median']:.3f}, 10+ in view {ten}; decisions that "
              f"differ from the recording: {s['decisions_differ']}")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
