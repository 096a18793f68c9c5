"""Baselines and other humans on the same runs: ``persuasive compare`` (docs/method.md §11).

Every (AV kind, human kind) pair runs on the same seeds. With the per-agent random streams
(``simulation.streams = "per-agent"``, which the comparison uses unless told otherwise) a
seed fixes the initial state and the human's random draws whatever the AV does, so two AV
planners meet the same humans in the same situations and their runs can be compared seed by
seed. The runs go through the sweep runner (``persuasive.sweep``: Dask, Parquet parts,
resumable); the comparison's folder is a sweep folder plus ``summary.json`` and
``summary.md``.

A third axis puts the safety shield on and off (``shields``, e.g. ``("off", "worst-case")``;
docs/method.md §12): a row per (AV, shield, human).

Per row the summary gives shares of who reached their line first, collisions (all of them, and
those caused by the AV), runs where the chance constraint failed, mean delays, the 5th
percentile of the minimum distance and the AV's decision time, with 95 % bootstrap confidence
intervals (``scipy.stats.bootstrap``, percentile method, a fixed random seed so that the same
runs give the same intervals); the surrogate safety measures (shield interventions, footprint
gap, time to collision, post-encroachment time, rear-ends by the human) and the AV's comfort
(strongest braking, RMS jerk); and the paired differences over the seeds both finished
(bootstrap over seeds of the per-seed differences): for each shield setting and human, every
other AV against ``persuasive``, and for each AV and human, each shield against ``off``.

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
from ..safety.measures import restricted_mean

#: Human kinds compared by default: all but ``replay``, which needs a recording.
DEFAULT_HV_KINDS = tuple(k for k in SIMULATED_HV_KINDS if k != "replay")
#: The reference AV of the paired differences.
REFERENCE_AV = "persuasive"
#: Keys of each row of ``--json`` (and of ``summary.json``'s rows, which hold more).
JSON_KEYS = ("av", "shield", "hv", "runs", "av_first_pct", "hv_first_pct", "neither_pct",
             "collisions", "collisions_caused_by_av", "rear_ends_by_human", "cc_fail_runs",
             "av_delay_s_mean", "hv_delay_s_mean", "min_distance_m_p05",
             "shield_interventions_mean", "override_pct", "override_mps2_mean",
             "uncertified_steps", "guarantee_held_runs",
             "both_cleared_pct", "av_first_through_pct", "deadlocks", "wait_s_p95",
             "wait_s_max", "av_clear_s_rmean",
             "min_gap_m_p05", "min_ttc_s_p05", "pet_s_p05",
             "av_max_brake_mps2_mean", "av_rms_jerk_mps3_mean", "av_decision_ms_median")
#: The shield setting every other is paired against.
REFERENCE_SHIELD = "off"
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


def check_size(seeds: Any, n_pairs: int, interactions: int = 1, name: str = "seeds") -> int:
    """``seeds`` (seeds ``1..seeds`` for each of ``n_pairs`` pairs, each seed ``interactions``
    runs with one human), or :class:`ConfigError` naming ``name`` and its allowed range: an
    integer in ``[1, 2^32 - 1]`` giving at most ``persuasive.experiments.MAX_RUNS`` runs in
    all, every interaction counted (they are summarised in memory). Pairs: AV kinds x human
    kinds x shield settings."""
    from ..experiments import MAX_RUNS, check_seeds

    check_seeds(seeds, 0, name)  # no rows: only the integer range; the cap follows
    n_pairs = max(1, n_pairs)
    if seeds * n_pairs * interactions > MAX_RUNS:
        most = MAX_RUNS // (n_pairs * interactions)
        rows = f"{n_pairs} pairs" + (f" x {interactions} interactions" if interactions > 1
                                     else "")
        counted = ", every interaction counted" if interactions > 1 else ""
        raise ConfigError(f"{name} = {seeds} is out of range; allowed: "
                          f"{f'1..{most}' if most >= 1 else 'none'} for {rows} (at most "
                          f"{MAX_RUNS} runs{counted}, summarised in memory; 'persuasive "
                          "sweep' streams more to disk)")
    return seeds


def n_interactions(config: Config) -> int:
    """The runs each seed of a pair makes (``simulation.interactions``, unset: 1)."""
    return config.simulation.interactions or 1


def comparison_grid(base: Config, av_kinds: Sequence[str], hv_kinds: Sequence[str],
                    seeds: int, shields: Sequence[str] | None = None):
    """The sweep grid of a comparison: ``av.kind`` x ``av.shield`` (when ``shields`` is given)
    x ``hv.kind`` x seeds ``1..seeds``, at most ``persuasive.experiments.MAX_RUNS`` runs, the
    repeated interactions of ``base`` counted (:func:`check_size`)."""
    from ..sweep import Grid

    check_size(seeds, len(av_kinds) * len(hv_kinds) * len(shields or (None,)),
               n_interactions(base))
    av_axes: dict[str, Any] = {"kind": list(av_kinds)}
    if shields:
        av_axes["shield"] = list(shields)
    data = {"seeds": seeds, "base": base.to_dict(),
            "axes": {"av": av_axes, "hv": {"kind": list(hv_kinds)}}}
    return Grid.from_dict(data)


def shield_settings(base: Config, shields: Sequence[str] | None) -> tuple[str, ...]:
    """The shield settings of a comparison: the axis when given, else the base's own."""
    return tuple(shields) if shields else (base.shield,)


