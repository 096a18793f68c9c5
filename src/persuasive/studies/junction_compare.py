"""AV planners and human populations compared at the junction of many vehicles, on the same
seeds (``persuasive compare --scenario junction``; docs/guide/junction.md).

A cell is an AV kind, a human population (one kind for every human, or the configuration's
``junction.hv_kinds`` mix) and a shield setting; every cell runs seeds ``1..seeds`` of the same
junction, so a seed gives the same arrivals (arms, movements, lanes, gaps, speeds and the
humans' draws) whatever the AV, and each seed's row is
``persuasive.many.study.run_seed``'s (the AV's run and the same seed without it). The summary
is one :func:`persuasive.many.study.aggregate` per cell with the 95 % Wilson interval of the
AV's through-rate, and each AV's paired difference against the reference AV (``persuasive``)
on the same seeds and population: the through-rate in points and the delay caused in
seconds, each with the normal 95 % interval of the mean paired difference (a seed is one
pair).

``--out`` (default ``results/compare-junction-<digest>/``) gets ``runs.parquet`` (one row per
cell and seed, with ``av``, ``hv`` and ``shield`` columns), ``summary.json`` and ``summary.md``,
written together at the end (a comparison is not resumed: run it again to redo it).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..config import Config
from ..sweep.metrics import Z95, mean_interval, wilson
from .compare import REFERENCE_AV

#: The files a junction comparison writes in its folder (``--force`` replaces only these).
OUT_FILES = ("runs.parquet", "summary.json", "summary.md")


def cell_config(base: Config, av: str, hv: str | None, shield: str | None) -> Config:
    """The configuration of one cell: ``base`` with the AV kind, every human of kind ``hv``
    (None: ``base``'s ``junction.hv_kinds``) and the shield (None: ``base``'s)."""
    overrides: dict[str, Any] = {"av.kind": av}
    if hv is not None:
        overrides["junction.hv_kinds"] = hv
    if shield is not None:
        overrides["av.shield"] = shield
    return base.with_overrides(overrides)


def cells_of(base: Config, avs: Sequence[str], hvs: Sequence[str] | None,
             shields: Sequence[str] | None) -> list[tuple[str, str, str, Config]]:
    """Every cell ``(av, hv, shield, config)``, AV-major; checked whole before any run."""
    out = []
    for hv in (hvs or (None,)):
        for shield in (shields or (None,)):
            for av in avs:
                config = cell_config(base, av, hv, shield)
                label = hv if hv is not None else _mix_label(config)
                out.append((av, label, config.shield, config))
    return out


def _mix_label(config: Config) -> str:
    kinds = config.junction_spec.hv_kinds
    return kinds[0][0] if len(kinds) == 1 else ",".join(f"{k}:{w:g}" for k, w in kinds)


def default_folder(base: Config, avs: Sequence[str], hvs: Sequence[str] | None,
                   shields: Sequence[str] | None, seeds: int) -> Path:
    """``results/compare-junction-<digest>``: the digest of the base configuration, the
    kinds and the seeds."""
    digest = base.digest(tuple(avs), tuple(hvs or ()), tuple(shields or ()), seeds)
    return Path("results") / f"compare-junction-{digest}"


def _paired(ref: Sequence[dict], other: Sequence[dict], key: str, scale: float = 1.0
            ) -> dict[str, Any]:
    """The mean paired difference ``other - ref`` of ``key`` over seeds (both finite), with
    its normal 95 % interval."""
    a = np.array([float(r[key]) for r in ref])
    b = np.array([float(r[key]) for r in other])
    keep = np.isfinite(a) & np.isfinite(b)
    mean, lo, hi = mean_interval(scale * (b[keep] - a[keep]))
    return {"mean": mean, "ci": [lo, hi], "n": int(keep.sum())}


def summarize(cells: Sequence[tuple[str, str, str, Config]],
              results: Sequence[tuple[list[dict], np.ndarray]]) -> dict[str, Any]:
    """The comparison's summary: a row per cell (its aggregate and the Wilson interval of
    the AV's through-rate) and the paired differences against :data:`REFERENCE_AV`."""
    from ..many.study import aggregate

    rows = []
    by_cell: dict[tuple[str, str, str], list[dict]] = {}
    for (av, hv, shield, _), (runs, step_ms) in zip(cells, results):
        agg = aggregate(runs, step_ms)
        k = sum(bool(r["av_through"]) for r in runs)
        lo, hi = wilson(k, len(runs))
        rows.append({"av": av, "hv": hv, "shield": shield, **agg,
                     "av_through_ci": [100.0 * lo, 100.0 * hi]})
        by_cell[(av, hv, shield)] = runs
    paired = []
    for (av, hv, shield), runs in by_cell.items():
        ref = by_cell.get((REFERENCE_AV, hv, shield))
        if av == REFERENCE_AV or ref is None:
            continue
        paired.append({"av": av, "hv": hv, "shield": shield,
                       "av_through_pts": _paired(ref, runs, "av_through", 100.0),
                       "caused_delay_s": _paired(ref, runs, "caused_delay_s")})
    return {"reference_av": REFERENCE_AV, "interval": "Wilson 95 % (through); normal 95 % of "
            "the mean paired difference (differences)", "z": Z95, "rows": rows,
            "paired": paired}


