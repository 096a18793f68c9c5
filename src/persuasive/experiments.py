"""The paper's Monte Carlo studies (docs/method.md §8): Tables 1 and 2, run in parallel.

A table is a list of rows (who drives the AV, the HV's initial role, ``p_a``, ``p_a_hat``);
each row runs seeds ``1..N``. Every run is a pure function of its configuration and seed, so
the work is split into chunks of seeds, farmed out to worker processes, and put back in
``(row, seed)`` order: the results do not depend on the number of workers.

Metrics per row (§8): counts of who reached the crossing line first (AV, HV, same
step, neither) and the AV/HV shares of all runs; collisions; runs with an infeasible MPC step;
safety violations (minimum distance below ``min_dist``) up to ``idx_end`` and over the whole
run. The published shares are printed beside the reproduced ones.
"""

from __future__ import annotations

import json
import os
import time
import tomllib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from ._version import __version__
from ._compile import warm_up
from ._processes import context
from ._files import OutputError, atomic_folder, atomic_write, is_lock_file
from .config import Config, ConfigError
from .simulation import simulate
from .sweep.grid import SEED_MAX

TABLES = ("table1", "table2")
#: Most runs one reproduction (or comparison) may have: its runs are summarised in memory
#: (about 2.5 kB each at the peak, some 3 GB for the most); ``persuasive sweep`` streams any
#: number of runs to disk.
MAX_RUNS = 1_000_000


@dataclass(frozen=True)
class Row:
    """One row of a paper table and its published result (percent of runs)."""

    av: str  #: the AV's kind: "lfg" (Table 1) or "persuasive" (Table 2)
    hv_role: str  #: the HV's initial role
    pa: float  #: the human's p_a
    pa_hat: float | None  #: the AV's estimate (Table 2), None for Table 1
    published_av_first_pct: float
    published_hv_first_pct: float

    def overrides(self) -> dict[str, Any]:
        """This row's agents and parameters, as dotted fields."""
        return {
            "av.kind": self.av,
            "hv.role": self.hv_role,
            "roles.p_a": self.pa,
            "mpc.p_a_hat": self.pa if self.pa_hat is None else self.pa_hat,
        }

    def config(self, base: Config) -> Config:
        """``base`` with this row's agents and parameters."""
        return base.with_overrides(self.overrides())


#: The published rows (docs/method.md §8), in the paper's order.
PUBLISHED: dict[str, tuple[Row, ...]] = {
    "table1": (
        Row("lfg", "leader", 1.0, None, 0.0, 100.0),
        Row("lfg", "follower", 1.0, None, 97.9, 2.1),
    ),
    "table2": tuple(
        Row("persuasive", "leader" if r == "L" else "follower", pa, pah, av, hv)
        for r, pa, pah, av, hv in (
            ("L", 1.00, 1.00, 87.8, 12.2),
            ("F", 1.00, 1.00, 96.4, 3.6),
            ("L", 0.70, 1.00, 86.3, 13.7),
            ("L", 0.50, 1.00, 82.9, 17.1),
            ("L", 0.30, 1.00, 78.1, 21.9),
            ("F", 0.50, 1.00, 96.5, 3.5),
            ("F", 0.70, 1.00, 96.5, 3.5),
            ("F", 0.30, 1.00, 96.6, 3.4),
            ("L", 1.00, 0.98, 78.9, 21.1),
            ("L", 1.00, 0.95, 0.0, 100.0),
            ("L", 1.00, 0.70, 0.0, 100.0),
            ("F", 1.00, 0.98, 96.4, 3.6),
            ("F", 1.00, 0.95, 38.9, 61.1),
            ("F", 1.00, 0.70, 1.2, 98.8),
        )
    ),
}

#: The seeds of the published tables: seeds 1..1000 per row.
PUBLISHED_SEEDS = 1000

#: The sweep's name of the cases' axis (a table's row).
CASE = "case"

#: Per-run columns kept in the results table, in order.
RUN_COLUMNS = (
    "table", "row", "av", "hv_role", "pa", "pa_hat", "mode", "seed",
    "av_s0_m", "av_v0_mps", "hv_s0_m", "hv_v0_mps",
    "first_at_line", "first_at_conflict_point", "collision", "min_distance_to_line_m",
    "min_distance_m", "idx_end", "infeasible_steps", "hv_role_changes", "av_role_changes",
    "safety_distance_m", "config_hash", "version",
)


