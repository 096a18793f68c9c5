"""Liveness and safety of a run of many vehicles (docs/method.md §15.5), read from the run's
tables (``persuasive.tables.Trace``): a junction's run (``JunctionWorld.trace``) or a
two-vehicle run, their N = 2 case (``persuasive.record.RunRecord.trace``). Every function
takes a trace or a world that has one.

- **Wait-for graph** (:func:`wait_edges`): at a step, vehicle ``i`` waits for ``j`` when ``i``
  is slower than ``WAIT_V_MPS`` before leaving the box, and either ``j`` is ahead of it in a
  lane they share within ``FOLLOW_GAP_M`` (bumper gap), or ``i`` has not reached the
  conflict point of a crossing or merge with ``j``, is within ``APPROACH_M`` of its occupancy
  interval or inside it, and ``j`` has not cleared the conflict and is within ``APPROACH_M``
  of its own interval or inside it.
- **Deadlock** (:func:`deadlock`): a cycle of that graph (a strongly connected component of
  two or more vehicles, ``scipy.sparse.csgraph``) whose members stay the same for
  ``DEADLOCK_S`` seconds; the first one is reported with its members and time.
- **Standing clear** (:func:`stands_clear`): the AV waiting (slower than ``WAIT_V_MPS``), its
  centre before the occupancy interval of every crossing and merge of its own (outside the
  junction) and, for a given row, at least the table's ``keep_out_m`` before that row's
  conflict point (outside the circle the human's pair game keeps around it). A human that
  waits for an AV standing clear of it waits by its own choice: the way is free.
- **AV-caused deadlock** (:func:`av_caused`): a deadlock with the AV in it in which, at the
  step it is declared, the AV is still on a cycle of the wait-for graph once the edges of the
  humans waiting for an AV that stands clear of them are removed.
- **Standing inside** (:func:`stood_inside`): the AV at rest (slower than 0.1 m/s,
  ``persuasive.tables.STAND_V_MPS``, as the two-vehicle waits) with its centre
  inside the occupancy interval of one of its crossings or merges; *blocking* when,
  at the same step, a human waits for it in the wait-for graph.
- **Waiting time**: the time a vehicle spends slower than ``WAIT_V_MPS`` before leaving the
  box.
- **Throughput**: vehicles through the box per hour, over the time until the last one left
  it (the run's length when some did not).
- **Delays**: the AV's, its time to leave the box (from its arrival) less its free-flow time
  (full throttle to ``v_max`` from its initial state, alone); the delay it causes, the humans' mean time to
  leave the box less the same in the run of the same seed without the AV (a vehicle that
  never leaves counts the run's length).
- **PET** (post-encroachment time) of a crossing or merge: the time between the two centres
  passing their conflict points (linear between steps).
- **AV first**: of the AV's crossings and merges both vehicles passed, those whose conflict
  point the AV's centre passed first (persuasion's measure, per conflict).
"""

from __future__ import annotations

import math

import numpy as np

from ..tables import (ACTIVE, CRASHED, CROSSING, DONE, FOLLOW, MERGE, STAND_V_MPS, WAIT_V_MPS,
                      Trace)

#: A follower within this bumper gap of its leader waits for it [m].
FOLLOW_GAP_M = 15.0
#: How far before its occupancy interval a vehicle waits for a conflict, and how near its own
#: a vehicle must be to be waited for [m].
APPROACH_M = 20.0
#: A cycle of the wait-for graph that lasts this long is a deadlock [s].
DEADLOCK_S = 5.0


def _trace(world) -> Trace:
    """The trace of a world (``JunctionWorld``), or the trace itself."""
    return world if isinstance(world, Trace) else world.trace()


def clear_times(world: Trace) -> np.ndarray:
    """Per vehicle: the time it left the box [s] (NaN: never), linear between steps."""
    world = _trace(world)
    S, dt = world.S, world.dt
    out = np.full(world.n, np.nan)
    for i in range(world.n):
        line = world.through_m(i)
        s = S[:, i]
        past = np.flatnonzero(np.nan_to_num(s, nan=-np.inf) >= line)
        done = np.flatnonzero(world.STATUS[:, i] == DONE)
        if past.size:
            k = int(past[0])
            if k == 0:
                out[i] = 0.0
            else:
                s0, s1 = s[k - 1], s[k]
                out[i] = dt * (k - 1 + (line - s0) / (s1 - s0) if s1 > s0 else k)
        elif done.size:  # left the map within one step
            out[i] = dt * int(done[0])
    return out


