"""The pairs of a whole site, file by file (``persuasive recordings pairs``; issue 42).

Two tracks pair only within one recording (:func:`persuasive.recordings.pairs.candidates`),
and every recording is in one file (``persuasive.recordings.formats.read_tracks`` refuses two
files holding one recording), so the pairs of a site are the pairs of each of its files: each
file is read, smoothed, paired and, with a map, given its rules on its own
(:func:`file_pairs`), on the worker processes of a local Dask cluster when ``workers > 1``.
Memory is bounded by the largest file, not by the site: a worker writes its file's pairs to a
part of its own in a scratch folder beside the output, and this process keeps only each pair's
labels (:class:`persuasive.recordings.pairs.PairLabels`, for the summary) and copies the
parts, in order of recording name, into the pairs file, numbering the pairs from 0 across the
files: as the files are done, while the others are still being paired, where their order by
recording name is their order (:class:`_Stream`), else afterwards (:func:`_write`). The parts
are Arrow IPC files, uncompressed (about 10 times the pairs file's size, in the scratch
folder): written and read back mapped at almost no cost, the Parquet encoding is the pairs
file's alone. The file is the one :func:`persuasive.recordings.pairs.find_pairs` and
:func:`~persuasive.recordings.pairs.write_pairs` make from all the tracks at once: the same
pairs in the same order with the same IDs and labels, floats equal to rounding (positions
within 1e-10 m, times within 1e-12 s: the whole site's smoothing sums over more tracks), and
the same bits whatever the number of workers
(``tests/test_recordings_site.py::test_the_site_paired_file_by_file_is_the_site_paired_at_once``);
its metadata (:data:`~persuasive.recordings.pairs.PAIRS_METADATA`) is written last, among the
file's key-value metadata, with the counts known only then. The file appears whole or not at
all (written beside, then renamed); an interrupted run removes its scratch folder.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable, Sequence

from .formats import STEP_S, RecordingError, TrackFile, find_track_files
from .pairs import PAIRS_METADATA, Pair, PairLabels, PairParams, find_pairs, pairs_table, summary_of
from .tracks import SmoothingParams


@dataclass
class FilePairs:
    """What one file gave: its recordings, its counts, its pairs' labels and, when the pairs
    are written, the part holding them (pair IDs from 0 within the file)."""

    index: int  #: the file's place among the track files
    recordings: list[str]
    vehicle_tracks: int
    candidates: int
    labels: list[PairLabels] = field(repr=False)
    part: str | None = None


@lru_cache(maxsize=4)
def _road_map(path: str, origin: tuple[float, float]):
    """The map, read once per process."""
    from .lanelet_map import read_map

    return read_map(path, origin)


def pairs_of_file(track_file: TrackFile, params: PairParams, smoothing: SmoothingParams,
                  road_map: tuple[str, tuple[float, float]] | None = None):
    """One file's :class:`persuasive.recordings.pairs.PairsResult` (its pairs with their rules
    from ``road_map``, ``(path, origin)``, when given) and its recording names."""
    from dataclasses import replace

    import pandas as pd

    from .formats import read_ind, read_interaction
    from .tracks import smooth_tracks

    f = track_file
    frame = read_interaction(f.path) if f.format == "interaction" else read_ind(f.path)
    recordings = [str(r) for r in pd.unique(frame["recording"])]
    result = find_pairs(smooth_tracks(frame, smoothing), params)
    if road_map is not None:
        from .lanelet_map import annotate_pairs

        rm = _road_map(road_map[0], tuple(road_map[1]))
        result = replace(result, pairs=annotate_pairs(result.pairs, rm),
                         road_map={"path": road_map[0], "origin": list(rm.origin)})
    return result, recordings


def file_pairs(index: int, track_file: TrackFile, params: PairParams,
               smoothing: SmoothingParams, road_map, scratch: str | None) -> FilePairs:
    """:func:`pairs_of_file`, its pairs written to a part in ``scratch`` (None: not kept).

    A part is the table in Arrow's IPC file format, uncompressed: the one Parquet encoding is
    the pairs file's (:func:`_write`), which reads the part back mapped, without decoding."""
    import pyarrow as pa

    result, recordings = pairs_of_file(track_file, params, smoothing, road_map)
    part = None
    if scratch is not None and result.pairs:
        part = str(Path(scratch) / f"part-{index:06d}.arrow")
        table = pairs_table(result.pairs)
        with pa.OSFile(part, "wb") as sink, pa.ipc.new_file(sink, table.schema) as writer:
            writer.write_table(table)
    return FilePairs(index, recordings, result.tracks.n_tracks, result.candidates,
                     [PairLabels.of(p) for p in result.pairs], part)


def _task(args) -> FilePairs:
    """:func:`file_pairs` on a worker process. The workers are one per core, so each runs
    its compiled kernels on one thread: Numba's own pool (a thread per core in every
    process) would put several threads on each core."""
    import numba

    numba.set_num_threads(1)
    return file_pairs(*args)


