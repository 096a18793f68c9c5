"""What the human saw and did, per logged step: the evidence every human model is scored on
(docs/method.md §13.1).

A log (``simulate --out FILE.parquet``, a ``drive`` trial, a ``replay`` input written by
either) holds, per decision step ``k``, the measured states both vehicles decided on
(``av_meas_s_m``, ``av_meas_v_mps``, ``hv_meas_s_m``, ``hv_meas_v_mps``) and the HV's applied
acceleration ``hv_accel_mps2``, and its Parquet metadata holds the run's configuration. From
them, :func:`human_view` re-solves the human's own game at every step, exactly as the LFG
human does (``persuasive.policies.lfg``, docs/method.md §5), with the compiled
``persuasive.game.predict_into`` on the log's own configuration:

- ``a_role[k]``: the acceleration the LFG would apply as leader and as follower (the first
  sample of its trajectory for that role, §5.3);
- ``q[k]``, ``a_first[k]``: the game's values of every trajectory for each role (the leader's
  ``Ql`` of "ego leads", the follower's ``Qf`` of "ego follows") and every trajectory's first
  acceleration, for the Boltzmann human;
- ``belief[k]``: the human's belief about the AV's role held *before* step ``k``, updated by
  ``persuasive.roles.bayes_update`` against the prediction stored at the previous step (§5.5,
  §5.6); it does not depend on the human's own role;
- ``pl[k]``: its ``P(plausible = L)`` if its own role is L and if it is F (§5.1): equal unless
  the belief is exactly tied, when the plausible role is the human's own role.

**Recorded accelerations are filtered ones.** A log written from recorded tracks
(``persuasive recordings logs``, replay's fitted other, ``benchmarks/recordings_roundtrip.py``)
carries the tracks' filter in its metadata (``recording.smoothing``; the held-out evaluation's
views do not: a filtered prediction reads states after its step, docs/method.md §13.10). Its
accelerations are the filter's view of the driver's, not the driver's: a step of the
acceleration is spread over the window, half a step early. The fit passes the models'
accelerations through the same filter before they are compared (the measurement model; the
filter is ``persuasive.recordings.tracks.acceleration_band``, exact at the track's ends too,
where the log says where its steps lie in the track; the run's first and last steps stand in
for the steps beyond its ends). For the ``lfg`` and ``stubborn`` it is exact: the recorded
value of step ``k`` is ``sum_d w_kd a_role[k + d, r_{k+d}]``, each neighbour's prediction from
its own measured state *in the role it held then*, and the forward filter runs over the role
paths of the window (:attr:`Evidence.a_raw`, :attr:`Evidence.band_w`;
``persuasive.fitting.models.path_loglik``). :func:`observe_through` gives the approximation
with the role held over the window, ``a_role[k, r]`` becoming ``sum_d w_kd a_role[k + d, r]``:
what :attr:`Evidence.a_role` holds for such runs (the role posteriors and the starting values
read it), and every candidate's ``a_first`` alike for the ``noisy`` (the candidate slot held).
Holding the role biased the ``lfg``'s ``p_a`` low wherever the role changes within a window
(docs/guide/recordings.md, "The round trip, replicated"). Simulated logs and drive trials
record the applied acceleration itself and are not filtered.

CSV logs are refused: they carry no configuration (mode, scenario, vehicles, library), and a
game re-solved with the wrong one would be fitted without a warning.
"""

from __future__ import annotations

import json
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
from numba import njit, prange

from .. import packing as slot
from ..config import Config, ConfigError
from ..game import (EGO_FOLLOWER, EGO_LEADER, OTHER_FOLLOWER, OTHER_LEADER,
                    Q_EGO_FOLLOWS_FOLLOWER, Q_EGO_LEADS_LEADER, predict_into)
from ..library import new_lib
from ..roles import FOLLOWER, LEADER, bayes_update, plausible_leader

#: The per-step columns a fit reads.
NEEDED_COLUMNS = ("av_meas_s_m", "av_meas_v_mps", "hv_meas_s_m", "hv_meas_v_mps",
                  "hv_accel_mps2")
#: A drive trial's file name: ``<participant>-tNN-<condition>[-partial].parquet``.
TRIAL_NAME = re.compile(r"^(?P<participant>.+?)-t(?P<trial>\d{2})-(?P<condition>[A-Za-z0-9_-]+?)"
                        r"(?P<partial>-partial)?\.parquet$")


