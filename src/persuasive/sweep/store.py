"""A sweep's folder: a manifest, one Parquet part per chunk, one failure file per bad chunk.

Layout of ``DIR``::

    DIR/manifest.json                      the sweep: grid, version, runs, chunks, chunk ids
    DIR/runs/part-<k>-<hash>.parquet       the runs of chunk k that finished (one row each)
    DIR/failed/failed-<k>-<hash>.json      the runs of chunk k that raised (if any)

``<k>`` is the chunk's index (zero-padded, so that names sort in run order) and ``<hash>`` a
hash of the grid's digest and the chunk's run range: the chunk id (:func:`chunk_id`).
``DIR/runs`` holds only the parts, so ``pandas.read_parquet(DIR / "runs")`` reads the dataset;
:func:`load` does the same in run order and tolerates parts whose columns differ.

The chunks are planned lazily: chunk ``k`` is computed from its index when it is needed, and
the manifest holds their size and number, not a list, so a sweep of billions of runs takes no
more memory or manifest than a small one.

Every file is written through a temporary sibling, fsynced and renamed
(:func:`persuasive._files.atomic_write`), the manifest first. A chunk is finished when its
part exists and it has no failure file; for a chunk with failures the failure file is written
before the part and removed only after a retry succeeds, so a process killed at any moment
leaves every chunk either finished, to be retried, or not started, never half-written.
Temporary files a kill leaves behind (hidden names) are removed when the sweep resumes.

A sweep's own files are those of the names above: ``manifest.json``, ``runs/part-*.parquet``
and ``failed/failed-*.json`` (the studies on top add their summaries). Replacing another
sweep (``force``) removes only those, and ``runs/`` and ``failed/`` once empty; anything else
in the folder or in those two (a user's ``notes.txt``, a subfolder) is kept
(:mod:`persuasive._files`: one meaning of ``--force``).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, NamedTuple

from .._version import __version__
from .._files import OutputError, atomic_write, check_output_folder, is_lock_file
from ..config import ConfigError
from .grid import Grid

#: Names of the manifest's temporary files (:func:`persuasive._files.atomic_write`).
_MANIFEST_TMP = re.compile(r"\.manifest\..*\.tmp\.json")
#: What a study calls its sweep, by the name of its folder (for messages).
_KINDS = {"sweep folder": "sweep", "comparison folder": "comparison",
          "results folder": "reproduction"}

#: Format tag of ``manifest.json``.
FORMAT = "persuasive-sweep-1"
MANIFEST = "manifest.json"
RUNS = "runs"
FAILED = "failed"


def chunk_ranges(n_runs: int, chunk: int) -> list[tuple[int, int]]:
    """``(start, stop)`` of every chunk of ``chunk`` consecutive runs (the last may be short)."""
    return [(lo, min(lo + chunk, n_runs)) for lo in range(0, n_runs, chunk)]


def default_chunk(n_runs: int) -> int:
    """Runs per chunk when none is given: about 32 chunks, 1 to 250 runs each.

    A chunk is one Dask task and one Parquet part; each costs the client a few milliseconds
    of CPU, so chunks of a few hundred runs (0.2 to 1 s of work) keep that small, while 32
    chunks or more keep 16 workers busy and make resuming cheap. The size depends on the
    grid only (not on the machine), so the same grid gives the same parts everywhere; pass
    ``chunk`` for a cluster of more workers.
    """
    return max(1, min(250, -(-n_runs // 32)))


def n_chunks(n_runs: int, chunk: int) -> int:
    """The number of chunks of ``chunk`` consecutive runs (the last may be short)."""
    return -(-n_runs // chunk)


def _id_width(count: int) -> int:
    return max(6, len(str(count - 1)))


def chunk_id(digest: str, k: int, lo: int, hi: int, count: int) -> str:
    """``<k>-<hash>`` of chunk ``k`` of ``count`` (runs ``lo .. hi - 1``): its index and a hash
    of the grid and its run range."""
    return (f"{k:0{_id_width(count)}d}-"
            + hashlib.sha256(f"{digest}:{lo}:{hi}".encode()).hexdigest()[:10])


def chunk_ids(digest: str, ranges: list[tuple[int, int]]) -> list[str]:
    """:func:`chunk_id` of each chunk of ``ranges``."""
    return [chunk_id(digest, k, lo, hi, len(ranges)) for k, (lo, hi) in enumerate(ranges)]


class Pending(NamedTuple):
    """What is left of a sweep: the number of runs, and their chunks in order (an iterator,
    planned as it is consumed)."""

    runs: int
    chunks: Iterator[Chunk]


@dataclass(frozen=True)
class Chunk:
    """One chunk of a sweep: index, id and run range ``start .. stop - 1``."""

    index: int
    id: str
    start: int
    stop: int

    @property
    def size(self) -> int:
        return self.stop - self.start

    @property
    def part_name(self) -> str:
        return f"part-{self.id}.parquet"

    @property
    def failed_name(self) -> str:
        return f"failed-{self.id}.json"


def _dump(data: Any) -> bytes:
    return (json.dumps(data, indent=1) + "\n").encode("utf-8")


def _write_bytes(path: Path, data: bytes) -> None:
    atomic_write(path, lambda tmp: tmp.write_bytes(data))


def _remove_temporaries(folder: Path) -> None:
    """Hidden temporary files that a killed process left (``atomic_write``'s names)."""
    if folder.is_dir():
        for child in folder.iterdir():
            if child.name.startswith(".") and ".tmp" in child.name and child.is_file():
                child.unlink(missing_ok=True)


def read_manifest(folder: str | Path) -> dict[str, Any]:
    """The manifest of the sweep in ``folder``; :class:`ConfigError` if there is none."""
    path = Path(folder) / MANIFEST
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"sweep folder {str(folder)!r} has no {MANIFEST} (not a sweep "
                          "written by 'persuasive sweep')") from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"sweep folder {str(folder)!r}: {MANIFEST} cannot be read "
                          f"({exc.__class__.__name__})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ConfigError(f"sweep folder {str(folder)!r}: {MANIFEST} is not a sweep manifest "
                          f"(format {FORMAT})")
    return data


