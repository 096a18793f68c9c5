"""How fast the N-vehicle junction steps, and where the time goes, by number of vehicles.

    python benchmarks/junction_speed.py [--vehicles 2 3 4 6 8 10] [--seeds 50]
                                       [--plan pairwise joint] [--av persuasive lfg-rule]
                                       [--figure FILE] [--json]

For each N: ``--seeds`` runs (seeds 1..), one process, the default junction (``major``, one
lane, ``lfg`` humans playing their next conflict, the persuasive AV with the worst-case
shield, 30-s runs; ``--av`` other AV kinds on the same seeds), timing every closed-loop step (every vehicle decides, all advance, every
conflict checked) and, inside it, the AV's decision (its planners and the shield) and the
humans' decisions. ``--plan``: how the AV plans (``junction.av_plan``: one planner per
human, or one plan against all; each plan is timed on the same seeds). Prints the medians and
99th percentiles [ms] and the share of the step each part takes. Targets (the 2-core
machine): one step at N = 10 at most 1 ms median (issue 40); the AV's decision with the
shield at N = 10 at most 1 ms median and 3 ms p99 (issue 41). The whole study's wall time is ``persuasive junction --vehicles 10 --seeds 500
--workers 2`` (at most 2 minutes).
"""

from __future__ import annotations

import argparse
import json

from persuasive.bench import bench_junction
from persuasive.config import Config


def measure(n: int, seeds: int, plan: str = "pairwise", av: str = "persuasive") -> dict:
    """One N's timings (``persuasive.bench.bench_junction``, as ``persuasive bench
    --scenario junction --vehicles N --runs SEEDS`` prints them for the pairwise plan) for the
    AV kind ``av``."""
    config = Config(mode="corrected").with_overrides({"scenario.kind": "junction",
                                                      "junction.n_vehicles": n,
                                                      "junction.av_plan": plan,
                                                      "av.kind": av})
    return {**bench_junction(config, seeds), "plan": plan, "av": av}


def figure(rows: list[dict], path: str) -> None:
    """The AV's decision time (the shield included) against N: median (solid) and 99th
    percentile (dashed) per AV kind and plan, on a log scale, with the issue's targets at
    N = 10; written atomically (``persuasive.plots.files.save_figure``)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from persuasive.plots.files import save_figure

    fig = Figure(figsize=(5.2, 3.4), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    series = list(dict.fromkeys((r["av"], r["plan"]) for r in rows))
    for i, (av, plan) in enumerate(series):
        mine = sorted((r for r in rows if (r["av"], r["plan"]) == (av, plan)),
                      key=lambda r: r["vehicles"])
        n = [r["vehicles"] for r in mine]
        label = av if len({p for _, p in series}) == 1 else f"{av}, {plan}"
        line, = ax.plot(n, [r["av_ms_median"] for r in mine], marker="o", ms=3.5, lw=1.1,
                        label=f"{label} median")
        ax.plot(n, [r["av_ms_p99"] for r in mine], marker="o", ms=2.5, lw=0.9, ls="--",
                color=line.get_color(), label=f"{label} p99")
    ax.set_xticks(sorted({r["vehicles"] for r in rows}))
    ax.axhline(1.0, color="0.4", lw=0.6, ls=":")
    ax.axhline(3.0, color="0.4", lw=0.6, ls="-.")
    ax.set_yscale("log")
    ax.set_xlabel("vehicles at the junction (the AV and N - 1 humans)", fontsize=8)
    ax.set_ylabel("AV decision with the shield [ms]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, linewidth=0.4, alpha=0.35)
    ax.legend(fontsize=6, frameon=False, ncol=2)
    ax.set_title("decision time against N (targets at N = 10: 1 ms median, 3 ms p99)",
                 fontsize=8)
    print(f"wrote {save_figure(fig, path, dpi=150)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, nargs="+", default=[2, 3, 4, 6, 8, 10])
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--plan", nargs="+", default=["pairwise"],
                        choices=["pairwise", "joint"])
    parser.add_argument("--av", nargs="+", default=["persuasive"],
                        help="AV kinds (av.kind), each timed on the same seeds")
    parser.add_argument("--figure", default=None, metavar="FILE",
                        help="also draw the AV's decision time against N (.png/.svg/.pdf)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = [measure(n, args.seeds, plan, av) for av in args.av for n in args.vehicles
            for plan in args.plan]
    if args.figure:
        figure(rows, args.figure)
    if args.json:
        print(json.dumps(rows))
        return
    print("| AV | vehicles | AV plan | steps | step ms median / p99 | AV decision ms median / "
          "p99 | humans ms median | AV share | humans share |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['av']} | {r['vehicles']} | {r['plan']} | {r['steps']} | "
              f"{r['step_ms_median']:.3f} / "
              f"{r['step_ms_p99']:.3f} | {r['av_ms_median']:.3f} / {r['av_ms_p99']:.3f} "
              f"| {r['humans_ms_median']:.3f} | {100 * r['av_share']:.0f} % "
              f"| {100 * r['humans_share']:.0f} % |")


if __name__ == "__main__":
    main()