def free_flow_s(s0: float, v0: float, s1: float, u_max: float, v_max: float) -> float:
    """The time to go from ``s0`` to ``s1`` [m] starting at ``v0``, at ``u_max`` up to
    ``v_max``, in continuous time (not ``persuasive.record.free_flow_time``, which counts the
    loop's steps: the clear times here are interpolated between steps, and the delay compares
    like with like)."""
    d = s1 - s0
    if d <= 0.0:
        return 0.0
    d_acc = (v_max * v_max - v0 * v0) / (2.0 * u_max)
    if d <= d_acc:
        return (-v0 + math.sqrt(v0 * v0 + 2.0 * u_max * d)) / u_max
    return (v_max - v0) / u_max + (d - d_acc) / v_max


def wait_edges(world: Trace, k: int) -> list[tuple[int, int]]:
    """The wait-for graph at step ``k`` (module docstring), as ``(waiter, waited for)``."""
    world = _trace(world)
    s, v, st = world.S[k], world.V[k], world.STATUS[k]
    waiting = [(st[i] == ACTIVE and v[i] < WAIT_V_MPS and s[i] < world.through_m(i))
               for i in range(world.n)]
    edges = []
    for row in world.table.rows:
        i, j = row.i, row.j
        if st[i] != ACTIVE or st[j] != ACTIVE or not (waiting[i] or waiting[j]):
            continue
        if row.kind == FOLLOW:
            if s[i] > s[j]:
                lead, fol = i, j
            else:
                lead, fol = j, i
            gap = s[lead] - s[fol] - 0.5 * (world.limits[lead].length_m +
                                             world.limits[fol].length_m)
            if waiting[fol] and gap < FOLLOW_GAP_M and s[fol] <= row.shared_until_m:
                edges.append((fol, lead))
            continue
        for a, b, rc in ((i, j, row.ij), (j, i, row.ji)):
            if not waiting[a]:
                continue
            sa, sb = s[a] - rc.ego_at_m, s[b] - rc.other_at_m
            lo_a, (lo_b, hi_b) = rc.ego_occupancy[0], rc.other_occupancy
            if sa < min(0.0, rc.ego_occupancy[1]) and lo_a - sa < APPROACH_M and sb < hi_b \
                    and lo_b - sb < APPROACH_M:
                edges.append((a, b))
    return edges


def _may_cycle(edges: list[tuple[int, int]]) -> bool:
    """Whether a graph may hold a cycle: what is left after removing, again and again, every
    vertex without an edge in or without an edge out (a cheap test before the components)."""
    live = list(edges)
    while live:
        heads, tails = {b for _, b in live}, {a for a, _ in live}
        keep = [(a, b) for a, b in live if a in heads and b in tails]
        if len(keep) == len(live):
            return True
        live = keep
    return False


def all_wait_edges(world: Trace) -> list[list[tuple[int, int]]]:
    """The wait-for graph at every step of the run (:func:`wait_edges`)."""
    world = _trace(world)
    return [wait_edges(world, k) for k in range(world.k + 1)]


def _on_cycles(edges: list[tuple[int, int]], n: int) -> frozenset:
    """The vertices of a graph of ``n`` vertices that lie on a cycle: the members of its
    strongly connected components of two or more (``scipy.sparse.csgraph``)."""
    if len(edges) < 2 or not _may_cycle(edges):
        return frozenset()
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.array(edges)
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, label = connected_components(g, directed=True, connection="strong")
    return frozenset(int(m) for m in np.flatnonzero(np.bincount(label)[label] >= 2))


def deadlock(world: Trace, hold_s: float = DEADLOCK_S,
             edges_of: list[list[tuple[int, int]]] | None = None
             ) -> tuple[float, tuple[int, ...]] | None:
    """The first deadlock of the run (module docstring): ``(time it began [s], members)``,
    or None; ``edges_of``: the run's :func:`all_wait_edges`, if at hand."""
    world = _trace(world)
    hold = max(1, int(round(hold_s / world.dt)))
    current: frozenset = frozenset()
    since = 0
    for k in range(world.k + 1):
        edges = wait_edges(world, k) if edges_of is None else edges_of[k]
        cycle = _on_cycles(edges, world.n)
        if cycle != current:
            current, since = cycle, k
        if current and k - since >= hold:
            return since * world.dt, tuple(sorted(current))
    return None


