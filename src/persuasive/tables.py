"""The tables of a run: vehicles, conflicts and what they did, for 2 vehicles and for N
(docs/method.md §15.1).

Every world is described by the same three tables, whatever its number of vehicles:

- the **vehicles table** (:class:`Vehicles`): per vehicle its kind (``av`` or the human's),
  limits (:class:`Limits`), initial state and arrival time, the arc length past which it
  has left the conflict area (``through_m``) and descriptive labels (its path, or at a
  junction its arm, movement and lane);
- the **conflict table** (:class:`ConflictTable`): one :class:`Row` per pair of vehicles
  whose paths come close enough for the footprints to touch: its kind (:data:`CROSSING`,
  :data:`MERGE` or :data:`FOLLOW`), the conflict seen from each side (:class:`RouteConflict`:
  both conflict points and both occupancy intervals, in each vehicle's own arc length), the
  lane shared by a follow row and who has the right of way;
- the **trace** (:class:`Trace`): what the run did, per step and vehicle (positions, speeds,
  applied accelerations, status), the shield's verdicts, the collisions and the human
  opponents; :meth:`Trace.frame` is its long table (one row per step and vehicle on the
  road).

The two-vehicle scenarios are the N = 2 case: two vehicles, one row (a crossing, or a merge
where the lanes are shared), both conflict points at ``s = 0`` of the paths
(``persuasive.record.RunRecord.trace``). The junction's world fills the same tables
(``persuasive.many.world.JunctionWorld.trace``), and the measures of liveness and safety for
many (``persuasive.many.measures``) read only these tables, so they measure a two-vehicle run
exactly as one of N.

:class:`Conflict` is the per-step view of one row from one vehicle, as the shield and the
outside-simulator adapters (``persuasive.envs.external``) take it; :class:`RouteConflict`
turns the two vehicles' arc lengths into it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Hashable

import numpy as np

from .config import Config

#: Kinds of conflict: the paths cross once; the other joins the ego's lane (a merge); the
#: other is ahead in the ego's lane (follow).
CROSSING, MERGE, FOLLOW = "crossing", "merge", "follow"


@dataclass(frozen=True)
class Limits:
    """A vehicle's size and actuation limits."""

    length_m: float
    width_m: float
    u_min_mps2: float
    u_max_mps2: float
    v_min_mps: float
    v_max_mps: float

    @classmethod
    def of(cls, config: Config, who: str) -> Limits:
        v = config.vehicle_of(who)
        return cls(v.length_m, v.width_m, v.u_min_mps2, v.u_max_mps2, v.v_min_mps, v.v_max_mps)


@dataclass(frozen=True)
class Conflict:
    """One outside vehicle on its conflict with the ego's path (module docstring)."""

    key: Hashable  #: the vehicle's identity in the simulator
    kind: str  #: :data:`CROSSING`, :data:`MERGE` or :data:`FOLLOW`
    ego_s_m: float  #: the ego's position relative to the conflict point, along its path [m]
    other_s_m: float  #: the other's, along its own path [m]
    other_v_mps: float  #: the other's speed [m/s]
    #: where the ego's footprint can touch the other's path [m] (a merge: up to the merge
    #: point, 0; follow: unused)
    ego_occupancy: tuple[float, float] = (-math.inf, math.inf)
    #: where the other's footprint can touch the ego's path [m] (a merge: its side zone)
    other_occupancy: tuple[float, float] = (-math.inf, math.inf)
    other: Limits | None = None  #: its limits (default: the configuration's human vehicle)
    #: the adapter's own data; ``"stand_in": True`` marks a vehicle not in the simulator yet
    #: (highway-env's spawns), which the shield checks and the planner does not plan against;
    #: ``"placeholder": True`` one that stands for vehicles still to be inserted (SUMO's
    #: entries), planned against but, like a stand-in, no driver with duties under the
    #: responsibility rule (``persuasive.safety.responsibility``); ``"wreck": True`` a
    #: crashed vehicle, a standing obstacle with no duty either (highway-env's)
    extra: dict = field(default_factory=dict, compare=False)
    #: the ego's yield line relative to the conflict point [m]: where the shield makes it
    #: stand when it yields (docs/method.md §12.8; e.g. before a junction's polygon); None:
    #: ``ego_occupancy[0]`` less the configuration's ``av.yield_line_m``; never after
    #: ``ego_occupancy[0]``
    ego_line_m: float | None = None
    #: who has the right of way here under the responsibility rule (docs/method.md §12.13):
    #: 1 the ego, -1 the other, 0 neither (the simulator's own road, e.g. highway-env's lane
    #: priorities); None: the configuration's ``responsibility.right_of_way``
    right_of_way: float | None = None