def _num(value: Any, digits: int = 1) -> str:
    return "-" if value is None or (isinstance(value, float) and not math.isfinite(value)) \
        else f"{value:.{digits}f}"


def _diff(d: dict[str, Any], digits: int = 1) -> str:
    lo, hi = d["ci"]
    return f"{d['mean']:+.{digits}f} [{_num(lo, digits)}, {_num(hi, digits)}]"


def to_markdown(summary: dict[str, Any]) -> str:
    """The summary as two Markdown tables (the cells; the paired differences)."""
    head = ("| AV | humans | shield | runs | AV through [95 %] | AV first (conflicts) | "
            "AV-caused collisions | uncertified steps | deadlocks (AV in) | human collisions "
            "| AV delay [s] | delay caused [s] | throughput [veh/h] | min PET AV [s] | "
            "step ms median / p99 |")
    lines = [head, "|" + "---|" * head.count(" | ") + "---|"]
    for r in summary["rows"]:
        lo, hi = r["av_through_ci"]
        lines.append(
            f"| {r['av']} | {r['hv']} | {r['shield']} | {r['runs']} | "
            f"{r['av_through_pct']:.1f} % [{lo:.1f}, {hi:.1f}] | {r['av_first_pct']:.1f} % "
            f"({r['av_conflicts_passed']}) | {r['av_caused_collisions']} | "
            f"{r['uncertified_steps']} | {r['deadlock_runs']} ({r['av_in_deadlock_runs']}) | "
            f"{r['human_collisions']} | {_num(r['mean_av_delay_s'], 2)} | "
            f"{_num(r['mean_caused_delay_s'], 2)} | {_num(r['median_throughput_veh_h'], 0)} | "
            f"{_num(r['min_pet_av_s'], 2)} | {_num(r['step_ms_median'], 3)} / "
            f"{_num(r['step_ms_p99'], 3)} |")
    if summary["paired"]:
        lines += ["", f"Paired by seed against the {summary['reference_av']} AV (other minus "
                  "it; mean [95 % interval]):", "",
                  "| AV | humans | shield | AV through [points] | delay caused [s] |",
                  "|---|---|---|---|---|"]
        for p in summary["paired"]:
            lines.append(f"| {p['av']} | {p['hv']} | {p['shield']} | "
                         f"{_diff(p['av_through_pts'])} | {_diff(p['caused_delay_s'], 2)} |")
    return "\n".join(lines)


def run_comparison(base: Config, avs: Sequence[str], hvs: Sequence[str] | None,
                   shields: Sequence[str] | None, seeds: int, out: str | Path,
                   workers: int = 1,
                   progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Run every cell on seeds ``1..seeds`` and write ``out`` (module docstring; the caller
    checks the folder first, ``persuasive._files.check_replaceable_folder``, and holds its
    lock); returns the summary."""
    import json

    import pandas as pd

    from .._files import atomic_folder, json_safe
    from ..many.study import run_cells

    cells = cells_of(base, avs, hvs, shields)
    results = run_cells([(c, c.junction_spec) for *_, c in cells], range(1, seeds + 1),
                        workers, progress)
    summary = summarize(cells, results)
    summary.update({"scenario": "junction", "vehicles": base.junction_spec.n_vehicles,
                    "variant": base.junction.variant or "major", "mode": base.mode,
                    "seeds": [1, seeds], "workers": workers})
    frame = pd.DataFrame([{"av": av, "hv": hv, "shield": shield, **row}
                          for (av, hv, shield, _), (runs, _) in zip(cells, results)
                          for row in runs])
    with atomic_folder(out, owned=OUT_FILES) as tmp:
        frame.to_parquet(Path(tmp) / "runs.parquet", index=False)
        (Path(tmp) / "summary.json").write_text(
            json.dumps(json_safe(summary), indent=2, allow_nan=False) + "\n")
        (Path(tmp) / "summary.md").write_text(to_markdown(summary) + "\n")
    return summary


__all__ = ["OUT_FILES", "cell_config", "cells_of", "default_folder", "run_comparison",
           "summarize", "to_markdown"]
