"""The online posterior over p_a: its learning curve over repeated interactions with one human
(docs/method.md §13.9; issue 19, item 3).

Corrected mode with its defaults (the worst-case shield, per-agent streams, epsilon = 0.02) at
the intersection. Each human is a seed ``s`` in ``1..--humans``: the paper's human (LFG,
``p_a = 1``, starting as leader) met ``--interactions`` times, interaction ``k`` from the
streams of ``persuasive.streams.interaction_seed(s, k)`` (``k = 0`` is the seed's own run).
Planners, on the same humans and the same initial states:

- ``online``: ``mpc.p_a_hat = "online"``, the Beta(7, 3) prior (mean 0.7) on 21 points, the
  posterior carried from one interaction to the next;
- ``informed``: ``p_a_hat = 1`` (knows the human);
- ``fixed 0.7``: ``p_a_hat = 0.7`` (the prior mean, never updated);
- ``fixed 0.95``: ``p_a_hat = 0.95``, the check of Table 2's effect (paper mode: 0 % AV first)
  in corrected mode.

The recklessness check runs ``online`` and ``fixed 0.7`` against a human with ``p_a = 0.3``
(leader start) and counts the runs and steps where the chance constraint failed, collisions,
safety violations (a distance below ``min_dist``, up to the line and over the whole run, as the
tables count them), the smallest distance and the shield's interventions; it compares the two
run by run (the same humans and initial states: which runs differ, and a bootstrap interval
over humans of the difference in failed steps). ``--settings reckless`` runs it alone, beside
the planner that knows ``p_a = 0.3`` and one fixed at 0.5, near where the online estimate ends.

Per interaction it reports the share of humans the AV was first with, the runs and steps where
the chance constraint failed, collisions, the mean posterior mean at the end (online), and the
*informative steps*: steps where the human's role is not its plausible role (the only steps
where it can change role, and so the only ones that say anything about p_a).

Resumable: each chunk of humans of each setting is one JSON file under ``--out/parts``; a
rerun skips the chunks already written. Prints a Markdown table and writes
``--out/summary.json`` and ``--out/summary.md``.

    python benchmarks/online_pa.py --humans 1000 --interactions 30 --workers 2 \\
        --out results/online-pa
    python benchmarks/online_pa.py --settings reckless --humans 3000 --interactions 30 \\
        --workers 2 --out results/online-pa-reckless
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

import numpy as np

#: The settings: name -> (human's p_a, configuration overrides of the AV).
SETTINGS = {
    "online": (1.0, {"mpc.p_a_hat": "online"}),
    "informed": (1.0, {"mpc.p_a_hat": 1.0}),
    "fixed 0.7": (1.0, {"mpc.p_a_hat": 0.7}),
    "fixed 0.95": (1.0, {"mpc.p_a_hat": 0.95}),
    "online, p_a = 0.3": (0.3, {"mpc.p_a_hat": "online"}),
    "fixed 0.7, p_a = 0.3": (0.3, {"mpc.p_a_hat": 0.7}),
    # a prior that already tries to persuade at epsilon = 0.02 (--settings extra)
    "online Beta(30, 1)": (1.0, {"mpc.p_a_hat": "online", "mpc.p_a_prior": [30, 1]}),
    "fixed 0.97": (1.0, {"mpc.p_a_hat": 0.97}),
    "online Beta(30, 1), p_a = 0.3": (0.3, {"mpc.p_a_hat": "online", "mpc.p_a_prior": [30, 1]}),
    "fixed 0.97, p_a = 0.3": (0.3, {"mpc.p_a_hat": 0.97}),
    # the planner that knows p_a = 0.3, and one fixed near where the online estimate ends
    "informed, p_a = 0.3": (0.3, {"mpc.p_a_hat": 0.3}),
    "fixed 0.5, p_a = 0.3": (0.3, {"mpc.p_a_hat": 0.5}),
}
#: The issue's settings (``--settings all``) and the extra ones (``--settings extra``).
MAIN = tuple(list(SETTINGS)[:6])
EXTRA = tuple(list(SETTINGS)[6:10])
#: The recklessness check on its own (``--settings reckless``), beside the planner that knows
#: ``p_a = 0.3`` and one fixed near the online estimate's end.
RECKLESS = ("online, p_a = 0.3", "fixed 0.7, p_a = 0.3", "informed, p_a = 0.3",
            "fixed 0.5, p_a = 0.3")
#: The pair the recklessness target compares (issue 19): the online planner against the fixed
#: planner at its prior mean.
PAIR = ("online, p_a = 0.3", "fixed 0.7, p_a = 0.3")
#: Interactions printed in the table (1-based).
SHOWN = (1, 2, 3, 5, 10, 20, 30)


def config_of(name: str):
    from persuasive import Config

    p_a, av = SETTINGS[name]
    return Config(mode="corrected").with_overrides(
        {"roles.p_a": p_a, "hv.role": "leader", "hv.kind": "lfg", **av})


def _informative(log) -> int:
    role = log["hv_role"]
    pl = log["hv_plausible_leader"]
    return int(np.sum(((role == "leader") & (pl == 0.0)) | ((role == "follower") & (pl == 1.0))))


def run_chunk(name: str, seeds: list[int], interactions: int) -> dict:
    """Every human of ``seeds`` under setting ``name``: per human, per interaction."""
    from persuasive.simulation import simulate_interactions

    config = config_of(name)
    out = {"setting": name, "seeds": seeds, "first_at_line": [], "infeasible_steps": [],
           "collision": [], "pa_hat_final": [], "informative_steps": [], "violation_line": [],
           "violation_run": [], "min_distance_m": [], "shield_interventions": []}
    for seed in seeds:
        recs = simulate_interactions(config, seed, interactions)
        out["first_at_line"].append([r.outcome.first_at_line for r in recs])
        out["infeasible_steps"].append([r.outcome.infeasible_steps for r in recs])
        out["collision"].append([bool(r.outcome.collision) for r in recs])
        # safety violations as the tables count them (docs/method.md §8.4): a distance below
        # the pair's min_dist up to the line and over the whole run
        out["violation_line"].append([bool(r.outcome.min_distance_to_line_m < r.scenario.min_dist_m)
                                      for r in recs])
        out["violation_run"].append([bool(r.outcome.min_distance_m < r.scenario.min_dist_m)
                                     for r in recs])
        out["min_distance_m"].append([float(r.outcome.min_distance_m) for r in recs])
        out["shield_interventions"].append([int(r.outcome.shield_interventions) for r in recs])
        out["informative_steps"].append([_informative(r.log) for r in recs])
        out["pa_hat_final"].append([float(r.log["av_p_a_hat"][-1]) for r in recs])
    return out


#: What ``run_chunk`` records per human and interaction.
_KEYS = ("first_at_line", "infeasible_steps", "collision", "pa_hat_final", "informative_steps",
         "violation_line", "violation_run", "min_distance_m", "shield_interventions")


def _part(folder: Path, name: str, start: int) -> Path:
    slug = name.replace(" ", "").replace(",", "_").replace("=", "")
    return folder / "parts" / f"{slug}-{start:06d}.json"


def summarise(parts: dict[str, list[dict]], interactions: int, humans: int) -> dict:
    rows = {}
    for name, chunks in parts.items():
        chunks = sorted(chunks, key=lambda c: c["seeds"][0])
        cat = {key: np.array([row for c in chunks for row in c[key]], dtype=float)
               for key in _KEYS}
        rows[name] = {
            "humans": int(cat["first_at_line"].shape[0]),
            "av_first_pct": (100.0 * np.mean(cat["first_at_line"] == 1, axis=0)).tolist(),
            "hv_first_pct": (100.0 * np.mean(cat["first_at_line"] == 2, axis=0)).tolist(),
            "cc_fail_runs": np.sum(cat["infeasible_steps"] > 0, axis=0).astype(int).tolist(),
            "cc_fail_steps": np.sum(cat["infeasible_steps"], axis=0).astype(int).tolist(),
            "collisions": np.sum(cat["collision"], axis=0).astype(int).tolist(),
            "pa_hat_final_mean": np.mean(cat["pa_hat_final"], axis=0).tolist(),
            "pa_hat_final_max": np.max(cat["pa_hat_final"], axis=0).tolist(),
            "informative_steps_mean": np.mean(cat["informative_steps"], axis=0).tolist(),
            "violation_line_runs": np.sum(cat["violation_line"], axis=0).astype(int).tolist(),
            "violation_run_runs": np.sum(cat["violation_run"], axis=0).astype(int).tolist(),
            "min_distance_m": float(np.min(cat["min_distance_m"])),
            "shield_interventions": int(np.sum(cat["shield_interventions"])),
        }
    out = {"interactions": interactions, "humans": humans, "rows": rows}
    if all(n in parts for n in PAIR):
        out["pair"] = paired(*(sorted(parts[n], key=lambda c: c["seeds"][0]) for n in PAIR))
    return out


def paired(chunks_a: list[dict], chunks_b: list[dict], n_boot: int = 10_000) -> dict:
    """The recklessness pair run by run: the same humans and initial states under two planners.

    Returns which runs failed the chance constraint under each (and whether they are the same
    runs), the runs whose failed-step counts differ (``[seed, interaction, a - b]``), and a 95 %
    bootstrap interval of the difference in failed steps, resampling humans (each human's 30
    interactions stay together; ``numpy.random.default_rng(19)``, ``n_boot`` resamples).
    """
    seeds = [s for c in chunks_a for s in c["seeds"]]
    if seeds != [s for c in chunks_b for s in c["seeds"]]:
        raise ValueError("the two settings ran different humans")
    a = np.array([row for c in chunks_a for row in c["infeasible_steps"]], dtype=np.int64)
    b = np.array([row for c in chunks_b for row in c["infeasible_steps"]], dtype=np.int64)
    d = a - b
    where = np.argwhere(d != 0)
    per_human = d.sum(axis=1)
    rng = np.random.default_rng(19)
    boot = per_human[rng.integers(0, len(per_human), (n_boot, len(per_human)))].sum(axis=1)
    return {
        "same_failed_runs": bool(np.array_equal(a > 0, b > 0)),
        "failed_runs": [int(np.sum(a > 0)), int(np.sum(b > 0))],
        "failed_steps": [int(a.sum()), int(b.sum())],
        "differing_runs": [[seeds[i], int(k), int(d[i, k])] for i, k in where],
        "steps_diff_ci95": [float(x) for x in np.percentile(boot, [2.5, 97.5])],
    }


def to_markdown(summary: dict) -> str:
    k = summary["interactions"]
    shown = [i for i in SHOWN if i <= k]
    rows = summary["rows"]
    cc = [n for n in rows if SETTINGS[n][0] == 1.0]  # the settings with the paper's human
    lines = [f"{summary['humans']} humans, {k} interactions each; corrected mode"]
    if cc:
        lines += ["", "AV first % per interaction (paper's human p_a = 1, leader start):", "",
                  "| planner | " + " | ".join(f"{i}" for i in shown) + " |",
                  "|---|" + "---|" * len(shown)]
    for name in cc:
        if name in rows:
            lines.append(f"| {name} | " + " | ".join(
                f"{rows[name]['av_first_pct'][i - 1]:.1f}" for i in shown) + " |")
    for name in [n for n in rows if SETTINGS[n][0] == 1.0 and n.startswith("online")]:
        r = rows[name]
        lines.append(f"| {name}: mean p_a_hat at the end | " + " | ".join(
            f"{r['pa_hat_final_mean'][i - 1]:.4f}" for i in shown) + " |")
        lines.append(f"| {name}: steps the human could change role / run | " + " | ".join(
            f"{r['informative_steps_mean'][i - 1]:.3f}" for i in shown) + " |")
    if "online" in rows and "fixed 0.7" in rows:
        gap = np.array(rows["online"]["av_first_pct"]) - np.array(rows["fixed 0.7"]["av_first_pct"])
        worst = int(np.argmin(gap))
        lines += ["", f"worst gap online - fixed 0.7 over all {k} interactions: "
                  f"{gap[worst]:+.1f} points (interaction {worst + 1})"]
    if "online" in rows and "informed" in rows:
        gap = np.array(rows["online"]["av_first_pct"]) - np.array(rows["informed"]["av_first_pct"])
        lines += [f"gap online - informed at interaction {k}: {gap[-1]:+.1f} points"]
    reck = [n for n in rows if SETTINGS[n][0] != 1.0]
    if reck:
        lines += ["", "Recklessness check, human p_a = 0.3 (leader start), all interactions:", "",
                  "| planner | runs | runs with cc failed | steps with cc failed | collisions | "
                  "violations to line / whole run | min distance m | shield interventions | "
                  "AV first % | mean p_a_hat at the end of the last |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for n in reck:
            r = rows[n]
            lines.append(f"| {n} | {r['humans'] * k} | {sum(r['cc_fail_runs'])} | "
                         f"{sum(r['cc_fail_steps'])} | {sum(r['collisions'])} | "
                         f"{sum(r['violation_line_runs'])} / {sum(r['violation_run_runs'])} | "
                         f"{r['min_distance_m']:.3f} | {r['shield_interventions']} | "
                         f"{np.mean(r['av_first_pct']):.1f} | {r['pa_hat_final_mean'][-1]:.4f} |")
        if "pair" in summary:
            p = summary["pair"]
            diff = p["differing_runs"]
            lines += ["", f"{PAIR[0]} against {PAIR[1]}, run by run: "
                      f"failed runs {p['failed_runs'][0]} / {p['failed_runs'][1]} "
                      f"({'the same runs' if p['same_failed_runs'] else 'not the same runs'}); "
                      f"failed steps {p['failed_steps'][0]} / {p['failed_steps'][1]}, "
                      f"difference 95 % CI [{p['steps_diff_ci95'][0]:+.0f}, "
                      f"{p['steps_diff_ci95'][1]:+.0f}] (bootstrap over humans); "
                      f"{len(diff)} runs differ, {sum(x[2] > 0 for x in diff)} with more steps "
                      "online: " + ", ".join(f"seed {s} k={i} {x:+d}" for s, i, x in diff)]
    if cc:
        lines += ["", "Chance-constraint failures with the paper's human (runs / steps over "
                  "all interactions): " + "; ".join(
                      f"{n} {sum(rows[n]['cc_fail_runs'])} / {sum(rows[n]['cc_fail_steps'])}"
                      for n in cc)]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--humans", type=int, default=1000)
    ap.add_argument("--interactions", type=int, default=30)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=25, help="humans per task")
    ap.add_argument("--settings", default="all",
                    help="all (the issue's six settings), extra (a prior that tries to "
                         "persuade, Beta(30, 1), beside fixed 0.97), reckless (the p_a = 0.3 "
                         "human against online, fixed 0.7, informed and fixed 0.5), or names "
                         "separated by "
                         "';': " + "; ".join(SETTINGS))
    ap.add_argument("--out", default="results/online-pa")
    args = ap.parse_args(argv)
    groups = {"all": MAIN, "extra": EXTRA, "reckless": RECKLESS}
    names = list(groups[args.settings]) if args.settings in groups \
        else [s.strip() for s in args.settings.split(";")]
    for n in names:
        if n not in SETTINGS:
            print(f"error: unknown setting {n!r}", file=sys.stderr)
            return 2
    folder = Path(args.out)
    (folder / "parts").mkdir(parents=True, exist_ok=True)
    # "format": what a part holds (2: with the safety measures), so that a folder of older
    # parts is refused rather than summarised without them
    meta = {"humans": args.humans, "interactions": args.interactions, "chunk": args.chunk,
            "settings": names, "format": 2}
    meta_path = folder / "benchmark.json"
    if meta_path.exists() and json.loads(meta_path.read_text()) != meta:
        print(f"error: {folder} holds another run ({meta_path.read_text().strip()})",
              file=sys.stderr)
        return 2
    meta_path.write_text(json.dumps(meta))
    config_of(names[0]).digest()  # fail early on a bad setting
    from persuasive.simulation import simulate

    simulate(config_of(names[0]), 1)  # compile (or load the cache) before forking
    todo, parts = [], {n: [] for n in names}
    for n in names:
        for start in range(1, args.humans + 1, args.chunk):
            path = _part(folder, n, start)
            if path.exists():
                parts[n].append(json.loads(path.read_text()))
            else:
                todo.append((n, list(range(start, min(start + args.chunk, args.humans + 1)))))
    t0 = time.perf_counter()
    print(f"{len(todo)} chunks to run ({sum(len(s) for _, s in todo)} humans x "
          f"{args.interactions} interactions), {args.workers} workers", file=sys.stderr)
    # spawned workers: they import this script (its run_chunk) afresh, never a fork of this
    # threaded process
    with ProcessPoolExecutor(args.workers, mp_context=get_context("spawn")) as pool:
        futures = {pool.submit(run_chunk, n, seeds, args.interactions): (n, seeds)
                   for n, seeds in todo}
        for i, fut in enumerate(as_completed(futures), 1):
            n, seeds = futures[fut]
            result = fut.result()
            path = _part(folder, n, seeds[0])
            tmp = path.with_suffix(".tmp")
            tmp.write_text(json.dumps(result))
            os.replace(tmp, path)
            parts[n].append(result)
            if i % 10 == 0 or i == len(todo):
                print(f"  {i}/{len(todo)} chunks, {time.perf_counter() - t0:.0f} s",
                      file=sys.stderr)
    summary = summarise(parts, args.interactions, args.humans)
    summary["elapsed_s_this_invocation"] = time.perf_counter() - t0
    text = to_markdown(summary)
    (folder / "summary.json").write_text(json.dumps(summary, indent=1))
    (folder / "summary.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