class SweepStore:
    """The files of one sweep in its folder (see the module docstring)."""

    def __init__(self, folder: Path, grid: Grid, chunk: int, manifest: dict[str, Any],
                 what: str = "sweep folder", new: bool = False, replace: bool = False):
        self.folder = folder
        self.grid = grid
        self.chunk = chunk
        self.manifest = manifest
        self.what = what  #: how the command names the folder, for messages
        self.n_runs = len(grid)
        self.n_chunks = n_chunks(self.n_runs, chunk)
        self._new = new  # the manifest is still to be written
        self._replace = replace  # another sweep's files are still to be cleared

    def chunk_at(self, k: int) -> Chunk:
        """Chunk ``k`` of the sweep."""
        lo = k * self.chunk
        hi = min(lo + self.chunk, self.n_runs)
        return Chunk(k, chunk_id(self.grid.digest, k, lo, hi, self.n_chunks), lo, hi)

    @property
    def runs_dir(self) -> Path:
        return self.folder / RUNS

    @property
    def failed_dir(self) -> Path:
        return self.folder / FAILED

    @staticmethod
    def manifest_for(grid: Grid, chunk: int) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "version": __version__,
            "grid_digest": grid.digest,
            "grid_toml": grid.to_toml(),
            "axes": list(grid.names),
            "seeds": [grid.seed_start, grid.seed_stop],
            "runs": len(grid),
            "chunk": chunk,
            "chunks": n_chunks(len(grid), chunk),
        }

    @classmethod
    def open(cls, folder: str | Path, grid: Grid, chunk: int | None = None,
             force: bool = False, what: str = "sweep folder") -> SweepStore:
        """The sweep of ``grid`` in ``folder``, new or resumed; checks only, nothing is
        written here (:meth:`start` does, once the work can start).

        A folder holding the same sweep (same grid, package version and chunk size) is
        resumed; ``chunk=None`` then takes the folder's chunk size. A folder holding another
        sweep, or other files, is refused with :class:`OutputError` unless ``force``: then
        :meth:`start` removes its manifest, parts and failure files first. ``what`` names the
        folder in messages (``"comparison folder"``, ...).
        """
        folder = check_output_folder(Path(folder), what)
        old = None
        replace = False
        # a manifest being written when a process was killed, or a lock file, does not count
        found = sorted(p.name for p in folder.iterdir() if not _MANIFEST_TMP.fullmatch(p.name)
                       and not is_lock_file(p.name)) if folder.is_dir() else []
        if found:
            try:
                old = read_manifest(folder)
            except ConfigError:
                if not force:
                    raise OutputError(f"{what} {str(folder)!r} holds other files ({found[0]}); "
                                      "choose another --out, or pass --force to write into it "
                                      "(they are kept)") from None
            if old is not None:
                same = (old.get("grid_digest") == grid.digest
                        and old.get("version") == __version__
                        and (chunk is None or old.get("chunk") == chunk))
                if same:
                    return cls(folder, grid, old["chunk"], old, what)
                if not force:
                    raise OutputError(cls._difference(folder, old, grid, chunk, what))
            replace = True
        chunk = default_chunk(len(grid)) if chunk is None else chunk
        return cls(folder, grid, chunk, cls.manifest_for(grid, chunk), what, new=True,
                   replace=replace)

    def start(self) -> None:
        """Make the folder ready for the runs: clear what :meth:`open` found to replace,
        write the manifest of a new sweep, make ``runs/`` and ``failed/``, remove the
        temporary files a killed process left."""
        folder = self.folder
        if folder.is_dir():
            for tmp in folder.iterdir():
                if _MANIFEST_TMP.fullmatch(tmp.name):
                    tmp.unlink(missing_ok=True)
        if self._replace:
            self._clear(folder, self.what)
            self._replace = False
        if self._new:
            try:
                folder.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise OutputError(f"{self.what} {str(folder)!r} cannot be written: "
                                  f"{(exc.strerror or str(exc)).lower()}") from None
            _write_bytes(folder / MANIFEST, _dump(self.manifest))
            self._new = False
        for d in (self.runs_dir, self.failed_dir):
            d.mkdir(exist_ok=True)
            _remove_temporaries(d)

    @staticmethod
    def _difference(folder: Path, old: dict[str, Any], grid: Grid, chunk: int | None,
                    what: str) -> str:
        where = f"{what} {str(folder)!r} holds"
        kind = _KINDS.get(what, "sweep")
        tail = "; choose another --out or pass --force to replace it"
        if old.get("grid_digest") != grid.digest:
            return (f"{where} another {kind} (grid {old.get('grid_digest')}, {old.get('runs')} "
                    f"runs; this grid is {grid.digest}, {len(grid)} runs){tail}")
        if old.get("version") != __version__:
            return (f"{where} this {kind} made with persuasive {old.get('version')} (this is "
                    f"{__version__}){tail}")
        return (f"{where} this {kind} in chunks of {old.get('chunk')} runs (--chunk {chunk} "
                f"asked; leave --chunk out to resume){tail}")

    @staticmethod
    def _clear(folder: Path, what: str = "sweep folder") -> None:
        """Remove another sweep's own files (the module docstring); keep everything else."""
        try:
            (folder / MANIFEST).unlink(missing_ok=True)
            for name, pattern in ((RUNS, "part-*.parquet"), (FAILED, "failed-*.json")):
                if not (folder / name).is_dir():
                    continue
                for path in (folder / name).glob(pattern):
                    if path.is_file() and not path.is_symlink():
                        path.unlink()
                _remove_temporaries(folder / name)
                with contextlib.suppress(OSError):  # one that holds other files stays
                    (folder / name).rmdir()
        except OSError as exc:
            raise OutputError(f"{what} {str(folder)!r} cannot be cleared: "
                              f"{(exc.strerror or str(exc)).lower()}") from None

    # -- progress of the sweep -----------------------------------------------------------------

    def _indices(self, folder: Path, prefix: str, suffix: str) -> set[int]:
        """The chunks of this sweep that have a file ``<prefix><chunk id><suffix>`` in
        ``folder`` (other names are not its chunks' and are ignored)."""
        found: set[int] = set()
        if not folder.is_dir():
            return found
        for path in folder.iterdir():
            name = path.name
            if not (name.startswith(prefix) and name.endswith(suffix)):
                continue
            cid = name[len(prefix):len(name) - len(suffix)]
            head = cid.partition("-")[0]
            if head.isdigit() and int(head) < self.n_chunks and \
                    self.chunk_at(int(head)).id == cid:
                found.add(int(head))
        return found

    def pending(self) -> Pending:
        """What is left to run: chunks with no part yet, or with a failure file (retried).
        Reads the folder, writes nothing. Memory and time grow with the files in the folder,
        not with the chunks of the grid."""
        finished: set[int] = set()
        if not self._replace:
            finished = self._indices(self.runs_dir, "part-", ".parquet") - \
                self._indices(self.failed_dir, "failed-", ".json")
        done = sum(self.chunk_at(k).size for k in finished)
        return Pending(self.n_runs - done, (self.chunk_at(k) for k in range(self.n_chunks)
                                            if k not in finished))

    def record(self, chunk: Chunk, part: bytes | None, failures: list[dict[str, Any]]) -> None:
        """Write a finished chunk: failure file first, then the part; a clean retry removes
        the old failure file last."""
        failed_path = self.failed_dir / chunk.failed_name
        if failures:
            _write_bytes(failed_path, _dump({"chunk": chunk.id, "runs": [chunk.start,
                                                                         chunk.stop],
                                             "failures": failures}))
        if part is not None:
            _write_bytes(self.runs_dir / chunk.part_name, part)
        if not failures:
            failed_path.unlink(missing_ok=True)