def _select(runs, av: str, shield: str, hv: str, shields_axis: bool):
    mask = (runs["av.kind"] == av) & (runs["hv.kind"] == hv)
    if shields_axis:
        mask &= runs["av.shield"] == shield
    return runs[mask]


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


def default_folder(grid) -> Path:
    """``results/compare-<grid digest>``: where a comparison goes without ``out``."""
    return Path("results") / f"compare-{grid.digest[:10]}"


def run_comparison(base: Config, av_kinds: Sequence[str], hv_kinds: Sequence[str],
                   seeds: int = 200, out: str | Path | None = None, workers: int | None = None,
                   force: bool = False, timing_seeds: int = 3,
                   progress: Callable[[int, int], None] | None = None,
                   shields: Sequence[str] | None = None) -> Comparison:
    """Run and summarise a comparison (see the module docstring); returns a
    :class:`Comparison`. ``out`` defaults to ``results/compare-<grid digest>``; ``shields``:
    the shield settings to compare (default: the base configuration's only). ``progress``
    counts runs, every repeated interaction one: ``progress(done_runs, total_runs)``."""
    from .. import sweep

    base = comparison_base(base)
    grid = comparison_grid(base, av_kinds, hv_kinds, seeds, shields)
    folder = Path(out) if out is not None else default_folder(grid)
    k = n_interactions(base)
    if progress is not None and k > 1:  # a grid row is one seed's k interactions
        rows_progress = progress

        def progress(done: int, total: int) -> None:
            rows_progress(done * k, total * k)

    result = sweep.run(grid, folder, workers=workers, force=force, progress=progress,
                       what="comparison folder")
    runs = sweep.load(folder)
    timing = decision_times(base, av_kinds, hv_kinds, min(timing_seeds, seeds), shields)
    summary = summarize(runs, base, av_kinds, hv_kinds, seeds, timing, shields)
    summary["failures"] = len(result.failures)
    atomic_write(folder / "summary.json",
                 lambda p: p.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8"))
    atomic_write(folder / "summary.md",
                 lambda p: p.write_text(to_markdown(summary), encoding="utf-8"))
    return Comparison(folder, runs, summary, len(result.failures))


def decision_times(base: Config, av_kinds: Sequence[str], hv_kinds: Sequence[str],
                   n_seeds: int, shields: Sequence[str] | None = None
                   ) -> dict[tuple[str, str, str], float]:
    """Median decision time [ms] (the shield included) of each AV kind and shield setting
    against each human, over the steps of seeds ``1..n_seeds``, measured in this process."""
    from ..simulation import simulate

    out = {}
    for av in av_kinds:
        for shield in shield_settings(base, shields):
            for hv in hv_kinds:
                config = base.with_overrides({"av.kind": av, "av.shield": shield,
                                              "hv.kind": hv})
                simulate(config, 1, timed=True)  # load the code
                times = [simulate(config, seed, timed=True).av_decision_ms
                         for seed in range(1, n_seeds + 1)]
                out[(av, shield, hv)] = float(np.median(np.concatenate(times)))
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


def _min(x: np.ndarray) -> float | None:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.min(x)) if x.size else None