_METRICS = RUN_COLUMNS[RUN_COLUMNS.index("first_at_line"):
                       RUN_COLUMNS.index("safety_distance_m")]


def run_record(table: str, row: int, config: Config, seed: int) -> dict[str, Any]:
    """One closed-loop run as a flat results row (see ``RUN_COLUMNS``)."""
    rec = simulate(config, seed)
    s = rec.summary()
    return {
        "table": table,
        "row": row,
        "av": s["av"],
        "hv_role": s["hv_role"],
        "pa": s["pa"],
        "pa_hat": s["pa_hat"] if s["av"] != "lfg" else None,
        "mode": s["mode"],
        "seed": seed,
        "av_s0_m": s["av_initial_state"][0],
        "av_v0_mps": s["av_initial_state"][1],
        "hv_s0_m": s["hv_initial_state"][0],
        "hv_v0_mps": s["hv_initial_state"][1],
        **{k: s[k] for k in _METRICS},
        "safety_distance_m": rec.scenario.min_dist_m,  # the pair's, as the kernels use it
        "config_hash": config.digest(),
        "version": __version__,
    }


@dataclass(frozen=True)
class RunFailure:
    """A run that raised instead of finishing: which one, and the one-line error."""

    table: str
    row: int
    seed: int
    config_hash: str
    error: str

    def describe(self) -> str:
        return (f"{self.table} row {self.row} seed {self.seed} (config {self.config_hash}): "
                f"{self.error}")


def check_seeds(seeds: Any, n_rows: int, name: str = "seeds", rows: str = "rows") -> int:
    """``seeds`` (seeds ``1..seeds`` for each of ``n_rows`` rows), or :class:`ConfigError`:
    an integer in ``[1, 2^32 - 1]`` giving at most :data:`MAX_RUNS` runs in all. ``name``
    and ``rows`` name the parameter and the rows in the message."""
    if isinstance(seeds, bool) or not isinstance(seeds, int) or not 1 <= seeds <= SEED_MAX:
        raise ConfigError(f"{name} = {seeds!r} is out of range; allowed: integer in "
                          f"[1, {SEED_MAX}]")
    if seeds * n_rows > MAX_RUNS:
        raise ConfigError(f"{name} = {seeds} is out of range; allowed: 1..{MAX_RUNS // n_rows} "
                          f"for {n_rows} {rows} (at most {MAX_RUNS} runs, summarised in "
                          "memory; 'persuasive sweep' streams more to disk)")
    return seeds


def _run_chunk(task: tuple[str, int, str, list[int]]) -> tuple[list[dict], list[RunFailure]]:
    """The runs of one chunk; a run that raises is recorded as failed, the others go on."""
    table, row, config_toml, seeds = task
    config = Config.from_dict(tomllib.loads(config_toml))
    done, failed = [], []
    for seed in seeds:
        try:
            done.append(run_record(table, row, config, seed))
        except Exception as exc:  # noqa: BLE001 - report the run, keep the others
            text = str(exc).strip().splitlines()
            failed.append(RunFailure(table, row, seed, config.digest(),
                                     f"{exc.__class__.__name__}: {text[0] if text else ''}"))
    return done, failed


def _tasks(tables: Iterable[str], base: Config, seeds: int, chunk: int):
    for table in tables:
        for i, row in enumerate(PUBLISHED[table]):
            cfg = row.config(base).to_toml()
            for lo in range(1, seeds + 1, chunk):
                yield table, i, cfg, list(range(lo, min(lo + chunk, seeds + 1)))