def stands_clear(world: Trace, k: int) -> dict[int, bool]:
    """Per human the AV has a row with: whether the AV stands clear of it at step ``k``
    (module docstring)."""
    world = _trace(world)
    s, v = world.S[k, 0], world.V[k, 0]
    rows = [world.table.rows[r] for r in world.table.of[0]]
    waiting = bool(world.STATUS[k, 0] == ACTIVE and v < WAIT_V_MPS)
    starts = [row.ij.ego_at_m + row.ij.ego_occupancy[0] for row in rows
              if row.kind in (CROSSING, MERGE)]
    outside = waiting and all(s < lo for lo in starts)
    keep = world.table.keep_out_m
    out = {}
    for row in rows:
        far = row.kind == FOLLOW or s - row.ij.ego_at_m <= -keep
        out[row.j] = outside and far
    return out


def av_caused(world: Trace, lock: tuple[float, tuple[int, ...]] | None,
              hold_s: float = DEADLOCK_S, edges_of: list[list[tuple[int, int]]] | None = None
              ) -> bool:
    """Whether the deadlock ``lock`` (:func:`deadlock`'s) is the AV's (module docstring)."""
    if not lock or 0 not in lock[1]:
        return False
    world = _trace(world)
    k = min(world.k, int(round(lock[0] / world.dt)) + max(1, int(round(hold_s / world.dt))))
    edges = wait_edges(world, k) if edges_of is None else edges_of[k]
    clear = stands_clear(world, k)
    kept = [(a, b) for a, b in edges if not (b == 0 and clear.get(a, False))]
    return 0 in _on_cycles(kept, world.n)


def stood_inside(world: Trace, i: int = 0) -> np.ndarray:
    """Per step: vehicle ``i`` stands (slower than ``STAND_V_MPS``) inside the junction,
    its centre inside the occupancy interval of one of its crossings or merges (a merge's
    ends at the merge point)."""
    world = _trace(world)
    S, V = world.S[: world.k + 1, i], world.V[: world.k + 1, i]
    inside = np.zeros(S.shape, bool)
    for r in world.table.of[i]:
        row = world.table.rows[r]
        if row.kind not in (CROSSING, MERGE):
            continue
        rc = row.ij if row.i == i else row.ji
        lo, hi = rc.ego_occupancy
        rel = S - rc.ego_at_m
        with np.errstate(invalid="ignore"):
            inside |= (rel >= lo) & ((rel < 0.0) if row.kind == MERGE else (rel <= hi))
    with np.errstate(invalid="ignore"):
        return inside & (V < STAND_V_MPS) & (world.STATUS[: world.k + 1, i] == ACTIVE)


def waiting_s(world: Trace) -> np.ndarray:
    """Per vehicle: its waiting time [s] (module docstring)."""
    world = _trace(world)
    through = np.array([world.through_m(i) for i in range(world.n)])
    S, V = world.S[: world.k + 1], world.V[: world.k + 1]
    with np.errstate(invalid="ignore"):
        w = (world.STATUS[: world.k + 1] == ACTIVE) & (V < WAIT_V_MPS) & (S < through)
    return w.sum(axis=0) * world.dt


def pets(world: Trace) -> list[tuple[int, int, float]]:
    """``(i, j, PET [s])`` of every crossing and merge both vehicles passed."""
    return [(i, j, abs(ti - tj)) for i, j, ti, tj in passings(world)]


def passings(world: Trace) -> list[tuple[int, int, float, float]]:
    """``(i, j, t_i, t_j)``: when each centre passed its conflict point [s] (linear between
    steps), for every crossing and merge both vehicles passed."""
    world = _trace(world)
    S, dt = world.S[: world.k + 1], world.dt
    out = []

    def passed(col: np.ndarray, at: float) -> float:
        rel = np.nan_to_num(col - at, nan=-np.inf)
        k = np.flatnonzero(rel >= 0.0)
        if not k.size or k[0] == 0 or not np.isfinite(rel[k[0] - 1]):
            return math.nan if not k.size or k[0] != 0 else 0.0
        k0 = int(k[0])
        r0, r1 = rel[k0 - 1], rel[k0]
        return dt * (k0 - 1 + (-r0) / (r1 - r0))

    for row in world.table.rows:
        if row.kind not in (CROSSING, MERGE):
            continue
        ti, tj = passed(S[:, row.i], row.ij.ego_at_m), passed(S[:, row.j], row.ji.ego_at_m)
        if math.isfinite(ti) and math.isfinite(tj):
            out.append((row.i, row.j, ti, tj))
    return out