@njit(cache=True)
def human_view(s_av: np.ndarray, v_av: np.ndarray, s_hv: np.ndarray, v_hv: np.ndarray,
               P_hv: np.ndarray, P_av: np.ndarray, disc: np.ndarray, a_role: np.ndarray,
               pl: np.ndarray, belief: np.ndarray, q: np.ndarray, a_first: np.ndarray,
               work: np.ndarray) -> None:
    """The human's view of one run, step by step, as the LFG human computes it.

    ``s_av, v_av, s_hv, v_hv`` ``(n,)``: the measured states [m, m/s]; ``P_hv, P_av``, ``disc``:
    the run's parameter vectors and discounts. Fills ``a_role`` ``(n, 2)`` [m/s^2], ``pl``
    ``(n, 2)``, ``belief`` ``(n, 2)`` (before each step), ``q`` ``(n, 2, n_traj)`` and
    ``a_first`` ``(n, n_traj)`` [m/s^2] (see the module docstring); ``work``: the kernels'
    counters.
    """
    n_samples, n_traj = int(P_hv[slot.N_SAMPLES]), int(P_hv[slot.N_MESH]) + 1
    lib_h, lib_r = new_lib(n_samples, n_traj), new_lib(n_samples, n_traj)
    idx = np.empty(4, np.int64)
    q_values = np.empty((4, n_traj))
    w_s, w_v = P_hv[slot.W_S], P_hv[slot.W_V]
    b_l, b_f = P_hv[slot.PRIOR_L], 1.0 - P_hv[slot.PRIOR_L]
    # the stored prediction starts at the other's measured state at the first step (§5)
    pred_ls, pred_lv, pred_fs, pred_fv = s_av[0], v_av[0], s_av[0], v_av[0]
    for k in range(s_av.shape[0]):
        predict_into(s_hv[k], v_hv[k], s_av[k], v_av[k], P_hv, P_av, disc, lib_h, lib_r, idx,
                     q_values, work, False)
        belief[k, 0], belief[k, 1] = b_l, b_f
        pl[k, 0] = plausible_leader(b_l, b_f, LEADER)
        pl[k, 1] = plausible_leader(b_l, b_f, FOLLOWER)
        a_role[k, 0] = lib_h.A[0, idx[EGO_LEADER]]
        a_role[k, 1] = lib_h.A[0, idx[EGO_FOLLOWER]]
        for c in range(n_traj):
            q[k, 0, c] = q_values[Q_EGO_LEADS_LEADER, c]
            q[k, 1, c] = q_values[Q_EGO_FOLLOWS_FOLLOWER, c]
            a_first[k, c] = lib_h.A[0, c]
        b_l, b_f = bayes_update(b_l, b_f, abs(s_av[k] - pred_ls), abs(v_av[k] - pred_lv),
                                abs(s_av[k] - pred_fs), abs(v_av[k] - pred_fv), w_s, w_v)
        o_l, o_f = idx[OTHER_LEADER], idx[OTHER_FOLLOWER]
        pred_ls, pred_lv = lib_r.S[0, o_l], lib_r.V[0, o_l]
        pred_fs, pred_fv = lib_r.S[0, o_f], lib_r.V[0, o_f]


@njit(cache=True, parallel=True)
def human_views(starts: np.ndarray, s_av: np.ndarray, v_av: np.ndarray, s_hv: np.ndarray,
                v_hv: np.ndarray, P_hv: np.ndarray, P_av: np.ndarray, disc: np.ndarray,
                a_role: np.ndarray, pl: np.ndarray, belief: np.ndarray, q: np.ndarray,
                a_first: np.ndarray, work: np.ndarray) -> None:
    """:func:`human_view` of every run, the runs in parallel. Runs are stored one after the
    other: run ``i`` is rows ``starts[i]:starts[i + 1]``; ``P_hv, P_av`` ``(n_runs,
    N_SLOTS)``, ``disc`` ``(n_runs, n_samples)``, ``work`` ``(n_runs, N_WORK)``."""
    for i in prange(starts.shape[0] - 1):
        a, b = starts[i], starts[i + 1]
        human_view(s_av[a:b], v_av[a:b], s_hv[a:b], v_hv[a:b], P_hv[i], P_av[i], disc[i],
                   a_role[a:b], pl[a:b], belief[a:b], q[a:b], a_first[a:b], work[i])