def iter_failures(folder: str | Path) -> Iterator[dict[str, Any]]:
    """The failure records of a sweep folder, in run order."""
    failed = Path(folder) / FAILED
    if not failed.is_dir():
        return
    for path in sorted(failed.glob("failed-*.json")):
        yield from json.loads(path.read_text(encoding="utf-8"))["failures"]


def part_paths(folder: str | Path) -> list[Path]:
    """The Parquet parts of a sweep folder, in run order."""
    return sorted((Path(folder) / RUNS).glob("part-*.parquet"))


def load(folder: str | Path, columns: list[str] | None = None):
    """The dataset of a sweep folder as a pandas DataFrame: one row per finished run, in run
    order (column ``run``), ``columns`` only when given.

    Parts whose columns differ (a summary that gained a field between versions) are
    combined: a column missing from a part is null there.
    """
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    read_manifest(folder)  # a sweep folder, or a one-line error
    tables = [pq.read_table(p, columns=columns) for p in part_paths(folder)]
    if not tables:
        return pd.DataFrame(columns=columns or ["run"])
    table = pa.concat_tables(tables, promote_options="permissive")
    return table.to_pandas()


def load_failures(folder: str | Path):
    """The failed runs of a sweep folder as a pandas DataFrame: ``run``, ``seed``, one column
    per axis, ``config_hash``, ``error``; empty when every run finished."""
    import pandas as pd

    axes = read_manifest(folder)["axes"]
    rows = [{"run": f["run"], "seed": f["seed"], **f["axes"], "config_hash": f["config_hash"],
             "error": f["error"]} for f in iter_failures(folder)]
    return pd.DataFrame(rows, columns=["run", "seed", *axes, "config_hash", "error"])


def summary_columns(folder: str | Path) -> list[str]:
    """The dataset's columns that come from ``RunRecord.summary()`` (flattened), in order;
    ``unflatten({c: row[c] for c in these})`` is the run's summary."""
    import pyarrow.parquet as pq

    from .records import METADATA_KEY

    out: list[str] = []
    for path in part_paths(folder):
        meta = pq.read_schema(path).metadata or {}
        for name in json.loads(meta[METADATA_KEY])["summary_columns"]:
            if name not in out:
                out.append(name)
    return out


__all__ = ["Chunk", "FAILED", "FORMAT", "MANIFEST", "Pending", "RUNS", "SweepStore", "chunk_id",
           "chunk_ids", "chunk_ranges", "default_chunk", "iter_failures", "load", "load_failures",
           "n_chunks", "part_paths", "read_manifest", "summary_columns"]
