"""One chunk of a sweep's runs as one Parquet part: flat rows, fixed columns and types.

A run's row is, in this order: ``run`` (its index in the grid), one column per axis (named by
the dotted field, holding the axis value), ``seed``, ``config_hash``
(:meth:`Config.digest`), then :meth:`RunRecord.summary` flattened by :func:`flatten`: nested
dicts as dotted columns (``quirks.q1_branch_time_offset``), lists as one column per element
(``hv_initial_state.0``, ``hv_initial_state.1``). A summary field already present as a column
(``seed``; ``mode`` or a quirk when it is an axis) is not repeated: both hold the same value.

The part's bytes depend only on its runs: no time stamps, timings or worker names; columns in
the order above; types from the values (``bool``, ``int64``, ``float64``, ``string``; a column
mixing integers and floats is ``float64``; a value of None is a null, and a column of nulls
only is ``float64``). Its schema metadata (key ``persuasive.sweep``)
lists the summary's flattened columns, so :func:`unflatten` gives the summary back exactly.

A run that raises is left out of the part and reported as a failure record: ``run``,
``seed``, the axis values, ``config_hash`` and a one-line ``error``; the other runs go on.
"""

from __future__ import annotations

import json
import math
from typing import Any, Mapping

from .grid import Grid

#: Schema metadata key of a part: JSON ``{"axes": [...], "summary_columns": [...]}``.
METADATA_KEY = b"persuasive.sweep"


