"""Baselines and other humans on the same runs: ``persuasive compare`` (docs/method.md §11).

Every (AV kind, human kind) pair runs on the same seeds. With the per-agent random streams
(``simulation.streams = "per-agent"``, which the comparison uses unless told otherwise) a
seed fixes the initial state and the human's random draws whatever the AV does, so two AV
planners meet the same humans in the same situations and their runs can be compared seed by
seed. The runs go through the sweep runner (``persuasive.sweep``: Dask, Parquet parts,
resumable); the comparison's folder is a sweep folder plus ``summary.json`` and
``summary.md``.

Per pair the summary gives shares of who reached their line first, collisions, runs where the
chance constraint failed, mean delays, the 5th percentile of the minimum distance and the AV's
decision time, with 95 % bootstrap confidence intervals (``scipy.stats.bootstrap``,
percentile method, a fixed random seed so that the same runs give the same intervals), and
for each human kind the paired differences of every other AV against ``persuasive`` over the
seeds both finished (bootstrap over seeds of the per-seed differences).

The decision time is measured separately, in this process and not in the workers, on the
first ``timing_seeds`` seeds of each pair (``simulate(..., timed=True)``): it is the median
per step of the AV's own work (its prediction and library included), and the only figure that
is not a pure function of the runs.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .._version import __version__
from .._files import atomic_write
from ..config import AV_KINDS, SIMULATED_HV_KINDS, Config, ConfigError

#: Human kinds compared by default: all but ``replay``, which needs a recording.
DEFAULT_HV_KINDS = tuple(k for k in SIMULATED_HV_KINDS if k != "replay")
#: The reference AV of the paired differences.
REFERENCE_AV = "persuasive"
#: Keys of each row of ``--json`` (and of ``summary.json``'s rows, which hold more).
JSON_KEYS = ("av", "hv", "runs", "av_first_pct", "hv_first_pct", "neither_pct", "collisions",
             "cc_fail_runs", "av_delay_s_mean", "hv_delay_s_mean", "min_distance_m_p05",
             "av_decision_ms_median")
#: Resamples of the bootstrap and its seed.
N_RESAMPLES = 2000
BOOTSTRAP_SEED = 12345


def parse_kinds(text: str | Sequence[str] | None, allowed: Sequence[str], name: str,
                default: Sequence[str]) -> tuple[str, ...]:
    """A comma-separated list of kinds (``"all"``: every allowed one), validated, in order."""
    if text is None:
        return tuple(default)
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text)]
    if items == ["all"]:
        return tuple(default)
    out = []
    for item in items:
        kind = {"mpc": "persuasive"}.get(item, item)
        if kind not in allowed:
            raise ConfigError(f"{name} = {item!r} is out of range; allowed: a comma-separated "
                              f"list of {' | '.join(allowed)} (or all)")
        if kind in out:
            raise ConfigError(f"{name}: {kind!r} is given twice")
        out.append(kind)
    if not out:
        raise ConfigError(f"{name} is empty; allowed: {' | '.join(allowed)}")
    return tuple(out)


def comparison_grid(base: Config, av_kinds: Sequence[str], hv_kinds: Sequence[str],
                    seeds: int):
    """The sweep grid of a comparison: ``av.kind`` x ``hv.kind`` x seeds ``1..seeds``, at
    most ``persuasive.experiments.MAX_RUNS`` runs (they are summarised in memory)."""
    from ..experiments import check_seeds
    from ..sweep import Grid

    check_seeds(seeds, max(1, len(av_kinds) * len(hv_kinds)), rows="pairs")
    data = {"seeds": seeds, "base": base.to_dict(),
            "axes": {"av": {"kind": list(av_kinds)}, "hv": {"kind": list(hv_kinds)}}}
    return Grid.from_dict(data)


def comparison_base(config: Config) -> Config:
    """``config`` with the per-agent streams unless it sets ``simulation.streams`` itself."""
    if config.simulation.streams is None:
        return config.with_overrides({"simulation.streams": "per-agent"})
    return config


@dataclass(frozen=True)
class Comparison:
    """A finished comparison: its folder, the runs and the summary."""

    folder: Path
    runs: Any  #: pandas DataFrame, one row per run (the sweep's dataset)
    summary: dict[str, Any]  #: as written to ``summary.json``
    failures: int  #: runs that raised (see the sweep folder's ``failed/``)


def run_comparison(base: Config, av_kinds: Sequence[str], hv_kinds: Sequence[str],
                   seeds: int = 200, out: str | Path | None = None, workers: int | None = None,
                   force: bool = False, timing_seeds: int = 3,
                   progress: Callable[[int, int], None] | None = None) -> Comparison:
    """Run and summarise a comparison (see the module docstring); returns a
    :class:`Comparison`. ``out`` defaults to ``results/compare-<grid digest>``."""
    from .. import sweep

    base = comparison_base(base)
    grid = comparison_grid(base, av_kinds, hv_kinds, seeds)
    folder = Path(out) if out is not None else Path("results") / f"compare-{grid.digest[:10]}"
    result = sweep.run(grid, folder, workers=workers, force=force, progress=progress,
                       what="comparison folder")
    runs = sweep.load(folder)
    timing = decision_times(base, av_kinds, hv_kinds, min(timing_seeds, seeds))
    summary = summarize(runs, base, av_kinds, hv_kinds, seeds, timing)
    summary["failures"] = len(result.failures)
    atomic_write(folder / "summary.json",
                 lambda p: p.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8"))
    atomic_write(folder / "summary.md",
                 lambda p: p.write_text(to_markdown(summary), encoding="utf-8"))
    return Comparison(folder, runs, summary, len(result.failures))


def decision_times(base: Config, av_kinds: Sequence[str], hv_kinds: Sequence[str],
                   n_seeds: int) -> dict[tuple[str, str], float]:
    """Median decision time [ms] of each AV kind against each human, over the steps of seeds
    ``1..n_seeds``, measured in this process."""
    from ..simulation import simulate

    out = {}
    for av in av_kinds:
        for hv in hv_kinds:
            config = base.with_overrides({"av.kind": av, "hv.kind": hv})
            simulate(config, 1, timed=True)  # load the code
            times = [simulate(config, seed, timed=True).av_decision_ms
                     for seed in range(1, n_seeds + 1)]
            out[(av, hv)] = float(np.median(np.concatenate(times)))
    return out


# -- statistics -----------------------------------------------------------------------------


def _bootstrap_ci(values: np.ndarray, statistic=np.mean) -> list[float | None]:
    """95 % percentile-bootstrap interval of ``statistic`` of ``values`` (NaN dropped)."""
    from scipy.stats import bootstrap

    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return [None, None]
    if values.size == 1 or np.all(values == values[0]):
        v = float(statistic(values))
        return [v, v]
    res = bootstrap((values,), statistic, confidence_level=0.95, n_resamples=N_RESAMPLES,
                    method="percentile", random_state=np.random.default_rng(BOOTSTRAP_SEED),
                    vectorized=False)
    return [float(res.confidence_interval.low), float(res.confidence_interval.high)]


def _pct(x: np.ndarray) -> float:
    return 100.0 * float(np.mean(x))


def _mean(x: np.ndarray) -> float | None:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.mean(x)) if x.size else None


def _p05(x: np.ndarray) -> float:
    return float(np.percentile(x, 5))


def _column(frame, name: str) -> np.ndarray:
    return frame[name].to_numpy(dtype=float, na_value=np.nan)


def pair_row(frame, av: str, hv: str, timing: float | None) -> dict[str, Any]:
    """The summary of one (AV, human) pair's runs."""
    first = frame["first_at_line"].to_numpy()
    av_first, hv_first = (first == 1).astype(float), (first == 2).astype(float)
    neither = (first == 0).astype(float)
    av_delay, hv_delay = _column(frame, "av_delay_s"), _column(frame, "hv_delay_s")
    min_d = _column(frame, "min_distance_m")
    return {
        "av": av,
        "hv": hv,
        "runs": int(len(frame)),
        "av_first_pct": _pct(av_first),
        "av_first_pct_ci": [100 * v for v in _bootstrap_ci(av_first)],
        "hv_first_pct": _pct(hv_first),
        "hv_first_pct_ci": [100 * v for v in _bootstrap_ci(hv_first)],
        "same_step_pct": _pct(first == 3),
        "neither_pct": _pct(neither),
        "collisions": int(frame["collision"].sum()),
        "collision_pct_ci": [100 * v for v in _bootstrap_ci(frame["collision"].to_numpy(float))],
        "cc_fail_runs": int((frame["infeasible_steps"] > 0).sum()),
        "cc_fail_steps": int(frame["infeasible_steps"].sum()),
        "av_delay_s_mean": _mean(av_delay),
        "av_delay_s_mean_ci": _bootstrap_ci(av_delay),
        "av_not_cleared": int(np.sum(~np.isfinite(av_delay))),
        "hv_delay_s_mean": _mean(hv_delay),
        "hv_delay_s_mean_ci": _bootstrap_ci(hv_delay),
        "hv_not_cleared": int(np.sum(~np.isfinite(hv_delay))),
        "min_distance_m_p05": _p05(min_d),
        "min_distance_m_p05_ci": _bootstrap_ci(min_d, _p05),
        "av_rms_jerk_mps3_mean": _mean(_column(frame, "av_rms_jerk_mps3")),
        "hv_rms_jerk_mps3_mean": _mean(_column(frame, "hv_rms_jerk_mps3")),
        "av_decision_ms_median": timing,
    }