@dataclass
class SitePairs:
    """The pairs of a site: the summary (:func:`persuasive.recordings.pairs.summary_of`), the
    files in pair order and how many pairs each gave."""

    summary: dict
    files: list[FilePairs] = field(repr=False)

    def locate(self, pair_id: int) -> tuple[FilePairs, int]:
        """The file holding pair ``pair_id`` of the site and its ID within that file;
        :class:`RecordingError` when there is no such pair."""
        start = 0
        for f in self.files:
            if start <= pair_id < start + len(f.labels):
                return f, pair_id - start
            start += len(f.labels)
        raise RecordingError(f"--pair = {pair_id} is out of range; allowed: 0 to {start - 1}")


def site_pairs(paths: Sequence[str | Path], params: PairParams, smoothing: SmoothingParams,
               road_map: tuple[str, tuple[float, float]] | None = None,
               out: str | Path | None = None, workers: int = 1,
               progress: Callable[[int, int], None] | None = None,
               pair_id: int | None = None) -> SitePairs:
    """The pairs of every track file among ``paths``, file by file (module docstring), and,
    with ``out``, the pairs file written (when there is a pair); ``progress(done, total)``
    after each file. :class:`RecordingError` for a bad file or two files holding one
    recording, and, before anything is written, for a ``pair_id`` the site does not have."""
    files = find_track_files(paths)
    scratch = stream = None
    if out is not None:
        out = Path(out)
        scratch = tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".parts", dir=out.parent)
        stream = _Stream(Path(scratch) / "pairs.parquet")
    try:
        got = _run(files, params, smoothing, road_map, scratch, workers, progress,
                   None if stream is None else stream.add)
        owner: dict[str, Path] = {}
        for f in got:
            for name in f.recordings:
                if name in owner:
                    raise RecordingError(
                        f"track file {str(files[f.index].path)!r} holds recording {name!r}, "
                        f"as {str(owner[name])!r} does; rename one of them")
                owner[name] = files[f.index].path
        # find_pairs orders pairs by recording first: the files, by their recordings' names
        got.sort(key=lambda f: (min(f.recordings) if f.recordings else "", f.index))
        labels = [lab for f in got for lab in f.labels]
        n_tracks = sum(f.vehicle_tracks for f in got)
        n_candidates = sum(f.candidates for f in got)
        info = summary_of(labels, n_tracks, len(owner), n_candidates)
        site = SitePairs(info, got)
        if pair_id is not None and labels:
            site.locate(pair_id)  # refused before anything is written
        if labels and out is not None:
            text = _metadata(params, smoothing, road_map, paths, info)
            if not stream.finish(out, [f.index for f in got if f.part is not None], text):
                _write(out, got, text)
        return site
    finally:
        if stream is not None:
            stream.close()
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)


def _run(files: list[TrackFile], params, smoothing, road_map, scratch, workers, progress,
         on_file: Callable[[FilePairs], None] | None = None) -> list[FilePairs]:
    """:func:`file_pairs` of every file, on ``workers`` processes; ``on_file`` is called with
    each as it is done (in the order they finish)."""
    tasks = [(i, f, params, smoothing, road_map, scratch) for i, f in enumerate(files)]
    done: list[FilePairs] = []

    def finished(got: FilePairs) -> None:
        done.append(got)
        if on_file is not None:
            on_file(got)
        if progress is not None:
            progress(len(done), len(tasks))

    if progress is not None:
        progress(0, len(tasks))
    if workers <= 1 or len(tasks) <= 1:
        for t in tasks:
            finished(file_pairs(*t))
        return done
    from ..sweep.runner import local_client, map_bounded

    with local_client(min(workers, len(tasks))) as client:
        for _, got in map_bounded(client, _task, tasks):
            finished(got)
    return done


def _metadata(params: PairParams, smoothing: SmoothingParams, road_map, sources,
              info: dict) -> bytes:
    """The pairs file's metadata (:data:`~persuasive.recordings.pairs.PAIRS_METADATA`), as
    :func:`persuasive.recordings.pairs.write_pairs` writes it."""
    from .._version import __version__

    meta = {"params": asdict(params), "sources": [str(s) for s in sources],
            "n_pairs": info["pairs"], "candidates": info["candidates"],
            "vehicle_tracks": info["vehicle_tracks"], "version": __version__,
            "step_s": STEP_S, "smoothing": asdict(smoothing),
            "map": None if road_map is None else
            {"path": road_map[0], "origin": list(_road_map(road_map[0],
                                                           tuple(road_map[1])).origin)}}
    return json.dumps(meta).encode()


