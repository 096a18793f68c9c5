"""A run's setup and its record (docs/method.md §7): what both loops share around a run.

- :func:`setup` gives a run its scenario, both vehicles' parameter vectors, its random streams
  (``persuasive.streams.draw_streams``) and its initial state (:class:`Setup`);
- :func:`make_record` turns a finished loop's states and logs (either loop: the compiled
  ``persuasive.world.run_loop`` or the Python ``persuasive.world.PythonWorld``) into a
  :class:`RunRecord`: the configuration, the seed, the states, the per-step log and the
  outcome (:class:`RunOutcome`, computed by :func:`outcome`);
- :meth:`RunRecord.save` and :func:`load_record` keep a run as Parquet.

States are indexed ``x_0 .. x_N`` (``N = n_steps``): step ``k`` decides at ``x_k`` and advances
to ``x_{k+1}``; collision and arrival are tested on ``x_{k+1}``. ``idx_end`` is the first step
after which a vehicle is at its first-arrival line (the last step if none is), and the "up to
the line" minimum distance runs over ``x_0 .. x_{idx_end + 1}``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit

from ._version import __version__
from .config import Config, ConfigError
from .kinematics import saturated_step
from .packing import CONFLICT_ALONG_PATHS, CONFLICT_EUCLIDEAN, WORK_NAMES, discounts, pack
from .policies import kinds as kd
from .policies import kind_of, load_replay
from .roles import LEADER
from .safety import measures
from .scenarios import Scenario, build_scenario, first_arrival
from .streams import draw_streams, measure_states

#: Labels of ``first_at_line`` / ``first_at_conflict_point``.
ARRIVAL_LABELS = {0: "neither", 1: "AV", 2: "HV", 3: "same step"}
#: How a scenario's conflict measures the distance between the vehicles (docs/method.md §10.2).
DISTANCE_MEASURED = {CONFLICT_ALONG_PATHS: "along the paths",
                     CONFLICT_EUCLIDEAN: "between the centres"}


# Columns of the world's own per-step log: the measurements, the applied accelerations, the
# AV policy's proposal and the shield's verdict (-1: no shield; persuasive.safety.shield).
WORLD_LOG = ("av_meas_s_m", "av_meas_v_mps", "hv_meas_s_m", "hv_meas_v_mps", "av_accel_mps2",
             "hv_accel_mps2", "av_proposed_accel_mps2", "shield_verdict")
(W_AV_S, W_AV_V, W_HV_S, W_HV_V, W_AV_A, W_HV_A, W_AV_PROPOSED, W_SHIELD) = range(len(WORLD_LOG))


@dataclass(frozen=True)
class RunOutcome:
    """Per-run metrics (docs/method.md §7-8, §11). Times are NaN when the event never happens."""

    first_at_line: int  #: 1 AV, 2 HV, 3 same step, 0 neither
    first_at_conflict_point: int  #: same labels, for ``s >= 0``
    collision: bool  #: footprints overlapped at some step
    min_distance_to_line_m: float  #: min distance over ``x_0 .. x_{idx_end + 1}`` [m]
    #: min distance over the whole run [m] (along the paths in the intersection and the left
    #: turn: ``RunRecord.summary()["distance_measured"]``)
    min_distance_m: float
    idx_end: int  #: first step after which a vehicle is at its line (last step if none)
    infeasible_steps: int  #: AV steps where no candidate met the chance constraint
    hv_role_changes: int  #: role changes of a role-holding human
    av_role_changes: int  #: role changes of an LFG AV (0 otherwise)
    av_time_to_line_s: float  #: time when the AV reached its first-arrival line [s]
    hv_time_to_line_s: float
    av_time_to_clear_s: float  #: time when the AV left the conflict zone [s]
    hv_time_to_clear_s: float
    av_delay_s: float  #: time to clear minus the free-flow time (u_max up to v_max) [s]
    hv_delay_s: float
    av_rms_accel_mps2: float  #: RMS of the applied accelerations [m/s^2]
    hv_rms_accel_mps2: float
    av_rms_jerk_mps3: float  #: RMS of the acceleration differences over dt [m/s^3]
    hv_rms_jerk_mps3: float
    # safety outside the model (docs/method.md §12.6)
    #: an overlap the AV is at fault for: every one but a rear-end by the human
    collision_caused_by_av: bool
    #: the human drove into the AV from behind in a shared lane after the AV's fair cut-in,
    #: the AV braking no harder than the rule allows since (docs/method.md §12.10)
    rear_end_by_human: bool
    min_gap_m: float  #: smallest distance between the two footprints [m] (0: they touched)
    pet_s: float  #: post-encroachment time at the conflict [s]
    min_ttc_s: float  #: minimum time to collision along the paths [s]
    shield_interventions: int  #: steps where the shield overrode the AV's policy
    av_max_brake_mps2: float  #: the AV's strongest braking [m/s^2] (0: it never braked)
    #: steps where the shield had no certified choice (verdict "uncertified": the state was
    #: outside its invariant set; 0 with the shield off), counted until a contact by the human
    #: (a rear-end by it): the simulation has no contact, and the states after it are none
    #: the shield answers for
    uncertified_steps: int = 0
    #: the worst-case guarantee covered the whole run (docs/method.md §12.2): the worst-case
    #: shield was on, every step certified (so the run started in the invariant set) and no
    #: noise ran outside what the shield knows (measurement noise; it certifies against the
    #: acceleration noise); False with the shield off, ``responsive`` or ``responsibility``
    #: (their guarantees rest on the human responding)
    guarantee_held: bool = False
    # liveness (docs/method.md §12.8): both vehicles cleared the conflict within the run; the AV
    # passed the conflict point first and both cleared (persuasion that counts); a standoff
    # (neither advances 0.5 m in 3 s, neither cleared) and when its first window starts [s];
    # how long each vehicle stood (below 0.1 m/s) before it cleared [s]
    both_cleared: bool = False
    av_first_through: bool = False
    deadlock: bool = False
    deadlock_at_s: float = math.nan
    av_wait_s: float = 0.0
    hv_wait_s: float = 0.0
    # what the shield's overrides cost (issue 25 item 6, after SHARP: Hu, Nakamura, Fisac,
    # RA-L 2022): the share of the AV's steps it overrode, and the mean over the AV's steps of
    # how far it moved the proposal, |applied - proposed| [m/s^2] (0 where it admitted it; a
    # non-finite proposal, always overridden, adds nothing to the mean); 0 with the shield off
    override_share: float = 0.0
    override_mps2: float = 0.0


#: Outcome fields that are times or distances (floats), for tables.
OUTCOME_FIELDS = tuple(RunOutcome.__dataclass_fields__)


@dataclass(frozen=True)
class RunRecord:
    """One closed-loop run: configuration, seed, per-step log and outcome."""

    config: Config
    seed: int
    av_initial_state: tuple[float, float]  #: ``(s [m], v [m/s])``
    hv_initial_state: tuple[float, float]
    states: np.ndarray = field(repr=False)  #: ``(n_steps + 1, 4)``: s_AV, v_AV, s_HV, v_HV
    log: dict[str, np.ndarray] = field(repr=False)  #: per-step columns, ``n_steps`` rows
    outcome: RunOutcome
    scenario: Scenario = field(repr=False, compare=False)
    streams: str = "legacy"  #: the random-stream layout used
    #: the AV's decision time per step [ms] (prediction, library and its own step); not part
    #: of the deterministic record
    av_decision_ms: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: the kernels' work counters of the run (``persuasive.packing.WORK_NAMES``)
    work: dict[str, int] | None = field(default=None, repr=False, compare=False)
    version: str = __version__
    #: the repeated interaction with the same human this run is (0: the seed's own run;
    #: ``persuasive.simulation.simulate_interactions``)
    interaction: int = 0
    #: online ``p_a`` only (``mpc.p_a_hat = "online"``): the AV's posterior over the grid
    #: ``mpc.p_a_grid`` at the end of the run ``(G,)``, and the prior it started from
    p_a_posterior: np.ndarray | None = field(default=None, repr=False, compare=False)
    p_a_prior: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: foresight only (``av.yield_line_choices_m``): the yield line the AV picked for the run
    #: [m] (``persuasive.safety.foresight``)
    yield_line_m: float | None = None

    @property
    def mode(self) -> str:
        return self.config.mode

    def summary(self) -> dict[str, Any]:
        """The run's identity and metrics as plain JSON values (deterministic: no timings).

        Beside the outcome, ``safety_distance_m`` is the pair's safety threshold (7.5 m by
        default) that ``min_distance_m`` and ``min_distance_to_line_m`` are compared with,
        and ``distance_measured`` says how those distances are measured: ``"along the
        paths"`` (the intersection, where it is the distance between the centres, and the
        left turn, where it is not) or ``"between the centres"`` (crossing, merge)."""
        c, o = self.config, self.outcome
        out = {
            "mode": c.mode,
            "scenario": c.scenario.kind,
            "av": c.av.kind,
            "hv": c.hv.kind,
            "hv_role": c.hv.role,
            "pa": c.roles.p_a,
            "pa_hat": c.p_a_hat,
            "seed": self.seed,
            "streams": self.streams,
            "hv_initial_state": [float(x) for x in self.hv_initial_state],
            "av_initial_state": [float(x) for x in self.av_initial_state],
        }
        for name in OUTCOME_FIELDS:
            value = getattr(o, name)
            out[name] = None if isinstance(value, float) and math.isnan(value) else value
        scene = self.scenario
        out["safety_distance_m"] = scene.min_dist_m if scene is not None else None
        out["distance_measured"] = None if scene is None else DISTANCE_MEASURED[scene.conflict]
        if c.p_a_online:  # only online runs carry these keys
            out["interaction"] = self.interaction
            hat = self.log.get("av_p_a_hat")
            out["pa_hat_final"] = float(hat[-1]) if hat is not None and len(hat) else None
        # the line foresight picked (None without foresight): every run carries the key, so
        # that a sweep mixing runs with and without it reads each back as it was
        out["yield_line_m"] = self.yield_line_m
        out["quirks"] = dict(vars(c.effective_quirks))
        out["config_hash"] = c.digest()
        out["version"] = self.version
        return out

    def timing(self) -> dict[str, float]:
        """The AV's decision time: median and 99th percentile over the steps [ms]."""
        t = self.av_decision_ms
        if t is None or t.size == 0:
            return {}
        return {"av_decision_ms_median": float(np.median(t)),
                "av_decision_ms_p99": float(np.percentile(t, 99))}

    def trace(self):
        """The run as the tables' N = 2 case (``persuasive.tables.Trace``; docs/method.md
        §15.1): vehicle 0 the AV, 1 the human, on their scenario paths; one conflict row,
        a :data:`~persuasive.tables.MERGE` where the lanes are shared past ``s = 0``, else a
        :data:`~persuasive.tables.CROSSING`, both conflict points at ``s = 0`` and the paths'
        occupancy intervals; ``through_m`` each path's ``clear_s``; the right of way the
        configuration's ``responsibility.right_of_way``. The two-vehicle loop never takes a
        vehicle off the road: every status is active. The collisions list holds at most one
        event, at the first overlap, caused by the AV when the outcome's
        ``collision_caused_by_av`` is; the human's opponent is the AV at every step.
        ``persuasive.many.measures`` reads it as it reads a junction's run."""
        from .packing import RIGHT_OF_WAY_IDS
        from .safety.shield import verdict_name
        from .scenarios.base import pair_min_dist
        from .tables import (CROSSING, MERGE, ConflictTable, Limits, RouteConflict, Row, Trace,
                             Vehicles)

        c, scene, states, log = self.config, self.scenario, self.states, self.log
        dt = c.simulation.dt_s
        n_steps = states.shape[0] - 1
        kind = MERGE if scene.lane_shared else CROSSING
        occ_av, occ_hv = tuple(scene.av.occupancy), tuple(scene.hv.occupancy)
        row = Row(0, 1, kind, RouteConflict(kind, 0.0, 0.0, occ_av, occ_hv),
                  RouteConflict(kind, 0.0, 0.0, occ_hv, occ_av), math.nan,
                  int(RIGHT_OF_WAY_IDS[c.responsibility.right_of_way]))
        vehicles = Vehicles(("av", c.hv.kind), (Limits.of(c, "av"), Limits.of(c, "hv")),
                            states[0, [0, 2]].copy(), states[0, [1, 3]].copy(), np.zeros(2),
                            np.array([scene.av.clear_s, scene.hv.clear_s]),
                            {"path": ("av", "hv")})
        codes = log.get("shield_verdict")
        verdicts = ([None] * n_steps if codes is None
                    else [verdict_name(int(v)) for v in codes])
        collisions = []
        if self.outcome.collision:
            hit = np.flatnonzero(scene.collides(states[1:, 0], states[1:, 2]))
            collisions.append(((int(hit[0]) + 1) * dt, 0, 1,
                               bool(self.outcome.collision_caused_by_av)))
        opponents = np.zeros((n_steps, 2), np.int16)
        opponents[:, 0] = -1

        def place(i: int, s: np.ndarray):
            return scene.positions(("av", "hv")[i], s)

        return Trace(vehicles, ConflictTable.of_rows([row], 2, pair_min_dist(c)), self.seed, dt,
                     n_steps * dt, True, states[:, [0, 2]], states[:, [1, 3]],
                     np.column_stack([log["av_accel_mps2"], log["hv_accel_mps2"]]),
                     np.zeros((n_steps + 1, 2), np.int8), n_steps, verdicts, collisions,
                     float(self.outcome.min_gap_m), opponents, place)

    def vehicles_frame(self):
        """The run per step and vehicle (:meth:`trace`'s long table,
        ``persuasive.tables.Trace.frame``): the same columns as a junction's run, with the
        label ``path`` (``av`` or ``hv``)."""
        return self.trace().frame()

    def measures(self) -> dict[str, Any]:
        """The measures of many vehicles (``persuasive.many.measures.summary``: wait-for
        graph and deadlocks, waiting, clear times, PET, AV first per conflict) of this run,
        read from :meth:`trace` as from a junction's run."""
        from .many.measures import summary

        return summary(self.trace())

    def frame(self):
        """The per-step log as a pandas DataFrame (one row per step)."""
        import pandas as pd

        return pd.DataFrame(self.log)

    def save(self, path, extra: dict[str, Any] | None = None) -> None:
        """Write the per-step log as Parquet, atomically, with what :func:`load_record` needs
        to rebuild the record in the file's metadata: the configuration (TOML), the seed, the
        random-stream layout, the last state and the package version.

        ``extra``: more JSON fields stored beside those (a ``drive`` trial stores ``trial``:
        its participant, session, index and condition, which ``persuasive fit`` reads); they
        may not replace the record's own (ValueError)."""
        import json

        import pyarrow as pa
        import pyarrow.parquet as pq

        from ._files import atomic_write

        table = pa.Table.from_pandas(self.frame(), preserve_index=False)
        meta = {"config_toml": self.config.to_toml(), "seed": self.seed,
                "streams": self.streams, "final_state": [float(x) for x in self.states[-1]],
                "version": self.version}
        if self.yield_line_m is not None:
            meta["yield_line_m"] = self.yield_line_m
        clash = sorted(set(extra or {}) & set(meta))
        if clash:
            raise ValueError(f"extra metadata may not replace the record's own: {clash}")
        meta.update(extra or {})
        table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                               RECORD_METADATA: json.dumps(meta)})
        atomic_write(path, lambda p: pq.write_table(table, p))