@dataclass(frozen=True)
class RunLog:
    """One log as read for a fit: where it came from, its configuration and its steps."""

    source: str  #: the file
    config: Config
    seed: int
    #: a drive trial's participant ID (its metadata; older trials: the file name), else None
    participant: str | None
    states: np.ndarray = field(repr=False)  #: (n, 4) measured s_av, v_av, s_hv, v_hv
    accel: np.ndarray = field(repr=False)  #: (n,) the HV's applied acceleration [m/s^2]
    meta: dict = field(repr=False, default_factory=dict)  #: the file's run-record metadata

    @property
    def n_steps(self) -> int:
        return int(self.accel.shape[0])


def scenario_key(config: Config) -> tuple:
    """What makes two logs' scenarios the same: the kind and its geometry."""
    s = config.scenario
    return (s.kind, s.angle_deg, s.turn_radius_m)


def describe_scenario(key: tuple) -> str:
    kind, angle, radius = key
    extra = [f"angle_deg = {angle:g}"] if angle is not None else []
    extra += [f"turn_radius_m = {radius:g}"] if radius is not None else []
    return repr(kind) + (f" ({', '.join(extra)})" if extra else "")


_CONFIGS: dict[str, Config] = {}


def _config_of(toml: str) -> Config:
    config = _CONFIGS.get(toml)
    if config is None:
        config = _CONFIGS[toml] = Config.from_dict(tomllib.loads(toml))
    return config


def read_log(path: str | Path) -> RunLog:
    """Read one log for a fit; :class:`ConfigError` (one line naming the file) when it cannot
    be fitted: not a Parquet run log, missing columns, no steps, NaN or infinite values."""
    import pyarrow.parquet as pq

    from ..record import RECORD_METADATA

    path = Path(path)
    name = str(path)
    if path.suffix.lower() == ".csv":
        raise ConfigError(f"log file {name!r} is a CSV log: it carries no configuration (mode, "
                          "scenario, vehicles) to re-solve the human's game with; give the "
                          "Parquet log (simulate --out FILE.parquet, or a drive trial)")
    try:
        pf = pq.ParquetFile(path)
        schema = pf.schema_arrow
        raw = (schema.metadata or {}).get(RECORD_METADATA)
        missing = [c for c in NEEDED_COLUMNS if c not in schema.names]
        table = pf.read(columns=list(NEEDED_COLUMNS)) if raw is not None and not missing \
            else None
    except OSError as exc:
        reason = (exc.strerror or str(exc).splitlines()[0] or "cannot be read").lower()
        raise ConfigError(f"log file {name!r} cannot be read: {reason}") from None
    except Exception as exc:  # noqa: BLE001 - pyarrow raises several kinds for a bad file
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"log file {name!r} cannot be read: {text}") from None
    if raw is None:
        raise ConfigError(f"log file {name!r} holds no run record (write it with 'persuasive "
                          "simulate --out FILE.parquet' or 'persuasive drive')")
    if missing:
        raise ConfigError(f"log file {name!r} lacks the columns a fit needs: "
                          f"{', '.join(missing)}")
    if table.num_rows == 0:
        raise ConfigError(f"log file {name!r} is empty: no logged step")
    meta = json.loads(raw)
    try:
        config = _config_of(meta["config_toml"])
    except (KeyError, tomllib.TOMLDecodeError, ConfigError) as exc:
        raise ConfigError(f"log file {name!r} holds an invalid configuration: {exc}") from None
    cols = []
    for c in NEEDED_COLUMNS:
        try:
            x = table.column(c).to_numpy(zero_copy_only=False).astype(np.float64)
        except (TypeError, ValueError):
            raise ConfigError(f"log file {name!r}: column {c} is not numeric") from None
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise ConfigError(f"log file {name!r} has a non-finite value ({x[bad[0]]}) in "
                              f"{c} at step {int(bad[0])}; allowed: finite numbers")
        cols.append(x)
    return RunLog(name, config, int(meta.get("seed", 0)), participant_of(meta, path, config),
                  np.stack(cols[:4], axis=1), cols[4], meta)