def _paired(ref, other, column: str, scale: float = 1.0) -> dict[str, Any]:
    """Mean of ``other - ref`` over the seeds both have (and finite), with its interval."""
    a = ref.set_index("seed")[column].astype(float)
    b = other.set_index("seed")[column].astype(float)
    seeds = a.index.intersection(b.index)
    diff = (b.loc[seeds] - a.loc[seeds]).to_numpy() * scale
    diff = diff[np.isfinite(diff)]
    ci = _bootstrap_ci(diff)
    return {"mean": float(np.mean(diff)) if diff.size else None, "ci": ci,
            "seeds": int(diff.size)}


def paired_differences(runs, av_kinds: Sequence[str], hv_kinds: Sequence[str]) -> list[dict]:
    """For each human, every other AV minus ``persuasive``, paired by seed."""
    if REFERENCE_AV not in av_kinds:
        return []
    out = []
    for hv in hv_kinds:
        ref = runs[(runs["av.kind"] == REFERENCE_AV) & (runs["hv.kind"] == hv)].copy()
        ref["av_first"] = (ref["first_at_line"] == 1).astype(float)
        ref["collided"] = ref["collision"].astype(float)
        for av in av_kinds:
            if av == REFERENCE_AV:
                continue
            other = runs[(runs["av.kind"] == av) & (runs["hv.kind"] == hv)].copy()
            other["av_first"] = (other["first_at_line"] == 1).astype(float)
            other["collided"] = other["collision"].astype(float)
            out.append({
                "hv": hv, "av": av, "against": REFERENCE_AV,
                "av_first_pct": _paired(ref, other, "av_first", 100.0),
                "collision_pct": _paired(ref, other, "collided", 100.0),
                "av_delay_s": _paired(ref, other, "av_delay_s"),
                "hv_delay_s": _paired(ref, other, "hv_delay_s"),
                "min_distance_m": _paired(ref, other, "min_distance_m"),
            })
    return out