#: Key of a saved run's metadata in its Parquet schema.
RECORD_METADATA = b"persuasive.run"


def load_record(path) -> RunRecord:
    """The :class:`RunRecord` saved by :meth:`RunRecord.save` (``simulate --out x.parquet``, a
    recorded trial of the browser page): states, log, outcome and configuration."""
    import json
    from pathlib import Path

    import pyarrow.parquet as pq

    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        reason = (exc.strerror or "no such file or directory").lower()
        raise ConfigError(f"run file {str(path)!r} cannot be read: {reason}") from None
    if head != b"PAR1":  # Parquet's magic bytes
        raise ConfigError(f"run file {str(path)!r} is not a Parquet file: only the .parquet "
                          "logs of 'simulate --out' and the trials of 'drive' are read back "
                          "(a .csv log holds no configuration)")
    try:
        table = pq.read_table(path)
    except OSError as exc:
        reason = (exc.strerror or "no such file or directory").lower()
        raise ConfigError(f"run file {str(path)!r} cannot be read: {reason}") from None
    except ValueError as exc:
        raise ConfigError(f"run file {str(path)!r} cannot be read: "
                          f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") \
            from None
    raw = (table.schema.metadata or {}).get(RECORD_METADATA)
    if raw is None:
        raise ConfigError(f"run file {str(path)!r} holds no run record (write it with "
                          "'persuasive simulate --out FILE.parquet' or the browser page)")
    return record_from_frame(json.loads(raw), table.to_pandas(), __version__)


def record_from_frame(meta: dict, frame, default_version: str) -> RunRecord:
    """A :class:`RunRecord` from a saved run's metadata (``config_toml``, ``seed``,
    ``final_state``, and ``streams`` and ``version`` when present) and its per-step log as a
    pandas frame; the states are the log's ``av_``/``hv_`` positions and speeds plus the final
    state, and the outcome is computed again from them."""
    import tomllib

    config = Config.from_dict(tomllib.loads(meta["config_toml"]))
    log = {name: frame[name].to_numpy() for name in frame.columns}
    states = np.vstack([frame[["av_s_m", "av_v_mps", "hv_s_m", "hv_v_mps"]].to_numpy(float),
                        np.asarray(meta["final_state"], float)[None, :]])
    scenario = static_setup(config)[0]
    return RunRecord(config, int(meta["seed"]), (float(states[0, 0]), float(states[0, 1])),
                     (float(states[0, 2]), float(states[0, 3])), states, log,
                     outcome(scenario, states, log), scenario, meta.get("streams", "legacy"),
                     version=meta.get("version", default_version),
                     yield_line_m=meta.get("yield_line_m"))


def check_seed(seed: Any) -> int:
    """The seed as an int, or :class:`ConfigError` if it is not an integer in [0, 2^32 - 1]."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise ConfigError(f"seed = {seed!r} is out of range; allowed: integer in [0, 2^32 - 1]")
    return int(seed)


@dataclass
class Setup:
    """Everything a loop needs for one run, shared by the compiled and the Python loop."""

    config: Config
    seed: int
    scenario: Scenario
    P_av: np.ndarray
    P_hv: np.ndarray
    disc: np.ndarray
    streams: Any  #: :class:`persuasive.streams.Streams`
    x0: np.ndarray
    #: the yield line foresight picked (``av.yield_line_choices_m``; ``P_av`` carries it)
    yield_line_m: float | None = None


def geometry_key(config: Config) -> tuple:
    """What the geometry of ``config``'s scenario depends on: the ``[scenario]`` section, both
    vehicles' lengths and widths, the lane width, the safety factor and the shield's clearance
    in force (every scenario's ``build`` reads no more of the configuration, and its checks of
    the starts, which read the limits too, are made again on every use). Not the vehicles'
    speed and acceleration limits, the run's length, the policies or the noise: a recorded
    pair's views have one geometry in every fold of a held-out evaluation, whose vehicle
    limits differ (``tests/test_record.py`` builds every kind with those changed and compares
    the result with a build from scratch)."""
    av, hv = config.vehicle_of("av"), config.vehicle_of("hv")
    return (config.scenario, av.length_m, av.width_m, hv.length_m, hv.width_m,
            config.vehicle.lane_width_m, config.vehicle.safety_factor, config.shield_margin_m)


class GeometryCache:
    """The scenarios' geometries by :func:`geometry_key`, the ``maxsize`` last used kept:
    each a :class:`Scenario` with ``config = None`` (the paths' vehicles are replaced on use).
    A merge's geometry takes 0.4 s to build (its occupancy intervals, sampled every 5 cm), and
    a held-out evaluation asks for each recorded view's in every fold."""

    def __init__(self, maxsize: int):
        from collections import OrderedDict
        from threading import Lock

        self.maxsize = maxsize
        self._store: OrderedDict = OrderedDict()
        self._lock = Lock()  # a Dask worker's tasks run on threads

    def __len__(self) -> int:
        return len(self._store)

    def get(self, key: tuple) -> Scenario | None:
        with self._lock:
            geometry = self._store.get(key)
            if geometry is not None:
                self._store.move_to_end(key)
            return geometry

    def put(self, key: tuple, geometry: Scenario) -> None:
        with self._lock:
            self._store[key] = geometry
            self._store.move_to_end(key)
            while len(self._store) > self.maxsize:
                self._store.popitem(last=False)

    def items(self) -> list[tuple[tuple, Scenario]]:
        with self._lock:
            return list(self._store.items())

    def clear(self) -> None:
        with self._lock:
            self._store.clear()


#: The geometries kept (:func:`scenario_of`): a site's recorded views (6,831 distinct of
#: 7,208 on the site-size recording's 3,604 pairs of docs/guide/recordings.md) fit.
GEOMETRIES = GeometryCache(maxsize=2 ** 15)


def geometry_of(scenario: Scenario) -> Scenario:
    """What :data:`GEOMETRIES` keeps of a built scenario: it without its configuration."""
    from dataclasses import replace

    return replace(scenario, config=None)


def with_geometry(geometry: Scenario, config: Config) -> Scenario:
    """The scenario of ``config`` from its geometry (:func:`geometry_of` of a scenario of
    the same :func:`geometry_key`): the configuration and the paths' vehicles (their
    limits) ``config``'s, the starts checked as a build checks them. Equal to
    ``build_scenario(config)`` field for field; where the starts fail, the build itself
    raises (its message names the kind it checked: a crossing at 90 deg is checked as the
    intersection)."""
    from dataclasses import replace

    from .scenarios.base import shape

    scenario = replace(geometry, config=config,
                       av=replace(geometry.av, vehicle=shape(config, "av")),
                       hv=replace(geometry.hv, vehicle=shape(config, "hv")))
    try:
        scenario.check_starts()
    except ConfigError:
        return build_scenario(config)
    return scenario


def scenario_of(config: Config, cache: GeometryCache | None = GEOMETRIES) -> Scenario:
    """``build_scenario(config)``, its geometry built once per :func:`geometry_key` and kept
    in ``cache`` (None: built anew). Errors as the build's: a geometry is kept only once a
    build has passed its checks."""
    if cache is None:
        return build_scenario(config)
    key = geometry_key(config)
    geometry = cache.get(key)
    if geometry is not None:
        return with_geometry(geometry, config)
    scenario = build_scenario(config)
    cache.put(key, geometry_of(scenario))
    return scenario


@functools.lru_cache(maxsize=32)
def static_setup(config: Config) -> tuple[Scenario, np.ndarray, np.ndarray, np.ndarray]:
    """The scenario, both parameter vectors and the discounts of ``config`` (they depend on
    the configuration only; kept for the last few configurations, since building a scenario
    can take milliseconds, and the scenario's geometry for many more, :func:`scenario_of`).
    The arrays are shared by every run of the configuration: do not change them (they are
    not marked read-only, which would give the kernels another type to compile for)."""
    scenario = scenario_of(config)
    P_av, P_hv = pack(config, scenario)
    return scenario, P_av, P_hv, discounts(config)


def setup(config: Config, seed: int, k_av: int | None = None,
          k_hv: int | None = None, interaction: int = 0,
          x0: np.ndarray | None = None, predict=None) -> Setup:
    """The scenario, parameter vectors, random streams and initial state of a run.

    ``k_av``, ``k_hv``: uniforms per step of each policy (default: the configured kinds').
    A ``replay`` human starts from its recorded initial state. ``interaction``: the repeated
    interaction with the seed's human (``persuasive.streams.interaction_seed``). ``x0``
    ``(4,)``: the initial state in place of both (the streams are drawn as ever).
    ``predict(config, seed, interaction, x0) -> summary``: how a loop predicts a run, for
    foresight (``av.yield_line_choices_m``: the line is picked here, before the first step,
    and set in ``P_av``; ``persuasive.world.predicted_summary`` in both loops).
    """
    seed = check_seed(seed)
    scenario, P_av, P_hv, disc = static_setup(config)
    k_av = kind_of(config, kd.AV).draws if k_av is None else k_av
    k_hv = kind_of(config, kd.HV).draws if k_hv is None else k_hv
    streams = draw_streams(config, seed, scenario, k_av, k_hv, interaction)
    if x0 is not None:
        x0 = np.array(x0, dtype=np.float64).reshape(4)
    else:
        x_hv = streams.x_hv
        if config.hv.kind == "replay":
            rec = load_replay(config)
            x_hv = (rec.s0_m, rec.v0_mps)
        x0 = np.array([*streams.x_av, *x_hv], dtype=np.float64)
    line = None
    if config.yield_line_choices is not None:  # foresight picks the run's yield line
        from .packing import place_yield_line
        from .safety.foresight import choose_line

        if predict is None:
            raise ConfigError("av.yield_line_choices_m (foresight) predicts runs before the "
                              "first step: run it with persuasive.simulation.simulate or the "
                              "Python loop")
        measured = np.array(measure_states(x0, 0, streams.noisy, streams.meas_noise, P_av, P_hv))
        line = choose_line(config, seed, measured, predict, interaction)
        P_av = P_av.copy()  # the static vector is shared by every run of the configuration
        place_yield_line(P_av, line)
    return Setup(config, seed, scenario, P_av, P_hv, disc, streams, x0, line)


def make_record(s: Setup, states: np.ndarray, world_log: np.ndarray, av_log: np.ndarray,
                hv_log: np.ndarray, av_decision_ms: np.ndarray | None,
                av_columns: tuple[str, ...] | None = None,
                hv_columns: tuple[str, ...] | None = None,
                work: np.ndarray | None = None) -> RunRecord:
    """The :class:`RunRecord` of a finished loop (either loop)."""
    config = s.config
    av_columns = kind_of(config, kd.AV).log if av_columns is None else av_columns
    hv_columns = kind_of(config, kd.HV).log if hv_columns is None else hv_columns
    log = _columns(s, states, world_log, av_log, hv_log, av_columns, hv_columns)
    x_av, x_hv = (float(states[0, 0]), float(states[0, 1])), (float(states[0, 2]),
                                                                float(states[0, 3]))
    return RunRecord(config, s.seed, x_av, x_hv, states, log, outcome(s.scenario, states, log),
                     s.scenario, s.streams.layout, av_decision_ms,
                     None if work is None else dict(zip(WORK_NAMES, (int(w) for w in work))),
                     yield_line_m=s.yield_line_m)


def _columns(s: Setup, states, world_log, av_log, hv_log, av_columns, hv_columns):
    config, scenario = s.config, s.scenario
    n = world_log.shape[0]
    log: dict[str, np.ndarray] = {
        "step": np.arange(n, dtype=np.int64),
        "t_s": np.arange(n) * config.simulation.dt_s,
        "av_s_m": states[:-1, 0],
        "av_v_mps": states[:-1, 1],
        "hv_s_m": states[:-1, 2],
        "hv_v_mps": states[:-1, 3],
        "distance_m": scenario.distance(states[:-1, 0], states[:-1, 2]),
    }
    for who, j in (("av", 0), ("hv", 2)):
        x, y, heading = scenario.positions(who, states[:-1, j])
        log[f"{who}_x_m"], log[f"{who}_y_m"], log[f"{who}_heading_rad"] = x, y, heading
    log.update({name: world_log[:, j] for j, name in enumerate(WORLD_LOG)})
    log["shield_verdict"] = log["shield_verdict"].astype(np.int64)
    for who, names, raw in (("hv", hv_columns, hv_log), ("av", av_columns, av_log)):
        for j, name in enumerate(names):
            col = raw[:, j]
            if name in kd.ROLE_COLUMNS:
                col = np.where(col == LEADER, "leader", "follower")
            elif name in kd.INT_COLUMNS:
                col = col.astype(np.int64)
            elif name in kd.BOOL_COLUMNS:
                col = col != 0.0
            log[f"{who}_{name}"] = col
    return log


@njit(cache=True, _nrt=False)
def free_flow_time(s0: float, v0: float, target_s: float, dt: float, u_max: float,
                   v_min: float, v_max: float, limit: int = 100_000) -> float:
    """Time [s] to reach ``target_s`` from ``(s0, v0)`` at full throttle up to ``v_max``, on
    the loop's time grid (the first step after which ``s >= target_s``); NaN beyond
    ``limit`` steps."""
    s, v = s0, v0
    for k in range(limit):
        if s >= target_s:
            return k * dt
        s, v = saturated_step(s, v, u_max, dt, v_min, v_max)
    return math.nan


def _first_time(hit: np.ndarray, dt: float) -> float:
    k = np.flatnonzero(hit)
    return float((k[0] + 1) * dt) if k.size else math.nan


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else math.nan


def outcome(scenario: Scenario, states: np.ndarray, log: dict[str, np.ndarray]) -> RunOutcome:
    """The metrics of a run from its states and log."""
    config = scenario.config
    dt = config.simulation.dt_s
    after = states[1:]
    line, idx_line = first_arrival(scenario.at_line("av", after[:, 0]),
                                   scenario.at_line("hv", after[:, 2]))
    conflict, _ = first_arrival(scenario.at_conflict_point(after[:, 0]),
                                scenario.at_conflict_point(after[:, 2]))
    d = scenario.distance(states[:, 0], states[:, 2])
    idx_end = idx_line if idx_line is not None else after.shape[0] - 1
    changes = {
        who: int(np.sum(log[f"{who}_next_role"] != log[f"{who}_role"]))
        if f"{who}_role" in log else 0
        for who in ("hv", "av")
    }
    infeasible = int(np.sum(~log["av_feasible"])) if "av_feasible" in log else 0
    times: dict[str, float] = {}
    for who, j in (("av", 0), ("hv", 2)):
        path = getattr(scenario, who)
        times[f"{who}_time_to_line_s"] = _first_time(scenario.at_line(who, after[:, j]), dt)
        clear = _first_time(scenario.cleared(who, after[:, j]), dt)
        times[f"{who}_time_to_clear_s"] = clear
        veh = path.vehicle
        if math.isnan(clear):
            times[f"{who}_delay_s"] = math.nan
        else:
            free = free_flow_time(float(states[0, j]), float(states[0, j + 1]), path.clear_s,
                                  dt, veh.u_max_mps2, veh.v_min_mps, veh.v_max_mps)
            times[f"{who}_delay_s"] = clear - free
        accel = log[f"{who}_accel_mps2"]
        times[f"{who}_rms_accel_mps2"] = _rms(accel)
        times[f"{who}_rms_jerk_mps3"] = _rms(np.diff(accel) / dt)
    overlap = scenario.collides(after[:, 0], after[:, 2])
    caused = measures.caused_by_av(overlap, measures.human_at_fault(
        scenario, states, log["av_accel_mps2"], dt, log["hv_accel_mps2"]))
    # a contact by the other vehicle (a rear-end by the human) ends what the shield is
    # judged on: the simulation has no contact, so the human drives on through the AV and
    # the states after it are no state the shield could keep (docs/method.md §12.2)
    contact = np.flatnonzero(overlap & ~caused)
    judged = int(contact[0]) + 1 if contact.size else len(after)
    occ_av, occ_hv = scenario.av.occupancy, scenario.hv.occupancy
    verdicts = log.get("shield_verdict")
    accel = log["av_accel_mps2"]
    from .safety.shield import UNCERTIFIED

    uncertified = (int(np.sum(verdicts[:judged] == UNCERTIFIED)) if verdicts is not None
                   else 0)
    cleared_av = scenario.cleared("av", states[:, 0])
    cleared_hv = scenario.cleared("hv", states[:, 2])
    both = bool(cleared_av[-1] and cleared_hv[-1])
    stood = measures.standoff(states[:, 0], states[:, 2], cleared_av, cleared_hv, dt)
    return RunOutcome(
        first_at_line=line,
        first_at_conflict_point=conflict,
        collision=bool(np.any(overlap)),
        min_distance_to_line_m=float(d[: idx_end + 2].min()),
        min_distance_m=float(d.min()),
        idx_end=int(idx_end),
        infeasible_steps=infeasible,
        hv_role_changes=changes["hv"],
        av_role_changes=changes["av"],
        **times,
        collision_caused_by_av=bool(np.any(caused)),
        rear_end_by_human=bool(np.any(overlap & ~caused)),
        min_gap_m=float(measures.min_gap(scenario, states[:, 0], states[:, 2]).min()),
        pet_s=float(measures.pet(states[:, 0], states[:, 2], occ_av, occ_hv, dt)),
        min_ttc_s=float(measures.min_ttc(states[:, 0], states[:, 1], states[:, 2], states[:, 3],
                                         *occ_av, *occ_hv, scenario.lane_shared,
                                         0.5 * (scenario.av.vehicle.length_m
                                                + scenario.hv.vehicle.length_m))),
        shield_interventions=int(np.sum(verdicts > 0)) if verdicts is not None else 0,
        av_max_brake_mps2=float(max(0.0, -np.min(accel))) if len(accel) else 0.0,
        uncertified_steps=uncertified,
        guarantee_held=bool(config.shield == "worst-case" and uncertified == 0
                            and verdicts is not None and len(verdicts) > 0
                            and not _noisy(config)),
        both_cleared=both,
        av_first_through=bool(both and conflict == 1),
        deadlock=not math.isnan(stood),
        deadlock_at_s=stood,
        av_wait_s=measures.waiting_time(states[:, 1], cleared_av, dt),
        hv_wait_s=measures.waiting_time(states[:, 3], cleared_hv, dt),
        **measures.override_cost(verdicts, log.get("av_proposed_accel_mps2"), accel),
    )


def _noisy(config) -> bool:
    """The run has noise the shield does not know of (docs/method.md §12.2): Gaussian
    measurement noise (unbounded; the uniform one and the acceleration noise it certifies
    against)."""
    sim = config.simulation
    return sim.measurement_noise == "gaussian" and (sim.noise_s_m > 0.0
                                                    or sim.noise_v_mps > 0.0)


__all__ = ["ARRIVAL_LABELS", "DISTANCE_MEASURED", "GEOMETRIES", "GeometryCache",
           "OUTCOME_FIELDS", "RECORD_METADATA", "WORLD_LOG", "RunOutcome", "RunRecord", "Setup",
           "check_seed", "geometry_key", "geometry_of", "load_record", "make_record", "outcome",
           "record_from_frame", "scenario_of", "setup", "static_setup", "with_geometry"]