def participant_of(meta: dict, path: str | Path, config: Config) -> str | None:
    """Who drove a log: the participant ID a ``drive`` trial stores in its metadata
    (``meta["trial"]["participant"]``), so that a renamed trial is still its participant's.
    Trials written before the metadata held it fall back to their file name,
    ``<participant>-tNN-<condition>.parquet`` (a person's log only): renamed, such a trial is
    fitted as whoever its new name says. None for a log that is not a trial. Raises
    :class:`ConfigError` for a trial record without a participant ID."""
    trial = meta.get("trial")
    if trial is not None:
        participant = trial.get("participant") if isinstance(trial, dict) else None
        if not isinstance(participant, str) or not participant:
            raise ConfigError(f"log file {str(path)!r} holds a trial record without a "
                              f"participant ID ({participant!r}); allowed: non-empty text")
        return participant
    match = TRIAL_NAME.match(Path(path).name)
    return match.group("participant") if match and config.hv.kind == "person" else None


def run_log_of(record, source: str = "") -> RunLog:
    """The :class:`RunLog` of a :class:`persuasive.simulation.RunRecord` in memory (what
    :func:`read_log` reads from its saved file)."""
    cols = [np.asarray(record.log[c], dtype=np.float64) for c in NEEDED_COLUMNS]
    meta = {"config_toml": record.config.to_toml(), "seed": record.seed,
            "streams": record.streams, "final_state": [float(x) for x in record.states[-1]],
            "version": record.version}
    return RunLog(source or f"seed {record.seed}", record.config, int(record.seed), None,
                  np.stack(cols[:4], axis=1), cols[4], meta)


@dataclass
class Evidence:
    """The evidence of a set of runs, stored one run after the other (``n`` steps in all).

    Run ``i`` is rows ``starts[i]:starts[i + 1]``. Arrays: ``accel`` ``(n,)`` the logged HV
    acceleration [m/s^2]; ``a_role`` ``(n, 2)`` the LFG's acceleration as L and F; ``pl``
    ``(n, 2)`` the human's ``P(plausible = L)`` if its role is L, F; ``belief`` ``(n, 2)``
    its ``(P(AV = L), P(AV = F))`` before the step; ``q`` ``(n, 2, n_traj)`` the game's
    values per role and ``a_first`` ``(n, n_traj)`` every trajectory's first acceleration;
    ``states`` ``(n, 4)`` the measured ``s_av, v_av, s_hv, v_hv``; per run ``P_hv, P_av``
    ``(n_runs, N_SLOTS)`` and ``dt`` ``(n_runs,)`` [s].
    """

    runs: list[RunLog]
    starts: np.ndarray
    accel: np.ndarray
    a_role: np.ndarray
    pl: np.ndarray
    belief: np.ndarray
    q: np.ndarray
    a_first: np.ndarray
    states: np.ndarray
    P_hv: np.ndarray
    P_av: np.ndarray
    dt: np.ndarray
    #: runs recorded through a filter (None: none was): ``filtered`` ``(n_runs,)``, the
    #: ``lfg``'s accelerations before the filter ``a_raw`` ``(n, 2)``, and the filter as a band,
    #: ``band_off`` ``(m,)`` and ``band_w`` ``(n, m)`` (rows of unfiltered runs 0); the
    #: ``lfg`` and ``stubborn`` score these runs over role paths
    #: (``persuasive.fitting.models.path_loglik``)
    filtered: np.ndarray | None = None
    a_raw: np.ndarray | None = field(default=None, repr=False)
    band_off: np.ndarray | None = field(default=None, repr=False)
    band_w: np.ndarray | None = field(default=None, repr=False)

    @property
    def n_runs(self) -> int:
        return len(self.runs)

    @property
    def n_steps(self) -> int:
        return int(self.accel.shape[0])

    def subset(self, indices: Sequence[int]) -> Evidence:
        """The evidence of the runs ``indices`` (in that order)."""
        indices = list(indices)
        rows = [np.arange(self.starts[i], self.starts[i + 1]) for i in indices]
        take = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        lengths = np.array([r.size for r in rows], np.int64)
        starts = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        band = {}
        if self.filtered is not None:
            band = {"filtered": self.filtered[indices], "a_raw": self.a_raw[take],
                    "band_off": self.band_off, "band_w": self.band_w[take]}
        return Evidence([self.runs[i] for i in indices], starts, self.accel[take],
                        self.a_role[take], self.pl[take], self.belief[take], self.q[take],
                        self.a_first[take], self.states[take], self.P_hv[indices],
                        self.P_av[indices], self.dt[indices], **band)