def _p05(x: np.ndarray) -> float | None:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.percentile(x, 5)) if x.size else None


def _column(frame, name: str) -> np.ndarray:
    return frame[name].to_numpy(dtype=float, na_value=np.nan)


def _liveness(frame, horizon_s: float | None) -> dict[str, Any]:
    """Liveness of a row's runs (docs/method.md §12.6): both cleared, the AV first through the
    conflict point with both cleared (with its interval), standoffs, the waiting time (the
    longer of the two vehicles' per run: p95 and max) and each vehicle's time to clear as a
    restricted mean of ``min(t, horizon)`` over all runs (a run that never cleared counts the
    horizon, so failing the hard runs is not rewarded). Rows from runs recorded before these
    measures existed give None."""
    if "both_cleared" not in frame:
        return {k: None for k in ("both_cleared_pct", "av_first_through_pct",
                                  "av_first_through_pct_ci", "deadlocks", "wait_s_p95",
                                  "wait_s_max", "av_clear_s_rmean", "hv_clear_s_rmean")}
    through = frame["av_first_through"].to_numpy(float)
    wait = np.maximum(_column(frame, "av_wait_s"), _column(frame, "hv_wait_s"))

    def rmean(name: str) -> float | None:
        if horizon_s is None:
            return None
        return restricted_mean(_column(frame, name), horizon_s)

    return {
        "both_cleared_pct": _pct(frame["both_cleared"].to_numpy(float)),
        "av_first_through_pct": _pct(through),
        "av_first_through_pct_ci": [100 * v for v in _bootstrap_ci(through)],
        "deadlocks": int(frame["deadlock"].astype(bool).sum()),
        "wait_s_p95": float(np.percentile(wait, 95)) if wait.size else None,
        "wait_s_max": float(np.max(wait)) if wait.size else None,
        "av_clear_s_rmean": rmean("av_time_to_clear_s"),
        "hv_clear_s_rmean": rmean("hv_time_to_clear_s"),
    }


def pair_row(frame, av: str, hv: str, timing: float | None,
             shield: str = "off", horizon_s: float | None = None) -> dict[str, Any]:
    """The summary of one (AV, shield, human) combination's runs; ``horizon_s``: the runs'
    length (``n_steps dt``), for the restricted mean times to clear."""
    first = frame["first_at_line"].to_numpy()
    av_first, hv_first = (first == 1).astype(float), (first == 2).astype(float)
    neither = (first == 0).astype(float)
    av_delay, hv_delay = _column(frame, "av_delay_s"), _column(frame, "hv_delay_s")
    min_d = _column(frame, "min_distance_m")
    caused = frame["collision_caused_by_av"].to_numpy(float)
    brake = _column(frame, "av_max_brake_mps2")
    return {
        "av": av,
        "shield": shield,
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
        "collisions_caused_by_av": int(caused.sum()),
        "collision_caused_by_av_pct_ci": [100 * v for v in _bootstrap_ci(caused)],
        "rear_ends_by_human": int(frame["rear_end_by_human"].sum()),
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
        "shield_interventions_mean": _mean(_column(frame, "shield_interventions")),
        "shield_intervention_runs": int((frame["shield_interventions"] > 0).sum()),
        # what the overrides cost (issue 25 item 6): the share of the AV's steps overridden
        # [%] and the mean change to the proposal per step [m/s^2], over the runs
        "override_pct": _mean(100.0 * _column(frame, "override_share"))
        if "override_share" in frame else None,
        "override_mps2_mean": _mean(_column(frame, "override_mps2"))
        if "override_mps2" in frame else None,
        # the guarantee (docs/method.md §12.2): steps without a certified choice, and the runs
        # it covered whole (worst-case shield, every step certified, no noise)
        "uncertified_steps": int(frame["uncertified_steps"].sum())
        if "uncertified_steps" in frame else None,
        "guarantee_held_runs": int(frame["guarantee_held"].astype(bool).sum())
        if "guarantee_held" in frame else None,
        **_liveness(frame, horizon_s),
        "min_gap_m_p05": _p05(_column(frame, "min_gap_m")),
        # the closest the footprints came in a run with no rear-end by the human (every
        # approach the AV answers for), against the shield's clearance av.shield_margin_m
        "min_gap_m_min": _min(_column(frame, "min_gap_m")[
            ~frame["rear_end_by_human"].to_numpy(bool)]),
        "min_ttc_s_p05": _p05(_column(frame, "min_ttc_s")),
        "pet_s_p05": _p05(_column(frame, "pet_s")),
        "av_max_brake_mps2_mean": _mean(brake),
        "av_max_brake_mps2_max": float(np.nanmax(brake)) if np.isfinite(brake).any() else None,
        "av_decision_ms_median": timing,
        **by_interaction(frame),
    }