@dataclass(frozen=True)
class RouteConflict:
    """The conflict of another route with the ego's, in each route's arc length: the kind,
    the conflict point on each route (``ego_at_m``, ``other_at_m``) and the occupancy
    intervals relative to it (what :class:`Conflict` takes)."""

    kind: str
    ego_at_m: float
    other_at_m: float
    ego_occupancy: tuple[float, float]
    other_occupancy: tuple[float, float]
    #: the ego's yield line relative to its conflict point (:attr:`Conflict.ego_line_m`;
    #: None: the configuration's)
    ego_line_m: float | None = None

    def conflict(self, key: Hashable, ego_arc_m: float, other_arc_m: float, other_v_mps: float,
                 other: Limits | None = None, extra: dict | None = None,
                 ego_occupancy: tuple[float, float] | None = None) -> Conflict:
        """The :class:`Conflict` of vehicles whose centres are at these arc lengths of their
        routes. A merge the ego has passed (it is in the shared lane) with the other ahead
        is a :data:`FOLLOW` conflict. ``ego_occupancy``: the ego's interval to hand on in
        place of :attr:`ego_occupancy` (e.g. widened for a simulator's integration; a
        follow conflict keeps its own)."""
        s_R, s_H = ego_arc_m - self.ego_at_m, other_arc_m - self.other_at_m
        kind = self.kind
        occupancy = self.ego_occupancy if ego_occupancy is None else ego_occupancy
        if kind == MERGE and s_R >= self.ego_occupancy[1] and s_H > s_R:
            kind, occupancy = FOLLOW, self.ego_occupancy
        return Conflict(key, kind, float(s_R), float(s_H), float(other_v_mps),
                        occupancy, self.other_occupancy, other,
                        extra if extra is not None else {},
                        ego_line_m=None if kind == FOLLOW else self.ego_line_m)



#: Vehicle status codes (PENDING: arrives later, not on the road yet).
ACTIVE, DONE, CRASHED, PENDING = 0, 1, 2, 3
#: A vehicle slower than this waits [m/s] (the wait-for graph, ``persuasive.many.measures``).
WAIT_V_MPS = 0.5
#: A vehicle slower than this stands [m/s] (SUMO's ``waitingTime`` threshold; the two-vehicle
#: waits, ``persuasive.safety.measures``, and standing inside, ``persuasive.many.measures``).
STAND_V_MPS = 0.1


@dataclass(frozen=True)
class Row:
    """One conflict (module docstring): vehicles ``i < j``; ``ij`` is the conflict seen from
    ``i`` (``i`` the ego of :class:`RouteConflict`), ``ji`` from ``j`` (both None for a
    follow row); ``shared_until_m``: for a follow row, the arc up to which the lane is shared;
    ``priority``: +1 ``i`` has the right of way, -1 ``j``, 0 neither."""

    i: int
    j: int
    kind: str
    ij: RouteConflict | None
    ji: RouteConflict | None
    shared_until_m: float
    priority: int


@dataclass
class ConflictTable:
    """Every conflict of a run (module docstring) and, per vehicle, the rows it is in."""

    rows: list[Row]
    of: list[list[int]]  #: per vehicle: indices of its rows
    #: the radius of the keep-out circle a human's pair game keeps around a conflict point
    #: (the pair's safety distance) [m]; 0: none (``persuasive.many.measures`` reads it)
    keep_out_m: float = 0.0

    @classmethod
    def of_rows(cls, rows: list[Row], n: int, keep_out_m: float = 0.0) -> ConflictTable:
        """The table of ``rows`` among ``n`` vehicles."""
        of: list[list[int]] = [[] for _ in range(n)]
        for r, row in enumerate(rows):
            of[row.i].append(r)
            of[row.j].append(r)
        return cls(list(rows), of, keep_out_m)


@dataclass(frozen=True)
class Vehicles:
    """The vehicles table (module docstring); vehicle 0 is the AV."""

    kind: tuple[str, ...]  #: ``av`` for the AV, else the human's kind
    limits: tuple[Limits, ...]
    s0_m: np.ndarray  #: initial arc length along its path [m]
    v0_mps: np.ndarray  #: initial speed [m/s]
    t0_s: np.ndarray  #: arrival time [s] (0: on the road from the start)
    through_m: np.ndarray  #: the arc past which it has left the conflict area [m]
    #: descriptive columns of :meth:`Trace.frame`, one value per vehicle each (a two-vehicle
    #: run: ``path``; a junction: ``arm``, ``movement``, ``lane``)
    labels: dict[str, tuple] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.kind)