def evidence_of(logs: Sequence[RunLog]) -> Evidence:
    """Re-solve the human's game at every logged step of every run (in parallel over runs)."""
    from ..record import static_setup

    if not logs:
        raise ConfigError("no log to fit")
    first = logs[0].config.library
    for log in logs[1:]:
        lib = log.config.library
        if (lib.n_samples, lib.n_mesh) != (first.n_samples, first.n_mesh):
            raise ConfigError(f"log file {log.source!r} has another trajectory library "
                              f"(library.n_samples, library.n_mesh = {lib.n_samples}, "
                              f"{lib.n_mesh}) than {logs[0].source!r} ({first.n_samples}, "
                              f"{first.n_mesh}); fit them separately")
    lengths = np.array([log.n_steps for log in logs], np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    n, n_traj = int(starts[-1]), first.n_mesh + 1
    states = np.concatenate([log.states for log in logs])
    accel = np.concatenate([log.accel for log in logs])
    P_hv = np.empty((len(logs), slot.N_SLOTS))
    P_av = np.empty((len(logs), slot.N_SLOTS))
    disc = np.empty((len(logs), first.n_samples))
    dt = np.empty(len(logs))
    for i, log in enumerate(logs):
        _, P_av[i], P_hv[i], disc[i] = static_setup(log.config)
        dt[i] = log.config.simulation.dt_s
    a_role, pl, belief = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2))
    q, a_first = np.empty((n, 2, n_traj)), np.empty((n, n_traj))
    work = np.zeros((len(logs), slot.N_WORK), np.int64)
    human_views(starts, np.ascontiguousarray(states[:, 0]), np.ascontiguousarray(states[:, 1]),
                np.ascontiguousarray(states[:, 2]), np.ascontiguousarray(states[:, 3]), P_hv,
                P_av, disc, a_role, pl, belief, q, a_first, work)
    filtered = [(i, measurement_band(log)) for i, log in enumerate(logs)]
    filtered = [(i, band) for i, band in filtered if band is not None]
    recorded = {}
    if filtered:
        runs = np.array([i for i, _ in filtered], np.int64)
        reach = max(int(-off[0]) for _, (off, _w) in filtered)
        offsets = np.arange(-reach, reach + 1)
        weights = np.zeros((int(sum(logs[i].n_steps for i in runs)), offsets.size))
        every = np.zeros((n, offsets.size))
        row = 0
        for i, (off, w) in filtered:
            cols = slice(off[0] + reach, off[-1] + reach + 1)
            weights[row:row + w.shape[0], cols] = w
            every[starts[i]:starts[i + 1], cols] = w
            row += w.shape[0]
        used = np.flatnonzero(np.any(every != 0.0, axis=0))
        keep = slice(int(used[0]), int(used[-1]) + 1) if used.size else slice(reach, reach + 1)
        is_filtered = np.zeros(len(logs), bool)
        is_filtered[runs] = True
        recorded = {"filtered": is_filtered, "a_raw": a_role.copy(),
                    "band_off": np.ascontiguousarray(offsets[keep]),
                    "band_w": np.ascontiguousarray(every[:, keep])}
        for arr in (a_role, a_first):
            observe_through(arr, starts, runs, offsets, weights)
    return Evidence(list(logs), starts, accel, a_role, pl, belief, q, a_first, states, P_hv,
                    P_av, dt, **recorded)


