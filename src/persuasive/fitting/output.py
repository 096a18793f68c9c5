"""The files of a fit: the report as JSON, and the runs with their smoothed roles as Parquet.

A fit's Parquet file (``persuasive fit LOGS --out FIT.parquet``) holds every fitted run's
per-step log, one run after the other, with four columns added:

- ``fit_run``: the run's index in the fit (0, 1, ...), ``fit_source``: its log file,
  ``fit_group``: its participant in a per-participant fit (else empty);
- ``hv_fit_p_leader``: ``P(the human's role = L | the whole run)`` at each step, smoothed under
  the fit's role model (``hv_fit_role_model``).

Its metadata (key ``persuasive.fit``) holds the report (:meth:`FitReport.to_dict`) and, per
run, its columns and its run record (configuration, seed, final state), so that
:func:`load_fitted_run` gives back the :class:`persuasive.simulation.RunRecord` of any run,
with ``hv_fit_p_leader`` in its log: ``persuasive plot profile --from FIT.parquet --run K``
draws it over the role row.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import numpy as np

from ..config import ConfigError

#: Key of a fit's metadata in its Parquet schema.
FIT_METADATA = b"persuasive.fit"
#: File extensions ``fit --out`` writes.
OUT_EXTENSIONS = (".json", ".parquet")


def report_dict(reports: Sequence, runs: bool = True) -> dict:
    """The JSON report of one fit, or of a per-participant fit (``groups``)."""
    from .._version import __version__

    if len(reports) == 1 and reports[0].group is None:
        body = reports[0].to_dict(runs)
    else:
        body = {"groups": [r.to_dict(runs) for r in reports]}
    return {"version": __version__, **body}


def write_json(path: str | Path, payload: dict) -> None:
    from .._files import atomic_write

    text = json.dumps(payload, indent=2, allow_nan=False)
    atomic_write(path, lambda p: Path(p).write_text(text + "\n", encoding="utf-8"))


def write_fit_parquet(path: str | Path, reports: Sequence, payload: dict) -> None:
    """Write the fitted runs with their smoothed roles (see the module docstring)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from .._files import atomic_write

    tables, runs_meta = [], []
    k = 0
    for report in reports:
        ev = report.evidence
        for i, log in enumerate(ev.runs):
            table = pq.read_table(log.source)
            table = table.replace_schema_metadata(None)
            a, b = ev.starts[i], ev.starts[i + 1]
            n = table.num_rows
            p = (report.p_leader[a:b] if report.p_leader is not None
                 else np.full(n, np.nan))
            table = (table
                     .append_column("fit_run", pa.array(np.full(n, k, np.int64)))
                     .append_column("fit_source", pa.array([log.source] * n))
                     .append_column("fit_group", pa.array([report.group or ""] * n))
                     .append_column("hv_fit_p_leader", pa.array(np.asarray(p, float)))
                     .append_column("hv_fit_role_model",
                                    pa.array([report.role_model or ""] * n)))
            tables.append(table)
            runs_meta.append({"source": log.source, "columns": table.column_names,
                              "record": log.meta})
            k += 1
    table = pa.concat_tables(tables, promote_options="default")
    meta = {"report": payload, "runs": runs_meta}
    table = table.replace_schema_metadata({FIT_METADATA: json.dumps(meta, allow_nan=False)})
    atomic_write(path, lambda p: pq.write_table(table, p))


def is_fit_file(path: str | Path) -> bool:
    """Whether ``path`` is a fit's Parquet file (it holds :data:`FIT_METADATA`)."""
    import pyarrow.parquet as pq

    try:
        return FIT_METADATA in (pq.read_schema(path).metadata or {})
    except Exception:  # noqa: BLE001 - not a Parquet file at all
        return False


def load_fitted_run(path: str | Path, run: int = 0):
    """The :class:`persuasive.simulation.RunRecord` of run ``run`` of a fit's Parquet file,
    its log holding ``hv_fit_p_leader``."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from ..record import record_from_frame

    table = pq.read_table(path)
    meta = json.loads(table.schema.metadata[FIT_METADATA])
    runs = meta["runs"]
    if not isinstance(run, int) or not 0 <= run < len(runs):
        raise ConfigError(f"--run = {run!r} is out of range for fit file {str(path)!r}; "
                          f"allowed: 0..{len(runs) - 1}")
    entry = runs[run]
    sub = table.filter(pc.equal(table["fit_run"], run)).select(entry["columns"])
    return record_from_frame(entry["record"], sub.to_pandas(), "")


__all__ = ["FIT_METADATA", "OUT_EXTENSIONS", "is_fit_file", "load_fitted_run",
           "report_dict", "write_fit_parquet", "write_json"]