def summary(world: Trace, reference: Trace | None = None,
            step_ms: np.ndarray | None = None) -> dict:
    """One row of a study: the run's outcome and measures (module docstring);
    ``reference``: the same seed without the AV (for the delay it causes)."""
    world = _trace(world)
    reference = None if reference is None else _trace(reference)
    dt = world.dt
    t_end = world.k * dt
    clear = clear_times(world)
    n = world.n
    humans = np.arange(1, n)
    through = np.isfinite(clear)
    through[0] &= world.with_av
    n_through = int(through.sum())
    last = float(np.nanmax(clear)) if n_through else math.nan
    throughput = 3600.0 * n_through / (last if n_through == (n if world.with_av else n - 1)
                                       and last > 0 else world.duration_s)
    edges_of = all_wait_edges(world)
    lock = deadlock(world, edges_of=edges_of)
    wait = waiting_s(world)
    if world.with_av:
        inside = stood_inside(world, 0)
        waited_for = np.array([any(b == 0 for _, b in e) for e in edges_of], bool)
    else:
        inside = waited_for = np.zeros(world.k + 1, bool)
    caused = av_caused(world, lock, edges_of=edges_of)
    passed = passings(world)
    pet = [(i, j, abs(ti - tj)) for i, j, ti, tj in passed]
    av_passed = [(ti, tj) for i, _, ti, tj in passed if i == 0]
    av = world.limits[0]
    row = {
        "seed": world.seed,
        "n_vehicles": n,
        "steps": world.k,
        "av_through": bool(through[0]),
        "av_clear_s": float(clear[0]),
        "av_delay_s": float(clear[0] - world.t0[0] - free_flow_s(world.vehicles.s0_m[0],
                                                   world.vehicles.v0_mps[0],
                                                   world.through_m(0), av.u_max_mps2,
                                                   av.v_max_mps)),
        "av_collisions": sum(1 for _, i, _, _ in world.collisions if i == 0),
        "av_caused_collisions": sum(1 for _, i, _, c in world.collisions if i == 0 and c),
        "human_collisions": sum(1 for _, i, _, _ in world.collisions if i != 0),
        "uncertified_steps": sum(v == "uncertified" for v in world.verdicts),
        "shield_overrides": sum(v in ("brake", "go") for v in world.verdicts),
        "deadlock": lock is not None,
        "deadlock_t_s": lock[0] if lock else math.nan,
        "deadlock_vehicles": " ".join(map(str, lock[1])) if lock else "",
        "av_in_deadlock": bool(lock and 0 in lock[1]),
        "av_caused_deadlock": caused,
        "av_inside_stood_s": float(inside.sum() * dt),
        "av_inside_blocking_s": float((inside & waited_for).sum() * dt),
        "av_wait_s": float(wait[0]),
        "mean_wait_s": float(wait[humans].mean()) if n > 1 else 0.0,
        "max_wait_s": float(wait.max()),
        "vehicles_through": n_through,
        "throughput_veh_h": float(throughput),
        "av_conflicts_passed": len(av_passed),
        "av_first_conflicts": sum(ti < tj for ti, tj in av_passed),
        "min_pet_av_s": min((p for i, _, p in pet if i == 0), default=math.nan),
        "min_pet_s": min((p for _, _, p in pet), default=math.nan),
        "min_gap_av_m": world.min_gap_av_m,
        "caused_delay_s": math.nan,
        "crashed_humans": int((world.status[humans] == CRASHED).sum()),
        "t_end_s": t_end,
    }
    if reference is not None:
        with_av = np.where(np.isfinite(clear[1:]), clear[1:], world.duration_s)
        ref = clear_times(reference)[1:]
        without = np.where(np.isfinite(ref), ref, reference.duration_s)
        row["caused_delay_s"] = float(np.mean(with_av - without)) if n > 1 else 0.0
    if step_ms is not None and len(step_ms):
        row["step_ms_median"] = float(np.median(step_ms))
        row["step_ms_max"] = float(np.max(step_ms))
    # plain Python values (a sweep's Parquet columns, JSON)
    return {k: v.item() if isinstance(v, np.generic) else v for k, v in row.items()}


__all__ = ["APPROACH_M", "DEADLOCK_S", "FOLLOW_GAP_M", "all_wait_edges", "av_caused",
           "clear_times", "deadlock", "free_flow_s", "passings", "pets", "stands_clear",
           "stood_inside", "summary", "wait_edges", "waiting_s"]