def flatten(summary: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dicts and lists as one level of dotted keys (list elements by position).

    ``{"a": {"b": 1}, "c": [2.0, 3.0]}`` becomes ``{"a.b": 1, "c.0": 2.0, "c.1": 3.0}``;
    :func:`unflatten` undoes it. Empty dicts and lists have no column.
    """
    out: dict[str, Any] = {}
    for key, value in summary.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, name + "."))
        elif isinstance(value, (list, tuple)):
            out.update(flatten({str(i): v for i, v in enumerate(value)}, name + "."))
        else:
            out[name] = value
    return out


def _plain(value: Any) -> Any:
    """A dataset value as ``summary()`` holds it: a NumPy scalar as the Python value, a
    missing value (null in Parquet, NaN or NA in pandas) as None."""
    item = getattr(value, "item", None)
    if callable(item) and getattr(value, "shape", None) == ():
        value = item()
    import pandas as pd  # imported where the dataset is read back, not by every worker

    if value is None or value is pd.NA or value is pd.NaT or (
            isinstance(value, float) and math.isnan(value)):
        return None
    return value


def unflatten(flat: Mapping[str, Any]) -> dict[str, Any]:
    """The nested summary of :func:`flatten`'s dotted keys (``"c.0"``, ``"c.1"`` -> a list)."""
    root: dict[str, Any] = {}
    for key, value in flat.items():
        *path, last = key.split(".")
        node = root
        for part in path:
            node = node.setdefault(part, {})
        node[last] = _plain(value)

    def lists(node: Any) -> Any:
        if not isinstance(node, dict):
            return node
        node = {k: lists(v) for k, v in node.items()}
        if node and all(k.isdigit() for k in node) and \
                sorted(int(k) for k in node) == list(range(len(node))):
            return [node[str(i)] for i in range(len(node))]
        return node

    return lists(root)


def _error_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{exc.__class__.__name__}: {text[0]}" if text else exc.__class__.__name__


def failure_record(grid: Grid, index: int, error: str) -> dict[str, Any]:
    """The record of run ``index`` that raised ``error`` (one line)."""
    values, _, seed = grid.run(index)
    return {"run": index, "seed": seed, "axes": values, "config_hash": grid.config_hash(index),
            "error": error}


def run_rows(grid: Grid, start: int, stop: int) -> tuple[dict[str, list[Any]], list[str],
                                                          list[dict[str, Any]]]:
    """Runs ``start .. stop - 1`` as columns: ``(columns, summary columns, failure records)``.

    ``columns`` maps each column name (in first-seen order) to one value per finished run;
    a column a run does not have holds None for it.
    """
    from ..simulation import run_summary

    columns: dict[str, list[Any]] = {}
    summary_columns: dict[str, None] = {}
    failures: list[dict[str, Any]] = []
    names, n_seeds, n = grid.names, grid.n_seeds, 0
    combos: dict[int, tuple[tuple[Any, ...], Any, str]] = {}
    for index in range(start, stop):
        combo, offset = divmod(index, n_seeds)
        if combo not in combos:
            combos[combo] = (grid.combination(combo), grid.config(combo),
                             grid.config_hash(index))
        values, config, config_hash = combos[combo]
        seed = grid.seed_start + offset
        try:
            flat = flatten(run_summary(config, seed))
        except Exception as exc:  # noqa: BLE001 - record the run, keep the others
            failures.append(failure_record(grid, index, _error_line(exc)))
            continue
        row = {"run": index, **dict(zip(names, values)), "seed": seed,
               "config_hash": config_hash}
        for key, value in flat.items():
            row.setdefault(key, value)
            summary_columns.setdefault(key)
        for key, value in row.items():
            column = columns.get(key)
            if column is None:
                column = columns[key] = [None] * n
            column.append(value)
        n += 1
        if len(row) < len(columns):  # a field this run's summary does not have
            for column in columns.values():
                if len(column) < n:
                    column.append(None)
    return columns, list(summary_columns), failures


def _arrow_type(values: list[Any]):
    import pyarrow as pa

    kinds = {type(v) for v in values if v is not None}
    if not kinds:
        # nulls only in this chunk: most optional summary fields are numbers (times) that
        # other chunks hold, so the parts agree on the type
        return pa.float64()
    if kinds <= {bool}:
        return pa.bool_()
    if kinds <= {int}:
        return pa.int64()
    if kinds <= {int, float}:
        return pa.float64()
    if kinds <= {str}:
        return pa.string()
    raise TypeError(f"a summary column mixes {', '.join(sorted(k.__name__ for k in kinds))}")


def to_parquet(columns: dict[str, list[Any]], axes: tuple[str, ...],
               summary_columns: list[str]) -> bytes:
    """``columns`` (as :func:`run_rows` returns them) as the bytes of one Parquet file."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays, fields = [], []
    for name, values in columns.items():
        kind = _arrow_type(values)
        if pa.types.is_floating(kind):
            values = [None if v is None else float(v) for v in values]
        arrays.append(pa.array(values, type=kind))
        fields.append(pa.field(name, kind))
    meta = json.dumps({"axes": list(axes), "summary_columns": summary_columns},
                      separators=(",", ":"))
    schema = pa.schema(fields, metadata={METADATA_KEY: meta.encode()})
    sink = pa.BufferOutputStream()
    pq.write_table(pa.Table.from_arrays(arrays, schema=schema), sink, compression="snappy")
    return sink.getvalue().to_pybytes()


def run_chunk(grid: Grid, start: int, stop: int) -> tuple[bytes | None, list[dict[str, Any]]]:
    """The work of one chunk: ``(Parquet part or None, failure records)``.

    The part is None when every run failed (there is nothing to write).
    """
    columns, summary_columns, failures = run_rows(grid, start, stop)
    part = to_parquet(columns, grid.names, summary_columns) if columns else None
    return part, failures


#: Grids a worker process has unpickled, by digest (a few sweeps at most).
_GRIDS: dict[str, Grid] = {}


def run_pickled_chunk(digest: str, grid_pickle: bytes, start: int,
                      stop: int) -> tuple[bytes | None, list[dict[str, Any]]]:
    """:func:`run_chunk` on a worker, the grid sent as pickled bytes (cheap to send with
    every chunk) and unpickled once per worker process, so that its configurations are
    built once too."""
    grid = _GRIDS.get(digest)
    if grid is None:
        import pickle

        if len(_GRIDS) >= 4:
            _GRIDS.clear()
        grid = _GRIDS[digest] = pickle.loads(grid_pickle)
    return run_chunk(grid, start, stop)


__all__ = ["METADATA_KEY", "flatten", "run_chunk", "run_pickled_chunk", "run_rows", "to_parquet",
           "unflatten"]