def run_tables(tables: Iterable[str], seeds: int = 1000, workers: int | None = None,
               mode: str | None = None, base: Config | None = None, chunk: int = 25,
               progress: Callable[[int, int, int], None] | None = None,
               failures: list[RunFailure] | None = None) -> list[dict[str, Any]]:
    """Run every row of ``tables`` for seeds ``1..seeds``; one dict per run, in order.

    ``mode``: overrides ``base.mode`` when given. ``workers``: processes (default: all cores,
    never more than the chunks of ``chunk`` runs; 1 runs in this process), started from the
    fork server and ending when this process dies (:mod:`persuasive._processes`). ``progress(done_runs, total_runs, rows_done)`` is called as chunks
    finish. A run that raises is left out of the result and appended to ``failures`` (when
    given) as a :class:`RunFailure`; the others go on.
    """
    tables = list(tables)
    for t in tables:
        if t not in PUBLISHED:
            raise ConfigError(f"table = {t!r} is out of range; allowed: {' | '.join(TABLES)}")
    check_seeds(seeds, sum(len(PUBLISHED[t]) for t in tables))
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ConfigError(f"chunk = {chunk!r} is out of range; allowed: integer >= 1")
    workers = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers = {workers!r} is out of range; allowed: integer >= 1")
    base = base or Config()
    if mode is not None:
        base = base.with_overrides({"mode": mode})
    tasks = list(_tasks(tables, base, seeds, chunk))
    workers = min(workers, len(tasks))
    total = sum(len(t[3]) for t in tasks)
    per_row: dict[tuple[str, int], int] = {}
    for t in tasks:
        per_row[(t[0], t[1])] = per_row.get((t[0], t[1]), 0) + len(t[3])
    results: dict[tuple[str, int, int], list[dict[str, Any]]] = {}
    failed: list[RunFailure] = []
    done, rows_done, left = 0, 0, dict(per_row)

    def collect(task, outcome):
        nonlocal done, rows_done
        records, bad = outcome
        results[(task[0], task[1], task[3][0])] = records
        failed.extend(bad)
        done += len(task[3])
        left[(task[0], task[1])] -= len(task[3])
        rows_done += left[(task[0], task[1])] == 0
        if progress is not None:
            progress(done, total, rows_done)

    if workers == 1:
        for task in tasks:
            collect(task, _run_chunk(task))
    else:
        warm_up()  # compile once here rather than in every worker at the same time
        with ProcessPoolExecutor(max_workers=workers, mp_context=context()) as pool:
            for task, outcome in zip(tasks, pool.map(_run_chunk, tasks)):
                collect(task, outcome)
    if failures is not None:
        failures.extend(sorted(failed, key=lambda f: (TABLES.index(f.table), f.row, f.seed)))
    return [rec for key in sorted(results, key=lambda k: (TABLES.index(k[0]), k[1], k[2]))
            for rec in results[key]]


def summarize(runs: list[dict[str, Any]], table: str, base: Config | None = None,
              seeds: int | None = None,
              failures: Iterable[RunFailure] = ()) -> dict[str, Any]:
    """The printed table of docs/method.md §8 for ``table``'s rows in ``runs``.

    Safety violations compare each run's distances with that run's own
    ``safety_distance_m``.
    ``base`` and ``seeds`` (the configuration and seed count the runs were made with) are
    recorded with their TOML text and digest; ``failures`` are listed. The differences to
    the published shares are given for seeds 1..1000 only (those of the published tables);
    with other seeds they are None.
    """
    if seeds is None:
        seeds = max((r["seed"] for r in runs if r["table"] == table), default=0)
    comparable = seeds == PUBLISHED_SEEDS
    rows = []
    for i, spec in enumerate(PUBLISHED[table]):
        mine = [r for r in runs if r["table"] == table and r["row"] == i]
        if not mine:
            continue
        first = np.array([r["first_at_line"] for r in mine])
        n = len(mine)
        av, hv = int(np.sum(first == 1)), int(np.sum(first == 2))
        av_pct, hv_pct = round(100.0 * av / n, 10), round(100.0 * hv / n, 10)
        rows.append({
            "hv_role": spec.hv_role,
            "pa": spec.pa,
            "pa_hat": spec.pa_hat,
            "runs": n,
            "av_first": av,
            "hv_first": hv,
            "same_step": int(np.sum(first == 3)),
            "neither": int(np.sum(first == 0)),
            "av_first_pct": av_pct,
            "hv_first_pct": hv_pct,
            "published_av_first_pct": spec.published_av_first_pct,
            "published_hv_first_pct": spec.published_hv_first_pct,
            "diff_av_first_pct": round(av_pct - spec.published_av_first_pct, 10)
            if comparable else None,
            "diff_hv_first_pct": round(hv_pct - spec.published_hv_first_pct, 10)
            if comparable else None,
            "collisions": int(sum(r["collision"] for r in mine)),
            "runs_with_infeasible": int(sum(r["infeasible_steps"] > 0 for r in mine)),
            "violations_to_line": int(sum(r["min_distance_to_line_m"] < r["safety_distance_m"]
                                          for r in mine)),
            "violations_whole_run": int(sum(r["min_distance_m"] < r["safety_distance_m"]
                                            for r in mine)),
            "config_hash": mine[0]["config_hash"],
        })
    mode = base.mode if base is not None else (runs[0]["mode"] if runs else None)
    out: dict[str, Any] = {"table": table, "mode": mode, "seeds": seeds,
                           "seed_range": [1, seeds], "rows": rows,
                           "scenario": base.scenario.kind if base is not None else
                           "intersection"}
    if base is not None:
        out["config_hash"] = settings_digest(base, table, seeds)
        out["config_toml"] = base.to_toml()
    out["failures"] = [vars(f) for f in failures if f.table == table]
    out["version"] = __version__
    return out