def summarize(runs, base: Config, av_kinds: Sequence[str], hv_kinds: Sequence[str],
              seeds: int, timing: dict[tuple[str, str], float] | None = None) -> dict[str, Any]:
    """The comparison's summary from its runs (the sweep's dataset)."""
    rows = []
    for av in av_kinds:
        for hv in hv_kinds:
            mine = runs[(runs["av.kind"] == av) & (runs["hv.kind"] == hv)]
            if len(mine):
                rows.append(pair_row(mine, av, hv, (timing or {}).get((av, hv))))
    return {
        "study": "compare",
        "mode": base.mode,
        "scenario": base.scenario.kind,
        "streams": base.streams,
        "seeds": seeds,
        "seed_range": [1, seeds],
        "av_kinds": list(av_kinds),
        "hv_kinds": list(hv_kinds),
        "rows": rows,
        "paired": paired_differences(runs, av_kinds, hv_kinds),
        "config_hash": base.digest(),
        "config_toml": base.to_toml(),
        "version": __version__,
        "bootstrap": {"confidence": 0.95, "method": "percentile", "resamples": N_RESAMPLES,
                      "seed": BOOTSTRAP_SEED},
    }


def json_rows(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The rows ``--json`` prints (keys :data:`JSON_KEYS`)."""
    return [{k: row[k] for k in JSON_KEYS} for row in summary["rows"]]


# -- text -----------------------------------------------------------------------------------


def _fmt(v: float | None, digits: int = 1) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}f}"


def _ci(ci: list, digits: int = 1) -> str:
    if not ci or ci[0] is None:
        return ""
    return f" [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"


def to_markdown(summary: dict[str, Any]) -> str:
    """The comparison as Markdown tables: one row per pair, then the paired differences."""
    head = ["AV", "human", "runs", "AV first % [95 % CI]", "HV first %", "neither %",
            "collisions", "runs with cc failed", "runs cleared AV / HV", "AV delay s [95 % CI]",
            "HV delay s [95 % CI]", "min distance p05 m", "AV decision ms"]
    lines = [f"**compare**, {summary['scenario']}, {summary['mode']} mode, "
             f"{summary['streams']} streams, seeds 1..{summary['seeds']}", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in summary["rows"]:
        lines.append("| " + " | ".join([
            r["av"], r["hv"], str(r["runs"]),
            _fmt(r["av_first_pct"]) + _ci(r["av_first_pct_ci"]), _fmt(r["hv_first_pct"]),
            _fmt(r["neither_pct"]), str(r["collisions"]), str(r["cc_fail_runs"]),
            f"{r['runs'] - r['av_not_cleared']} / {r['runs'] - r['hv_not_cleared']}",
            _fmt(r["av_delay_s_mean"], 2) + _ci(r["av_delay_s_mean_ci"], 2),
            _fmt(r["hv_delay_s_mean"], 2) + _ci(r["hv_delay_s_mean_ci"], 2),
            _fmt(r["min_distance_m_p05"], 2), _fmt(r["av_decision_ms_median"], 3),
        ]) + " |")
    lines += ["", "Delays are means over the runs in which that vehicle cleared the conflict "
              "before the run ended (\"runs cleared\"); n/a: it never did."]
    if summary["paired"]:
        head = ["human", "AV", "AV first % diff", "collision % diff", "AV delay s diff",
                "HV delay s diff", "min distance m diff"]
        lines += ["", f"Paired differences against {REFERENCE_AV} (other minus "
                  f"{REFERENCE_AV}, same seeds, mean [95 % CI]; delays over the seeds where "
                  "that vehicle cleared in both runs):", "",
                  "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for p in summary["paired"]:
            cells = [p["hv"], p["av"]]
            for key, digits in (("av_first_pct", 1), ("collision_pct", 1), ("av_delay_s", 2),
                                ("hv_delay_s", 2), ("min_distance_m", 2)):
                d = p[key]
                cells.append(("n/a" if d["mean"] is None else f"{d['mean']:+.{digits}f}")
                             + _ci(d["ci"], digits))
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def load_summary(folder: str | Path) -> dict[str, Any]:
    """Read a comparison's ``summary.json``."""
    path = Path(folder) / "summary.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ConfigError(f"comparison folder {str(folder)!r} has no readable summary.json "
                          f"({exc.__class__.__name__})") from None
    if data.get("study") != "compare":
        raise ConfigError(f"{str(path)!r} is not the summary of a comparison")
    return data


__all__ = ["AV_KINDS", "Comparison", "DEFAULT_HV_KINDS", "JSON_KEYS", "comparison_grid",
           "json_rows", "load_summary", "parse_kinds", "run_comparison", "summarize",
           "to_markdown"]