def by_interaction(frame) -> dict[str, Any]:
    """With ``simulation.interactions = K > 1`` (repeated interactions with one human per
    seed; docs/method.md §13.9): per interaction, the share of runs the AV was first, the runs
    and steps where the chance constraint failed and, online, the mean of the AV's final
    estimate of p_a. Empty without repeated interactions."""
    k = 0
    while f"by_interaction.first_at_line.{k}" in frame.columns:
        k += 1
    if k == 0:
        return {}
    col = lambda name, i: frame[f"by_interaction.{name}.{i}"].to_numpy(float)  # noqa: E731
    out: dict[str, Any] = {
        "interactions": k,
        "av_first_pct_by_interaction": [_pct(col("first_at_line", i) == 1) for i in range(k)],
        "cc_fail_runs_by_interaction": [int((col("infeasible_steps", i) > 0).sum())
                                        for i in range(k)],
        "cc_fail_steps_by_interaction": [int(col("infeasible_steps", i).sum())
                                         for i in range(k)],
    }
    if "by_interaction.pa_hat_final.0" in frame.columns:
        out["pa_hat_final_mean_by_interaction"] = [_mean(col("pa_hat_final", i))
                                                   for i in range(k)]
    return out


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


def _paired_entry(ref, other) -> dict[str, Any]:
    ref, other = ref.copy(), other.copy()
    for frame in (ref, other):
        frame["av_first"] = (frame["first_at_line"] == 1).astype(float)
        frame["collided"] = frame["collision_caused_by_av"].astype(float)
    return {
        "av_first_pct": _paired(ref, other, "av_first", 100.0),
        "collision_pct": _paired(ref, other, "collided", 100.0),
        "av_delay_s": _paired(ref, other, "av_delay_s"),
        "hv_delay_s": _paired(ref, other, "hv_delay_s"),
        "min_distance_m": _paired(ref, other, "min_distance_m"),
    }


def paired_differences(runs, av_kinds: Sequence[str], hv_kinds: Sequence[str],
                       shields: Sequence[str] = ("off",),
                       shields_axis: bool = False) -> list[dict]:
    """For each shield setting and human, every other AV minus ``persuasive``, paired by
    seed (collisions: those caused by the AV)."""
    if REFERENCE_AV not in av_kinds:
        return []
    out = []
    for shield in shields:
        for hv in hv_kinds:
            ref = _select(runs, REFERENCE_AV, shield, hv, shields_axis)
            for av in av_kinds:
                if av == REFERENCE_AV:
                    continue
                other = _select(runs, av, shield, hv, shields_axis)
                out.append({"hv": hv, "av": av, "shield": shield, "against": REFERENCE_AV,
                            **_paired_entry(ref, other)})
    return out


def shield_differences(runs, av_kinds: Sequence[str], hv_kinds: Sequence[str],
                       shields: Sequence[str]) -> list[dict]:
    """For each AV and human, every shield setting minus ``off`` (when both ran), paired by
    seed."""
    if REFERENCE_SHIELD not in shields or len(shields) < 2:
        return []
    out = []
    for av in av_kinds:
        for hv in hv_kinds:
            ref = _select(runs, av, REFERENCE_SHIELD, hv, True)
            for shield in shields:
                if shield != REFERENCE_SHIELD:
                    other = _select(runs, av, shield, hv, True)
                    out.append({"av": av, "hv": hv, "shield": shield,
                                "against": REFERENCE_SHIELD, **_paired_entry(ref, other)})
    return out