def settings_digest(base: Config, table: str, seeds: int) -> str:
    """The digest naming a reproduction: base configuration, table and seed range."""
    return base.digest(table, 1, seeds)


def default_folder(base: Config, table: str, seeds: int) -> Path:
    """``results/<table>-<mode>-<digest>``: runs made with other settings never share it."""
    return Path("results") / f"{table}-{base.mode}-{settings_digest(base, table, seeds)}"


def check_folder(folder: str | Path, settings, force: bool = False) -> None:
    """Refuse (:class:`ConfigError`) a results folder holding something else than this
    reproduction. ``settings``: the table's sweep grid (:func:`table_grid`; the folder must be
    that sweep's, checked before any run) or a summary's ``config_hash`` (the folder's
    ``summary.json`` must carry it). Nothing is refused with ``force``."""
    from .sweep import Grid, read_manifest

    folder = Path(folder)
    if force or not folder.exists():
        return
    if not folder.is_dir():
        raise OutputError(f"results folder {str(folder)!r} cannot be written: it is a file")
    if not any(not is_lock_file(p.name) for p in folder.iterdir()):
        return
    if isinstance(settings, Grid):
        try:
            same = read_manifest(folder).get("grid_digest") == settings.digest
        except ConfigError:
            raise OutputError(f"results folder {str(folder)!r} holds other files; choose "
                              "another --out or pass --force to replace it") from None
    else:
        try:
            old = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            raise OutputError(f"results folder {str(folder)!r} holds other files; choose "
                              "another --out or pass --force to replace it") from None
        same = old.get("config_hash") == settings
    if not same:
        raise OutputError(
            f"results folder {str(folder)!r} holds results made with other settings; choose "
            "another --out or pass --force to replace them")


def matches_published(summary: dict[str, Any]) -> bool:
    """Every row's AV-first and HV-first shares equal the published ones at one decimal."""
    return all(
        round(r["av_first_pct"], 1) == r["published_av_first_pct"]
        and round(r["hv_first_pct"], 1) == r["published_hv_first_pct"]
        for r in summary["rows"]
    )


def verdict(summary: dict[str, Any], base: Config) -> str:
    """One sentence on how a summary relates to the published table."""
    n = summary["seeds"]
    if base.scenario.kind != "intersection":
        return (f"the {base.scenario.kind} scenario: the paper published no values for it "
                "(its table is for the intersection).")
    if base.mode != "paper":
        return (f"{base.mode} mode: the published values (paper mode) are shown for "
                "comparison only.")
    if base != Config():
        return ("the configuration differs from the paper's, so the published values are "
                "shown for comparison only.")
    if n != PUBLISHED_SEEDS:
        return (f"the published values are for seeds 1..1000; with seeds 1..{n} the shares "
                "differ by sampling, so they are not compared (run with the default --seeds "
                "1000 to compare).")
    if matches_published(summary):
        return "every AV-first and HV-first cell equals the published one."
    return "NOT every cell equals the published one."