def _write_part(writer, part: str, offset: int) -> None:
    """Append the part to the Parquet ``writer``, its pair IDs from ``offset`` (the part is
    read mapped: the table's buffers are the map's while it is written)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    with pa.memory_map(part) as source:
        table = pa.ipc.open_file(source).read_all()
        ids = pc.add(table.column("pair"), pa.scalar(offset, table.schema.field("pair").type))
        table = table.set_column(table.schema.get_field_index("pair"), "pair", ids)
        writer.write_table(table.cast(writer.schema))
        del table


def _part_schema(part: str):
    import pyarrow as pa

    with pa.memory_map(part) as source:
        return pa.ipc.open_file(source).schema


def _write(out: Path, got: list[FilePairs], text: bytes) -> None:
    """Copy the parts into the pairs file, pair IDs from 0 across them, then its metadata
    ``text`` (as :func:`persuasive.recordings.pairs.write_pairs` writes it), atomically."""
    import pyarrow.parquet as pq

    from .._files import atomic_write

    def write(path: Path) -> None:
        writer = None
        offset = 0
        try:
            for f in got:
                if f.part is None:
                    continue
                if writer is None:
                    schema = _part_schema(f.part)
                    writer = pq.ParquetWriter(path, schema.with_metadata({
                        **(schema.metadata or {}), PAIRS_METADATA: text}))
                _write_part(writer, f.part, offset)
                offset += len(f.labels)
            writer.add_key_value_metadata({PAIRS_METADATA: text})
        finally:
            if writer is not None:
                writer.close()

    atomic_write(out, write)


class _Stream:
    """The pairs file written while the files are still being paired, so that its encoding
    overlaps the workers' pairing instead of following it: a file's part is appended, pair
    IDs from the pairs before it, as soon as it and every file before it (by index) are done,
    to a Parquet file ``path`` in the scratch folder.

    The file is then the one :func:`_write` makes when the files' order by recording name
    (``find_pairs``' order) is their order by index, as in a folder of one site's recordings,
    but for the footer: the metadata ``text`` (its counts known only at the end) belongs in
    the schema the writer opens with. :meth:`finish` therefore writes the footer's key-value
    metadata as :func:`_write`'s writer does (measured on an empty table written that way),
    checks the footer against it, and only then moves the file into place; otherwise (other
    orders, a pyarrow that orders the footer otherwise) it returns False and :func:`_write`
    writes the file from the parts."""

    def __init__(self, path: Path):
        self.path = path
        self.writer = None
        self.done: dict[int, FilePairs] = {}
        self.next = 0  # the first file not appended yet
        self.written: list[int] = []  # the files whose parts are appended, in order
        self.offset = 0
        self.failed = False  # a write failed: _write writes the file (and says why it fails)

    def add(self, got: FilePairs) -> None:
        """File ``got`` is done: append every part now in order."""
        import pyarrow.parquet as pq

        self.done[got.index] = got
        while not self.failed and self.next in self.done:
            f = self.done.pop(self.next)
            self.next += 1
            if f.part is None:
                continue
            try:
                if self.writer is None:
                    self.writer = pq.ParquetWriter(self.path, _part_schema(f.part))
                _write_part(self.writer, f.part, self.offset)
            except Exception:  # noqa: BLE001 - any failure: the file is written afterwards
                self.failed = True
                self.close()
                return
            self.offset += len(f.labels)
            self.written.append(f.index)

    def finish(self, out: Path, order: list[int], text: bytes) -> bool:
        """Give the file its metadata ``text`` and move it to ``out`` (atomically) when its
        parts are the files ``order`` (the files with parts in the pairs file's order) and
        its footer is :func:`_write`'s; False, and nothing written, otherwise."""
        import io
        import os

        import pyarrow.parquet as pq

        from .._files import atomic_write

        if self.failed or self.writer is None or order != self.written or self.done:
            return False
        schema = self.writer.schema
        model = io.BytesIO()  # the footer _write's writer makes, on no rows
        with pq.ParquetWriter(model, schema.with_metadata({
                **(schema.metadata or {}), PAIRS_METADATA: text})) as writer:
            writer.add_key_value_metadata({PAIRS_METADATA: text})
        footer = list(pq.read_metadata(io.BytesIO(model.getvalue())).metadata.items())
        # pyarrow 26 merges added keys in the reverse of the order they are given
        self.writer.add_key_value_metadata(dict(reversed(footer)))
        self.writer.close()
        self.writer = None
        if list(pq.read_metadata(self.path).metadata.items()) != footer:
            return False
        atomic_write(out, lambda tmp: os.replace(self.path, tmp))
        return True

    def close(self) -> None:
        if self.writer is not None:
            with contextlib.suppress(Exception):  # noqa: BLE001 - scratch, removed next
                self.writer.close()
            self.writer = None


def pair_and_tracks(site: SitePairs, track_files: Sequence[TrackFile], pair_id: int,
                    params: PairParams, smoothing: SmoothingParams, road_map=None
                    ) -> tuple[Pair, object]:
    """Pair ``pair_id`` of the site (its ID the site's) and its file's tracks, for a figure:
    that file paired again."""
    from dataclasses import replace

    from .pairs import pair_of

    f, local = site.locate(pair_id)
    result, _ = pairs_of_file(track_files[f.index], params, smoothing, road_map)
    return replace(pair_of(result, local), pair=pair_id), result.tracks


__all__ = ["FilePairs", "SitePairs", "file_pairs", "pair_and_tracks", "pairs_of_file",
           "site_pairs"]