def summarize(runs, base: Config, av_kinds: Sequence[str], hv_kinds: Sequence[str],
              seeds: int, timing: dict[tuple[str, str, str], float] | None = None,
              shields: Sequence[str] | None = None) -> dict[str, Any]:
    """The comparison's summary from its runs (the sweep's dataset)."""
    axis = bool(shields)
    settings = shield_settings(base, shields)
    rows = []
    for av in av_kinds:
        for shield in settings:
            for hv in hv_kinds:
                mine = _select(runs, av, shield, hv, axis)
                if len(mine):
                    rows.append(pair_row(mine, av, hv, (timing or {}).get((av, shield, hv)),
                                         shield, base.simulation.n_steps
                                         * base.simulation.dt_s))
    return {
        "study": "compare",
        "mode": base.mode,
        "scenario": base.scenario.kind,
        "streams": base.streams,
        "seeds": seeds,
        "seed_range": [1, seeds],
        "av_kinds": list(av_kinds),
        "hv_kinds": list(hv_kinds),
        "shields": list(settings),
        "rows": rows,
        "paired": paired_differences(runs, av_kinds, hv_kinds, settings, axis),
        "paired_shield": shield_differences(runs, av_kinds, hv_kinds, settings) if axis else [],
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


def _diff_cells(p: dict[str, Any]) -> list[str]:
    cells = []
    for key, digits in (("av_first_pct", 1), ("collision_pct", 1), ("av_delay_s", 2),
                        ("hv_delay_s", 2), ("min_distance_m", 2)):
        d = p[key]
        cells.append(("n/a" if d["mean"] is None else f"{d['mean']:+.{digits}f}")
                     + _ci(d["ci"], digits))
    return cells


def to_markdown(summary: dict[str, Any]) -> str:
    """The comparison as Markdown tables: outcomes per row, safety and comfort per row, then
    the paired differences."""
    shields = summary.get("shields", ["off"])
    show_shield = len(shields) > 1 or shields != ["off"]

    def key(r):
        return [r["av"]] + ([r.get("shield", "off")] if show_shield else []) + [r["hv"]]

    name = ["AV"] + (["shield"] if show_shield else []) + ["human"]
    head = name + ["runs", "AV first % [95 % CI]", "HV first %", "neither %",
                   "collisions (by AV)", "runs with cc failed", "runs cleared AV / HV",
                   "AV delay s [95 % CI]", "HV delay s [95 % CI]", "min distance p05 m",
                   "AV decision ms"]
    lines = [f"**compare**, {summary['scenario']}, {summary['mode']} mode, "
             f"{summary['streams']} streams, seeds 1..{summary['seeds']}", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in summary["rows"]:
        lines.append("| " + " | ".join(key(r) + [
            str(r["runs"]),
            _fmt(r["av_first_pct"]) + _ci(r["av_first_pct_ci"]), _fmt(r["hv_first_pct"]),
            _fmt(r["neither_pct"]), f"{r['collisions']} ({r['collisions_caused_by_av']})",
            str(r["cc_fail_runs"]),
            f"{r['runs'] - r['av_not_cleared']} / {r['runs'] - r['hv_not_cleared']}",
            _fmt(r["av_delay_s_mean"], 2) + _ci(r["av_delay_s_mean_ci"], 2),
            _fmt(r["hv_delay_s_mean"], 2) + _ci(r["hv_delay_s_mean_ci"], 2),
            _fmt(r["min_distance_m_p05"], 2), _fmt(r["av_decision_ms_median"], 3),
        ]) + " |")
    lines += ["", "Delays are means over the runs in which that vehicle cleared the conflict "
              "before the run ended (\"runs cleared\"); n/a: it never did. Collisions: runs "
              "with a footprint overlap (in brackets, those caused by the AV: all but "
              "rear-ends by the human in a shared lane)."]
    head = name + ["shield interventions / run (runs)", "overrides % of steps / mean change "
                   "m/s^2", "rear-ends by human",
                   "min footprint gap p05 m", "min TTC p05 s", "PET p05 s",
                   "AV strongest braking m/s^2 mean (max)", "AV RMS jerk m/s^3"]
    lines += ["", "Safety and comfort (surrogate measures, docs/method.md §12.6; percentiles "
              "over the runs where the measure is defined):", "",
              "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in summary["rows"]:
        lines.append("| " + " | ".join(key(r) + [
            f"{_fmt(r['shield_interventions_mean'], 2)} ({r['shield_intervention_runs']})",
            f"{_fmt(r.get('override_pct'), 1)} / {_fmt(r.get('override_mps2_mean'), 3)}",
            str(r["rear_ends_by_human"]), _fmt(r["min_gap_m_p05"], 2),
            _fmt(r["min_ttc_s_p05"], 2), _fmt(r["pet_s_p05"], 2),
            f"{_fmt(r['av_max_brake_mps2_mean'], 2)} ({_fmt(r['av_max_brake_mps2_max'], 2)})",
            _fmt(r["av_rms_jerk_mps3_mean"], 2),
        ]) + " |")
    if summary["rows"] and summary["rows"][0].get("both_cleared_pct") is not None:
        head = name + ["both cleared %", "AV first through % [95 % CI]", "standoffs",
                       "wait p95 / max s", "time to clear AV / HV s (restricted mean)"]
        lines += ["", "Liveness (docs/method.md §12.6): both vehicles cleared the conflict; the AV "
                  "passed the conflict point first and both cleared; standoffs (neither "
                  "advanced 0.5 m in 3 s, neither cleared); the longer wait of the two "
                  "(standing below 0.1 m/s before clearing); times to clear as means of "
                  "min(t, run length) over all runs:", "",
                  "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in summary["rows"]:
            lines.append("| " + " | ".join(key(r) + [
                _fmt(r["both_cleared_pct"]),
                _fmt(r["av_first_through_pct"]) + _ci(r["av_first_through_pct_ci"]),
                str(r["deadlocks"]), f"{_fmt(r['wait_s_p95'])} / {_fmt(r['wait_s_max'])}",
                f"{_fmt(r['av_clear_s_rmean'], 2)} / {_fmt(r['hv_clear_s_rmean'], 2)}",
            ]) + " |")
    repeated = [r for r in summary["rows"] if r.get("interactions")]
    if repeated:
        k = repeated[0]["interactions"]
        head = name + [f"AV first % in interaction {i + 1}" for i in range(k)]
        lines += ["", f"Repeated interactions with one human per seed ({k} each; docs/method.md "
                  "§13.9): AV first % per interaction (in brackets, runs where the chance "
                  "constraint failed):", "",
                  "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in repeated:
            lines.append("| " + " | ".join(key(r) + [
                f"{_fmt(a)} ({c})" for a, c in zip(r["av_first_pct_by_interaction"],
                                                   r["cc_fail_runs_by_interaction"])]) + " |")
    diff_head = ["AV first % diff", "AV collision % diff", "AV delay s diff", "HV delay s diff",
                 "min distance m diff"]
    if summary["paired"]:
        head = ["human", "AV"] + (["shield"] if show_shield else []) + diff_head
        lines += ["", f"Paired differences against {REFERENCE_AV} (other minus "
                  f"{REFERENCE_AV}, same seeds, mean [95 % CI]; delays over the seeds where "
                  "that vehicle cleared in both runs):", "",
                  "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for p in summary["paired"]:
            cells = [p["hv"], p["av"]] + ([p.get("shield", "off")] if show_shield else [])
            lines.append("| " + " | ".join(cells + _diff_cells(p)) + " |")
    if summary.get("paired_shield"):
        head = ["AV", "human", "shield"] + diff_head
        lines += ["", f"Paired differences against the unshielded planner (shield minus "
                  f"{REFERENCE_SHIELD}, same seeds, mean [95 % CI]):", "",
                  "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for p in summary["paired_shield"]:
            lines.append("| " + " | ".join([p["av"], p["hv"], p["shield"]] + _diff_cells(p))
                         + " |")
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


__all__ = ["AV_KINDS", "Comparison", "DEFAULT_HV_KINDS", "JSON_KEYS", "check_size",
           "comparison_grid", "json_rows", "load_summary", "n_interactions", "parse_kinds",
           "run_comparison", "summarize", "to_markdown"]