def to_markdown(summary: dict[str, Any]) -> str:
    """The summary as a Markdown table (one line per row). The published shares and the
    differences are shown beside those of seeds 1..1000 in the intersection only (the
    published tables'); other tables say why in :func:`verdict`."""
    t2 = summary["table"] == "table2"
    scenario = summary.get("scenario", "intersection")
    published = scenario == "intersection" and summary.get("seeds") == PUBLISHED_SEEDS
    head = ["HV initial role", "p_a"] + (["p_a_hat"] if t2 else []) + [
        "AV first %", "HV first %"] + (["published AV/HV %", "diff AV/HV"] if published
                                        else []) + [
        "same step", "neither", "collisions", "runs infeasible", "violations to line",
        "violations whole run"]
    where = "" if scenario == "intersection" else f", {scenario} scenario"
    lines = [
        f"**{summary['table']}**{where}, {summary['mode']} mode, seeds 1..{summary['seeds']}",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for r in summary["rows"]:
        cells = ["L" if r["hv_role"] == "leader" else "F", f"{r['pa']:.2f}"]
        if t2:
            cells.append(f"{r['pa_hat']:.2f}")
        cells += [f"{r['av_first_pct']:.1f}", f"{r['hv_first_pct']:.1f}"]
        if published:
            cells += [f"{r['published_av_first_pct']:.1f} / {r['published_hv_first_pct']:.1f}",
                      f"{r['diff_av_first_pct']:+.1f} / {r['diff_hv_first_pct']:+.1f}"]
        cells += [
            str(r["same_step"]), str(r["neither"]), str(r["collisions"]),
            str(r["runs_with_infeasible"]), str(r["violations_to_line"]),
            str(r["violations_whole_run"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class Reproduction:
    """The runs and summaries of one ``reproduce`` call."""

    runs: Any  #: pandas DataFrame, one row per run (``RUN_COLUMNS``)
    summaries: dict[str, dict[str, Any]]  #: per table, as :func:`summarize`
    wall_time_s: float
    failures: tuple[RunFailure, ...] = ()  #: runs that raised (left out of ``runs``)
    base: Config | None = None  #: the base configuration of every row
    folders: dict[str, Path] | None = None  #: per table, its results folder (when saved)
    skipped: int = 0  #: runs finished by an earlier call into the same folders
    ran: int = 0  #: runs computed by this call (failed ones included)


def table_grid(table: str, base: Config, seeds: int):
    """A table as a sweep grid: its rows as cases (``case`` = row), seeds ``1..seeds``."""
    from .sweep import Grid

    if table not in PUBLISHED:
        raise ConfigError(f"table = {table!r} is out of range; allowed: {' | '.join(TABLES)}")
    check_seeds(seeds, len(PUBLISHED[table]))
    return Grid(base, (), 1, seeds, cases=tuple(row.overrides() for row in PUBLISHED[table]))


def runs_of(table: str, frame) -> list[dict[str, Any]]:
    """A table's sweep dataset as results rows (``RUN_COLUMNS``), in (row, seed) order."""
    out = []
    for rec in frame.sort_values("run").to_dict("records"):
        row = {"table": table, "row": int(rec["case"])}
        for key in RUN_COLUMNS[2:]:
            if key in rec:
                row[key] = rec[key]
        row["av_s0_m"], row["av_v0_mps"] = rec["av_initial_state.0"], rec["av_initial_state.1"]
        row["hv_s0_m"], row["hv_v0_mps"] = rec["hv_initial_state.0"], rec["hv_initial_state.1"]
        if row.get("av") == "lfg":
            row["pa_hat"] = None
        for key in ("first_at_line", "first_at_conflict_point", "idx_end", "infeasible_steps",
                    "hv_role_changes", "av_role_changes", "seed", "row"):
            row[key] = int(row[key])
        row["collision"] = bool(row["collision"])
        out.append({key: row.get(key) for key in RUN_COLUMNS})
    return out


def reproduce(table: str = "all", seeds: int = 1000, workers: int | None = None,
              mode: str | None = None, base: Config | None = None,
              progress: Callable[[int, int, int], None] | None = None,
              out: str | Path | Mapping[str, str | Path] | None = None,
              force: bool = False, scheduler: str | None = None) -> Reproduction:
    """Rerun the paper's tables: ``table`` is "table1", "table2" or "all".

    The runs go through the sweep runner (``persuasive.sweep``, Dask): each table is a sweep
    whose cases are its rows, so a reproduction into a folder resumes where it stopped; one
    local cluster runs every table. ``out``: the results folder (with ``"all"``, one subfolder
    per table), or a mapping of table to folder; without it the runs go to a folder in the
    command's scratch folder, removed at the end. ``mode`` overrides ``base.mode`` when given (``base`` defaults to the
    paper's values). A folder holding another reproduction is refused unless ``force``.
    """
    import contextlib
    import shutil

    import pandas as pd

    from . import sweep
    from ._processes import scratch_dir
    from .sweep.runner import local_cluster, pending_chunks

    if table not in (*TABLES, "all"):
        raise ConfigError(f"table = {table!r} is out of range; allowed: "
                          f"{' | '.join((*TABLES, 'all'))}")
    tables = TABLES if table == "all" else (table,)
    check_seeds(seeds, sum(len(PUBLISHED[t]) for t in tables))
    base = base or Config()
    if mode is not None:
        base = base.with_overrides({"mode": mode})
    grids = {t: table_grid(t, base, seeds) for t in tables}  # checks everything first
    total = sum(len(g) for g in grids.values())
    finished: dict[str, int] = {t: 0 for t in tables}
    rows_of = {t: len(PUBLISHED[t]) for t in tables}

    def tracker(t):
        def update(done: int, _total: int) -> None:
            finished[t] = done
            if progress is not None:
                rows = sum(finished[u] // seeds for u in tables if u in finished)
                progress(sum(finished.values()), total, min(rows, sum(rows_of.values())))
        return update

    t0 = time.perf_counter()
    runs: list[dict[str, Any]] = []
    failures: list[RunFailure] = []
    folders: dict[str, Path] = {}
    skipped = ran = 0
    scratch = scratch_dir("reproduce-") if out is None else None
    what = "results folder"
    if out is None:
        targets = {t: scratch / t for t in tables}
    elif isinstance(out, Mapping):
        targets = {t: Path(out[t]) for t in tables}
    else:
        targets = {t: Path(out) / t if table == "all" else Path(out) for t in tables}
    try:
        with contextlib.ExitStack() as stack:
            client = None
            if scheduler is None:  # one cluster for every table (never one per table)
                chunks = max(pending_chunks(grids[t], targets[t], None, force, what)
                             for t in tables)
                client = stack.enter_context(local_cluster(list(grids.values()), chunks,
                                                           workers))
            for t in tables:
                folder = targets[t]
                if client is not None:
                    result = sweep.run(grids[t], folder, client=client, force=force,
                                       progress=tracker(t), what=what)
                else:
                    result = sweep.run(grids[t], folder, workers=workers, scheduler=scheduler,
                                       force=force, progress=tracker(t), what=what)
                runs += runs_of(t, sweep.load(folder))
                skipped, ran = skipped + result.skipped, ran + result.ran
                for f in result.failures:
                    failures.append(RunFailure(t, int(f["axes"][CASE]), int(f["seed"]),
                                               f["config_hash"], f["error"]))
                if out is not None:
                    folders[t] = folder
    finally:
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
    wall = time.perf_counter() - t0
    summaries = {t: summarize(runs, t, base, seeds, failures) for t in tables}
    for t, folder in folders.items():  # a results folder is complete: runs and summary
        _write_summary(folder, summaries[t], atomic=True)
    frame = pd.DataFrame(runs, columns=list(RUN_COLUMNS))
    return Reproduction(frame, summaries, wall, tuple(failures), base, folders or None,
                        skipped, ran)


#: The files :func:`save` writes into a folder of its own (:func:`persuasive._files.atomic_folder`
#: replaces these and keeps every other file).
SAVED_FILES = ("runs.parquet", "summary.json", "summary.md", "config.toml")


def save(result: Reproduction, table: str, out: str | Path, force: bool = True) -> Path:
    """Write ``table``'s summary (JSON, Markdown), configuration (TOML) and, when the runs are
    not there already, the runs (Parquet) into the folder ``out``, each file atomically.

    Without ``force``, a folder holding results made with other settings is refused
    (:func:`check_folder`); with it, the files of :data:`SAVED_FILES` are replaced and every
    other file in ``out`` is kept. After :func:`reproduce` with ``out``, the folder is already
    the table's sweep folder (its runs in ``runs/``) and this adds the summary beside them.
    """
    out = Path(out)
    summary = result.summaries[table]
    own = result.folders is not None and result.folders.get(table) == out
    if not own:
        check_folder(out, summary.get("config_hash", ""), force)
        runs = result.runs[result.runs["table"] == table]
        with atomic_folder(out, owned=SAVED_FILES) as tmp:
            runs.to_parquet(tmp / "runs.parquet", index=False)
            _write_summary(tmp, summary)
        return out
    _write_summary(out, summary, atomic=True)
    return out


def _write_summary(folder: Path, summary: dict[str, Any], atomic: bool = False) -> None:
    files = {"summary.json": json.dumps(summary, indent=2) + "\n",
             "summary.md": to_markdown(summary)}
    if "config_toml" in summary:
        files["config.toml"] = summary["config_toml"]
    for name, text in files.items():
        if atomic:
            atomic_write(folder / name, lambda p, text=text: p.write_text(text, encoding="utf-8"))
        else:
            (folder / name).write_text(text, encoding="utf-8")


def load_summary(folder: str | Path) -> dict[str, Any]:
    """Read a summary written by :func:`save`."""
    path = Path(folder) / "summary.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:  # JSONDecodeError and UnicodeDecodeError included
        raise ConfigError(f"results folder {str(folder)!r} has no readable summary.json "
                          f"({exc.__class__.__name__})") from None