#: ``place(i, s) -> (x, y, heading)``: vehicle ``i``'s centre [m] and heading [rad] at arc
#: lengths ``s`` of its path (arrays).
Place = Callable[[int, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass
class Trace:
    """What a run did, per step and vehicle (module docstring): the tables' run.

    ``S``, ``V``: ``(n_steps + 1, n)`` arc lengths [m] and speeds [m/s] at each step (NaN
    while a vehicle is off the road); ``A``: ``(n_steps, n)`` the applied accelerations over
    each step [m/s^2]; ``STATUS``: ``(n_steps + 1, n)`` status codes; ``k``: the steps run
    (a junction's run may end early); ``verdicts``: the shield's verdict on the AV per step
    (``None``: no shield, else ``admitted``, ``brake``, ``go``, ``uncertified``);
    ``collisions``: ``(t [s], i, j, caused by the AV)``; ``min_gap_av_m``: the AV's closest
    footprint gap to any human [m]; ``opponents``: ``(n_steps, n)`` the vehicle each human
    played at each step (-1: none; the AV's column -1); ``place``: positions for
    :meth:`frame`.
    """

    vehicles: Vehicles
    table: ConflictTable
    seed: int
    dt: float
    duration_s: float
    with_av: bool
    S: np.ndarray
    V: np.ndarray
    A: np.ndarray
    STATUS: np.ndarray
    k: int
    verdicts: list
    collisions: list
    min_gap_av_m: float
    opponents: np.ndarray
    place: Place

    # the attributes the measures read, named as the junction's world names them
    @property
    def n(self) -> int:
        return self.vehicles.n

    @property
    def limits(self) -> tuple[Limits, ...]:
        return self.vehicles.limits

    @property
    def t0(self) -> np.ndarray:
        return self.vehicles.t0_s

    @property
    def status(self) -> np.ndarray:
        """Every vehicle's status after the last step."""
        return self.STATUS[self.k]

    def through_m(self, i: int) -> float:
        """The arc past which vehicle ``i`` has left the conflict area."""
        return float(self.vehicles.through_m[i])

    def frame(self):
        """The run per step and vehicle, as a pandas DataFrame (long format, one row per
        vehicle on the road at a step): ``step``, ``t_s``, ``vehicle`` (0 the AV), ``kind``
        (``av`` or the human's), the vehicles' labels (:attr:`Vehicles.labels`), ``s_m``
        (arc length along its path), ``v_mps``, ``a_mps2`` (over the step that follows; NaN
        at the last), ``x_m``, ``y_m``, ``heading_rad`` and ``opponent`` (the vehicle a
        human played that step, -1: none)."""
        import pandas as pd

        veh = self.vehicles
        n_k = self.k + 1
        names = ("step", "t_s", "vehicle", "kind", *veh.labels, "s_m", "v_mps", "a_mps2",
                 "x_m", "y_m", "heading_rad", "opponent")
        cols: dict[str, list] = {name: [] for name in names}
        for i in range(veh.n):
            s = self.S[:n_k, i]
            on = np.isfinite(s)
            if not on.any():
                continue
            k = np.flatnonzero(on)
            sk = s[k]
            m = k.size
            x, y, heading = self.place(i, sk)
            a = np.full(m, np.nan)
            inside = k < self.A.shape[0]
            a[inside] = self.A[k[inside], i]
            opp = np.full(m, -1, np.int64)
            opp[inside] = self.opponents[k[inside], i]
            cols["step"].append(k)
            cols["t_s"].append(k * self.dt)
            cols["vehicle"].append(np.full(m, i))
            cols["kind"].append(np.full(m, veh.kind[i], dtype=object))
            for name, values in veh.labels.items():
                value = values[i]
                cols[name].append(np.full(m, value, dtype=object if isinstance(value, str)
                                          else None))
            cols["s_m"].append(sk)
            cols["v_mps"].append(self.V[k, i])
            cols["a_mps2"].append(a)
            cols["x_m"].append(x)
            cols["y_m"].append(y)
            cols["heading_rad"].append(heading)
            cols["opponent"].append(opp)
        frame = pd.DataFrame({name: np.concatenate(v) if v else [] for name, v in cols.items()})
        return frame.sort_values(["step", "vehicle"], kind="stable").reset_index(drop=True)

    def conflicts_frame(self):
        """The conflict table as a pandas DataFrame, one row per conflict: ``i``, ``j``,
        ``kind``, each side's conflict point and occupancy interval (``i_at_m``, ``i_lo_m``,
        ``i_hi_m``, ``j_...``; NaN for a follow row), ``shared_until_m`` and ``priority``."""
        import pandas as pd

        out = []
        for row in self.table.rows:
            d = {"i": row.i, "j": row.j, "kind": row.kind}
            for side, rc in (("i", row.ij), ("j", row.ji)):
                at, (lo, hi) = ((math.nan, (math.nan, math.nan)) if rc is None
                                else (rc.ego_at_m, rc.ego_occupancy))
                d[f"{side}_at_m"], d[f"{side}_lo_m"], d[f"{side}_hi_m"] = at, lo, hi
            d["shared_until_m"], d["priority"] = row.shared_until_m, row.priority
            out.append(d)
        return pd.DataFrame(out, columns=["i", "j", "kind", "i_at_m", "i_lo_m", "i_hi_m",
                                          "j_at_m", "j_lo_m", "j_hi_m", "shared_until_m",
                                          "priority"])


__all__ = ["ACTIVE", "CRASHED", "CROSSING", "DONE", "FOLLOW", "MERGE", "PENDING", "WAIT_V_MPS",
           "Conflict", "ConflictTable", "Limits", "Place", "RouteConflict", "Row", "Trace",
           "Vehicles"]