def measurement_band(log: RunLog) -> tuple[np.ndarray, np.ndarray] | None:
    """The recorded acceleration's filter of a log from recorded tracks, as
    ``persuasive.recordings.tracks.acceleration_band`` gives it for the log's steps (its
    ``recording.smoothing``, the human's ``track_k0_<h>`` and ``track_n_<h>``; without those,
    every step as an interior one); None for a log with no ``recording.smoothing``.
    :class:`ConfigError` when the metadata does not describe a filter."""
    from ..recordings.formats import RecordingError
    from ..recordings.tracks import SmoothingParams, acceleration_band

    rec = log.meta.get("recording") or {}
    smoothing = rec.get("smoothing")
    if smoothing is None:
        return None
    try:
        params = SmoothingParams(**smoothing)
    except (TypeError, RecordingError) as exc:
        raise ConfigError(f"log {log.source!r}: recording.smoothing = {smoothing!r} is not a "
                          f"filter the recordings' pipeline has: {exc}") from None
    human = rec.get("human")
    k0 = rec.get(f"track_k0_{human}")
    n_track = rec.get(f"track_n_{human}")
    if k0 is None or n_track is None:
        k0, n_track = 0, 0
    return acceleration_band(params, int(n_track), int(k0), log.n_steps)


def observe_through(arr: np.ndarray, starts: np.ndarray, runs: np.ndarray,
                    offsets: np.ndarray, weights: np.ndarray) -> None:
    """In place, for the rows of runs ``runs`` in that order (``starts`` as
    :attr:`Evidence.starts`; ``weights`` ``(their rows, len(offsets))``): ``arr[k] = sum_j
    weights[k, j] arr[k + offsets[j]]``, ``k + offsets[j]`` held within ``k``'s run (its
    first and last rows stand in beyond its ends); module docstring."""
    lengths = starts[runs + 1] - starts[runs]
    if lengths.sum() == 0:
        return
    rows = np.concatenate([np.arange(starts[i], starts[i + 1]) for i in runs])
    lo = np.repeat(starts[runs], lengths)
    hi = np.repeat(starts[runs + 1] - 1, lengths)
    out = np.zeros((rows.shape[0],) + arr.shape[1:])
    shape = (-1,) + (1,) * (arr.ndim - 1)
    for j, d in enumerate(offsets):
        w = weights[:, j]
        if np.any(w):
            out += w.reshape(shape) * arr[np.clip(rows + d, lo, hi)]
    arr[rows] = out


def check_distinct(paths: Sequence[str | Path]) -> None:
    """:class:`ConfigError` when one file is given twice: a fit would count its run twice.
    Files are compared as the file system sees them (device and inode), so ``./x`` and ``x``,
    a symbolic or a hard link are the same file; a path that cannot be read is compared by its
    resolved form (and refused later when it is read)."""
    seen: dict[tuple, str] = {}
    for p in paths:
        try:
            st = os.stat(p)
            key: tuple = ("file", st.st_dev, st.st_ino)
        except OSError:
            key = ("path", str(Path(p).resolve()))
        if key in seen:
            raise ConfigError(f"log file {str(p)!r} is the same file as {seen[key]!r}: its "
                              "run would count twice; give each log once")
        seen[key] = str(p)


def load_logs(paths: Sequence[str | Path], scenario: str | None = None) -> list[RunLog]:
    """Read every log; all must be of one scenario (``scenario``, a kind, or the first log's
    kind and geometry) and none given twice (:func:`check_distinct`). Raises
    :class:`ConfigError` naming the first bad file."""
    from concurrent.futures import ThreadPoolExecutor

    if not paths:
        raise ConfigError("no log to fit: give one or more Parquet logs")
    check_distinct(paths)
    with ThreadPoolExecutor(max_workers=4) as pool:  # pyarrow reads without the GIL
        futures = [pool.submit(read_log, p) for p in paths]
        logs = [f.result() for f in futures]
    want = None
    if scenario is not None:
        want = scenario
    for log in logs:
        key = scenario_key(log.config)
        if want is None:
            want = key
            first_source = log.source
        ok = key[0] == want if isinstance(want, str) else key == want
        if not ok:
            if isinstance(want, str):
                raise ConfigError(f"log file {log.source!r} is of scenario "
                                  f"{describe_scenario(key)}, not the model's {want!r} "
                                  "(--scenario)")
            raise ConfigError(f"log file {log.source!r} is of scenario "
                              f"{describe_scenario(key)}, not the model's "
                              f"{describe_scenario(want)} (that of {first_source!r}); fit "
                              "each scenario separately")
    return logs


__all__ = ["Evidence", "NEEDED_COLUMNS", "RunLog", "check_distinct", "evidence_of", "human_view",
           "human_views", "load_logs", "measurement_band", "observe_through", "participant_of",
           "read_log", "run_log_of"]
