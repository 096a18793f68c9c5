"""The fast paths of ``recordings pairs`` (issue 42, item 2) against the plain computations
they replace, kept here or in the package as the reference:

- ``route_conflict``'s search for the pairs of samples within reach (blocks of samples with
  bounding boxes, no k-d tree, no loop over samples) against its previous implementation,
  kept here (:func:`_route_conflict_kdtree`);
- the compiled projection of every candidate at once (``pairs.project_candidates`` and its
  twins of numpy's ``interp``, ``linspace``, ``searchsorted``) against ``pairs._project``,
  pair by pair, on a junction of synthetic tracks with stops (repeated positions) and on a
  small SUMO site;
- the map's rule with each approach point looked up once (``annotate_pairs``,
  ``approach_indices``) against ``pair_rule`` and ``approach_points`` per pair;
- ``pairs_frame``'s columns built per pair against the row-by-row construction it replaces,
  and ``pairs_table`` (the parts' table, without the frame) against the frame's table.

Tolerances: none. Every float is compared bit for bit (the fast paths reproduce numpy's
arithmetic), strings, labels and IDs exactly.
"""

from __future__ import annotations

import math
from dataclasses import fields, replace

import numpy as np
import pandas as pd
import pytest

from persuasive.envs import external as X
from persuasive.recordings import pairs as P
from persuasive.recordings.formats import (INTERACTION_COLUMNS, find_track_files,
                                           read_interaction, write_interaction)
from persuasive.recordings.lanelet_map import (APPROACH_POINTS, approach_indices,
                                               approach_points)
from persuasive.recordings.tracks import SmoothingParams, smooth_tracks
from persuasive.tables import CROSSING, MERGE, RouteConflict


def _route_conflict_kdtree(ego, other, ego_size, other_size, lateral_margin_m=0.5,
                           long_margin_m=0.05, merge_at=None, step_m=0.1):
    """``route_conflict`` as it was before its search was vectorised (the reference)."""
    from scipy.spatial import cKDTree

    (l_e, w_e), (l_o, w_o) = ego_size, other_size
    reach = 0.5 * (w_e + w_o) + lateral_margin_m + step_m
    widen_e = 0.5 * l_e + 0.5 * step_m + long_margin_m
    widen_o = 0.5 * l_o + 0.5 * step_m + long_margin_m
    if merge_at is not None:
        a0, b0 = merge_at
        s_e, p_e = ego.samples(0.0, a0 + 0.5 * l_e + step_m, step_m)
        s_o, p_o = other.samples(0.0, b0 + 0.5 * l_e + reach + step_m, step_m)
    else:
        s_e, p_e = ego.samples(0.0, ego.length_m, step_m)
        s_o, p_o = other.samples(0.0, other.length_m, step_m)
    near = cKDTree(p_o).query_ball_point(p_e, reach)
    counts = np.fromiter((len(n) for n in near), np.int64, len(near))
    if counts.sum() == 0:
        return None
    i = np.repeat(np.arange(len(s_e)), counts)
    j = np.concatenate([np.asarray(n, np.int64) for n in near if n])
    a, b = s_e[i], s_o[j]
    if merge_at is not None:
        a0, b0 = merge_at
        lo_e = float(a[a <= a0].min()) if np.any(a <= a0) else a0
        ego_occ = (lo_e - widen_e - a0, 0.0)
        side = a <= a0 + 0.5 * l_e + 0.5 * step_m
        other_occ = (float(b[side].min()) - widen_o - b0, float(b[side].max()) + widen_o - b0)
        return RouteConflict(MERGE, float(a0), float(b0), ego_occ, other_occ)
    d = np.hypot(*(p_e[i] - p_o[j]).T)
    k = int(np.argmin(d))
    a0, b0 = float(a[k]), float(b[k])
    return RouteConflict(CROSSING, a0, b0,
                         (float(a.min()) - widen_e - a0, float(a.max()) + widen_e - a0),
                         (float(b.min()) - widen_o - b0, float(b.max()) + widen_o - b0))


def _random_routes(seed: int, n: int = 400):
    """``n`` cases ``(ego, other, ego_size, other_size, merge_at, step_m)``: random walks,
    lines on a whole-metre grid (ties of distance), ramps merging into a main road, long
    lines that run alongside each other (many blocks of samples within reach), after a merge
    that route_conflict refuses and a tie of closest pairs."""
    # a merge whose ego comes within reach (2.8 m) only at its last sample, past the side
    # zone's end: route_conflict raises (no sample beside the merge point)
    yield (X.Polyline.of([(0.0, 100.0), (0.0, -10.0)]),
           X.Polyline.of([(-50.0, 0.0), (50.0, 0.0)]), (4.0, 1.8), (4.0, 1.8), (94.71, 50.0),
           0.5)
    # parallel lines 1 m apart, sampled every 1 m: three closest pairs at exactly 1 m, the
    # first of them (ego sample 0, other sample 2) the conflict point
    yield (X.Polyline.of([(-1.0, 0.0), (1.0, 0.0)]), X.Polyline.of([(1.0, 1.0), (-1.0, 1.0)]),
           (4.0, 1.8), (4.0, 1.8), None, 1.0)
    rng = np.random.default_rng(seed)
    for trial in range(n):
        kind = trial % 4
        if kind == 0:
            e = np.cumsum(rng.normal(size=(rng.integers(2, 30), 2)) * 5, axis=0)
            o = np.cumsum(rng.normal(size=(rng.integers(2, 30), 2)) * 5, axis=0) \
                + rng.normal(size=2) * 10
        elif kind == 1:
            e = np.array([[-20.0, 0.0], [20.0, 0.0]]) + rng.integers(-3, 3, 2)
            o = np.array([[0.0, -20.0], [0.0, 20.0]]) + rng.integers(-3, 3, 2)
        elif kind == 2:
            ang = math.radians(rng.uniform(5, 60))
            e = np.array([(-80 * math.cos(ang), -80 * math.sin(ang)), (0.0, 0.0), (60.0, 0.0)])
            o = np.array([(-100.0, 0.0), (0.0, 0.0), (60.0, 0.0)])
        else:
            e = np.cumsum(rng.normal(size=(60, 2)) * 3 + [2.0, 0.0], axis=0)
            o = e[::-1] + rng.normal(size=2) * 2
        ego, other = X.Polyline.of(e), X.Polyline.of(o)
        sizes = tuple(tuple(rng.uniform([3.0, 1.5], [12.0, 2.6]).tolist()) for _ in range(2))
        merge_at = None
        if kind == 2:
            merge_at = (80.0, 100.0)
        elif rng.random() < 0.25:
            merge_at = (float(rng.uniform(0, ego.length_m)), float(rng.uniform(0, other.length_m)))
        yield ego, other, sizes[0], sizes[1], merge_at, (0.1, 0.25, 0.5)[trial % 3]


def _outcome(fn, *args):
    try:
        return fn(*args)
    except ValueError:  # a merge with no sample beside its point: both raise
        return ValueError


@pytest.mark.parametrize("seed", [0, 1])
def test_route_conflict_is_its_k_d_tree_implementation(seed):
    seen = {None: 0, CROSSING: 0, MERGE: 0, ValueError: 0}
    for ego, other, ego_size, other_size, merge_at, step in _random_routes(seed):
        args = (ego, other, ego_size, other_size, 0.5, 0.05, merge_at, step)
        want = _outcome(_route_conflict_kdtree, *args)
        got = _outcome(X.route_conflict, *args)
        assert got == want  # dataclass equality: every float exactly
        seen[want if want in (None, ValueError) else want.kind] += 1
    assert min(seen.values()) > 0, seen  # every outcome was met


def test_the_compiled_route_conflict_is_route_conflict():
    """``pairs._route_conflict_nb`` (the kernel's) against ``route_conflict`` itself."""
    n = 0
    for ego, other, (l_e, w_e), (l_o, w_o), merge_at, step in _random_routes(2, 200):
        want = _outcome(X.route_conflict, ego, other, (l_e, w_e), (l_o, w_o), 0.5, 0.05,
                        merge_at, step)
        res = np.full(6, np.nan)
        a0, b0 = merge_at if merge_at is not None else (0.0, 0.0)
        got = P._route_conflict_nb(ego.xy[:, 0].copy(), ego.xy[:, 1].copy(), ego.arc,
                                   other.xy[:, 0].copy(), other.xy[:, 1].copy(), other.arc,
                                   l_e, w_e, l_o, w_o, 0.5, 0.05, step, merge_at is not None,
                                   a0, b0, res)
        if want is None or want is ValueError:
            assert got == {None: 0, ValueError: 2}[want]
            continue
        n += 1
        assert got == 1
        assert (want.ego_at_m, want.other_at_m, *want.ego_occupancy,
                *want.other_occupancy) == tuple(res.tolist())
    assert n > 100


def test_the_compiled_twins_of_numpy_give_its_bits():
    """interp (repeated abscissae, points before, on and after the ends), linspace and the
    Polyline's cut and samples."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        m = int(rng.integers(2, 40))
        xp = np.cumsum(rng.choice([0.0, 1e-13, 0.3, 2.0], m))
        xp[0] = 0.0
        fp = rng.normal(size=m) * 50
        xs = np.sort(rng.uniform(-1.0, xp[-1] + 1.0, 50))
        xs[::7] = xp[rng.integers(0, m, xs[::7].size)]
        xs.sort()
        want = np.interp(xs, xp, fp)
        j, got = 0, []
        for x in xs:
            value, j = P._interp_nb(x, xp, fp, j)
            got.append(value)
        assert np.array_equal(np.array(got), want)
        # samples of a polyline of those arcs (a Polyline drops repeated vertices)
        line = X.Polyline.of(rng.normal(size=(m, 2)) * 20)
        if line.xy.shape[0] < 2:
            continue
        lo, hi, step = 0.0, float(rng.uniform(-5.0, line.length_m + 5.0)), 0.25
        s, px, py = P._samples_nb(line.xy[:, 0].copy(), line.xy[:, 1].copy(), line.arc, lo,
                                  hi, step)
        ws, wp = line.samples(lo, hi, step)
        assert np.array_equal(s, ws) and np.array_equal(np.stack([px, py], 1), wp)


def _junction_rows(seed: int = 5, vehicles: int = 70) -> dict:
    """INTERACTION rows of a four-arm junction (arms 70 m, lanes 3.5 m, drive on the right):
    each vehicle enters on one arm and goes straight, left or right, at its own speed, some
    stopping before the junction for a few seconds (repeated positions, to the millimetre)."""
    rng = np.random.default_rng(seed)
    dirs = {"E": (1.0, 0.0), "W": (-1.0, 0.0), "N": (0.0, 1.0), "S": (0.0, -1.0)}
    turn = {"straight": lambda d: d, "left": lambda d: (-d[1], d[0]),
            "right": lambda d: (d[1], -d[0])}
    rows = {c: [] for c in INTERACTION_COLUMNS}
    for track in range(1, vehicles + 1):
        d_in = np.array(dirs[rng.choice(list(dirs))])
        d_out = np.array(turn[rng.choice(list(turn))](tuple(d_in)))
        right_in, right_out = np.array([d_in[1], -d_in[0]]), np.array([d_out[1], -d_out[0]])
        a, b = -8.0 * d_in + 1.75 * right_in, 8.0 * d_out + 1.75 * right_out
        # a turn bends about where its entry and exit lanes meet
        corner = a + d_in * np.dot(b - a, d_in) if abs(np.dot(d_in, d_out)) < 0.5 \
            else 0.5 * (a + b)
        u = np.linspace(0.0, 1.0, 12)[:, None]
        bend = (1 - u) ** 2 * a + 2 * u * (1 - u) * corner + u ** 2 * b
        path = X.Polyline.of(np.vstack([-70.0 * d_in + 1.75 * right_in, bend,
                                        70.0 * d_out + 1.75 * right_out]))
        v0 = rng.uniform(5.0, 13.0)
        stop_at = rng.uniform(45.0, 58.0) if rng.random() < 0.4 else math.inf
        wait = rng.uniform(1.0, 4.0)
        s, v, state, out = 0.0, v0, "drive", []
        while s <= path.length_m:
            out.append((s, v))
            if state == "drive":  # towards its stop (if any) braking at 3 m/s^2
                v = min(v0, math.sqrt(6.0 * max(stop_at - s, 0.0)))
                if v < 0.05:
                    v, state = 0.0, "wait"
            elif state == "wait":
                wait -= 0.1
                if wait <= 0.0:
                    state = "go"
            else:
                v = min(v0, v + 0.2)
            s += v * 0.1
        t0 = int(rng.integers(0, 300))
        length, width = rng.uniform(4.0, 5.5), rng.uniform(1.7, 2.1)
        for k, (s_k, v_k) in enumerate(out):
            x, y = path.at(min(s_k, path.length_m))
            ahead = path.at(min(s_k + 0.5, path.length_m)) - path.at(max(s_k - 0.5, 0.0))
            psi = math.atan2(ahead[1], ahead[0])
            for c, value in zip(INTERACTION_COLUMNS, (
                    track, t0 + k + 1, (t0 + k) * 100, "car", x, y, v_k * math.cos(psi),
                    v_k * math.sin(psi), psi, length, width)):
                rows[c].append(value)
    return rows


@pytest.fixture(scope="module")
def junction_tracks(tmp_path_factory):
    path = tmp_path_factory.mktemp("junction") / "vehicle_tracks_000.csv"
    write_interaction(path, _junction_rows())
    return smooth_tracks(read_interaction(path), SmoothingParams())


def _plain_pairs(tracks, params):
    """find_pairs the plain way: ``_project`` of every candidate, sorted, numbered."""
    _, meets = P.meetings(tracks, params)
    found = [q for m in meets if (q := P._project(tracks, params, *m)) is not None]
    found.sort(key=lambda q: (q.recording, float(q.t[0]), q.tracks))
    return [replace(q, pair=k) for k, q in enumerate(found)]


def _same(a, b) -> bool:
    """Equal values of equal types; floats and arrays bit for bit."""
    if isinstance(a, np.ndarray):
        return (isinstance(b, np.ndarray) and a.shape == b.shape and a.dtype == b.dtype
                and np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes())
    if isinstance(a, float):  # a Python float or numpy's (the plain path has both)
        return isinstance(b, float) and np.float64(a).tobytes() == np.float64(b).tobytes()
    if isinstance(a, tuple):
        return type(b) is tuple and len(a) == len(b) and all(map(_same, a, b))
    return type(a) is type(b) and a == b


def _assert_same_pairs(want, got):
    assert len(got) == len(want)
    for p, q in zip(want, got):
        differ = [f.name for f in fields(p) if not _same(getattr(p, f.name), getattr(q, f.name))]
        assert not differ, (p.pair, differ)


@pytest.mark.parametrize("near_m", [40.0, 15.0])
def test_the_compiled_projection_is_project_pair_by_pair(junction_tracks, near_m):
    params = P.PairParams(near_m=near_m)
    want = _plain_pairs(junction_tracks, params)
    got = P.find_pairs(junction_tracks, params)
    _assert_same_pairs(want, got.pairs)
    kinds = {p.kind for p in want}
    assert len(want) > 50 and kinds == {CROSSING, MERGE}, (len(want), kinds)
    # some vehicle stopped: its path repeats positions (Polyline.of drops them)
    assert np.any(np.diff(junction_tracks.s) == 0.0)


def test_a_candidate_the_kernel_leaves_is_projected_plainly(junction_tracks, monkeypatch):
    """Where the kernel answers PLAIN (route_conflict raises for it), _project runs: here it
    is made to answer PLAIN for every candidate, and the pairs are the same."""
    real = P.project_candidates

    def leave_all(*args):
        real(*args)
        out = args[-1]
        out[:, P.P_STATUS] = np.where(out[:, P.P_STATUS] == P.NOT_A_PAIR, P.NOT_A_PAIR,
                                      P.PLAIN)

    monkeypatch.setattr(P, "project_candidates", leave_all)
    params = P.PairParams()
    _assert_same_pairs(_plain_pairs(junction_tracks, params),
                       P.find_pairs(junction_tracks, params).pairs)


def _frame_row_by_row(pairs):
    """``pairs_frame`` as it was built before (strings and labels repeated per row)."""
    n = np.array([p.n_steps for p in pairs], np.int64)

    def rep(values, dtype=None):
        return np.repeat(np.asarray(values, dtype=dtype), n)

    def cat(get):
        return np.concatenate([get(p) for p in pairs]) if pairs else np.zeros(0)

    cols = {"pair": rep([p.pair for p in pairs], np.int64),
            "recording": rep([p.recording for p in pairs], object),
            "kind": rep([p.kind for p in pairs], object),
            "angle_deg": rep([p.angle_deg for p in pairs], float),
            "track_1": rep([p.tracks[0] for p in pairs], np.int64),
            "track_2": rep([p.tracks[1] for p in pairs], np.int64),
            "class_1": rep([p.classes[0] for p in pairs], object),
            "class_2": rep([p.classes[1] for p in pairs], object),
            "length_1_m": rep([p.lengths_m[0] for p in pairs], float),
            "width_1_m": rep([p.widths_m[0] for p in pairs], float),
            "length_2_m": rep([p.lengths_m[1] for p in pairs], float),
            "width_2_m": rep([p.widths_m[1] for p in pairs], float),
            "occupancy_1_lo_m": rep([p.occupancy[0][0] for p in pairs], float),
            "occupancy_1_hi_m": rep([p.occupancy[0][1] for p in pairs], float),
            "occupancy_2_lo_m": rep([p.occupancy[1][0] for p in pairs], float),
            "occupancy_2_hi_m": rep([p.occupancy[1][1] for p in pairs], float),
            "conflict_x_m": rep([p.conflict_xy[0] for p in pairs], float),
            "conflict_y_m": rep([p.conflict_xy[1] for p in pairs], float),
            "first": rep([p.first for p in pairs], object),
            "pet_s": rep([p.pet_s for p in pairs], float),
            "pet_area_s": rep([p.pet_area_s for p in pairs], float),
            "t_pass_1_s": rep([p.t_pass_s[0] for p in pairs], float),
            "t_pass_2_s": rep([p.t_pass_s[1] for p in pairs], float),
            "second_slowed": pd.array(np.repeat(np.array([p.second_slowed for p in pairs],
                                                         dtype=object), n), dtype="boolean"),
            "second_speed_drop_mps": rep([p.second_speed_drop_mps for p in pairs], float),
            **{f"track_{what}_{k + 1}": rep([getattr(p, f"track_{what}")[k] for p in pairs],
                                            np.int64)
               for k in (0, 1) for what in ("k0", "n")},
            "control": rep([p.control for p in pairs], object),
            "priority": rep([p.priority for p in pairs], np.int64),
            "stop_1_m": rep([p.stop_s[0] for p in pairs], float),
            "stop_2_m": rep([p.stop_s[1] for p in pairs], float),
            "step": cat(lambda p: np.arange(p.n_steps)).astype(np.int64),
            "t_s": cat(lambda p: p.t)}
    for k in (0, 1):
        for name, get in (("s_{}_m", "s"), ("v_{}_mps", "v"), ("a_{}_mps2", "a"),
                          ("x_{}_m", "x"), ("y_{}_m", "y"), ("heading_{}_rad", "heading")):
            cols[name.format(k + 1)] = cat(lambda p, get=get: getattr(p, get)[k])
    return pd.DataFrame(cols, columns=[*P.PAIR_COLUMNS, *P.TRACK_COLUMNS, *P.MAP_COLUMNS,
                                       *P.STEP_COLUMNS])


def test_the_pairs_frame_and_table_are_the_row_by_row_ones(junction_tracks):
    import pyarrow as pa

    pairs = P.find_pairs(junction_tracks).pairs
    pairs[3] = replace(pairs[3], control="right_of_way", priority=2)  # a mixed column
    pairs[4] = replace(pairs[4], second_slowed=None, pet_s=math.nan)  # a null flag, a NaN
    for some in (pairs, pairs[:1], []):
        want, got = _frame_row_by_row(some), P.pairs_frame(some)
        assert list(got.dtypes) == list(want.dtypes) and got.equals(want)
        # and the table a part or the pairs file is made of, schema and metadata included,
        # also as pairs_table builds it without the frame (a NaN is a null in both)
        table = pa.Table.from_pandas(want, preserve_index=False)
        assert pa.Table.from_pandas(got, preserve_index=False).equals(table, check_metadata=True)
        fast = P.pairs_table(some)
        assert fast.equals(table, check_metadata=True)
        assert [c.num_chunks for c in fast.columns] == [c.num_chunks for c in table.columns]


def test_the_approach_points_of_many_vehicles_at_once_are_each_ones():
    rng = np.random.default_rng(4)
    for _ in range(300):
        n = rng.integers(1, 60, int(rng.integers(1, 8)))
        s = np.concatenate([np.sort(rng.uniform(-90.0, 30.0, k)) if rng.random() < 0.7
                            else rng.uniform(-90.0, 30.0, k) for k in n])
        if rng.random() < 0.2:
            s[rng.integers(0, s.size)] = np.nan
        occ = rng.uniform(-40.0, 10.0, n.size)
        occ[rng.random(n.size) < 0.1] = np.nan
        idx, take = approach_indices(s, n, occ)
        assert take.max(initial=0) <= APPROACH_POINTS
        end = np.cumsum(n)
        got = np.split(idx, np.cumsum(take)[:-1])
        for k in range(n.size):
            rows = np.arange(end[k] - n[k], end[k])
            want, _ = approach_points(s[rows], rows, rows, occ[k])
            assert np.array_equal(got[k], want)


# -- a small SUMO site: a real junction's paths, and its map's rule ------------------------


@pytest.fixture(scope="module")
def tiny_site(tmp_path_factory):
    pytest.importorskip("libsumo")
    pytest.importorskip("lanelet2")
    from persuasive.recordings.site import SiteParams, make_site

    out = tmp_path_factory.mktemp("tiny") / "site"
    make_site(out, SiteParams(hours=0.05, files=2))
    return out


@pytest.mark.slow
def test_on_a_sumo_site_the_pairs_and_their_rules_are_the_plain_ones(tiny_site):
    from persuasive.recordings.lanelet_map import annotate_pairs, pair_rule, read_map

    road = read_map(tiny_site / "site.osm")
    # the same map with its right-of-way elements read as all-way stops (a stop line each),
    # so that the stop lines' branch runs too
    stops = {}
    for ll, rules in road.right_of_way.items():
        for e, _ in rules:
            line = np.array([[-3.0, -3.0], [3.0, 3.0]]) + 0.1 * (ll % 7)
            stops.setdefault(ll, []).append((e, line))
    as_stops = replace(road, right_of_way={}, all_way_stop=stops)
    n_pairs = 0
    for f in find_track_files([tiny_site]):
        tracks = smooth_tracks(read_interaction(f.path), SmoothingParams())
        want = _plain_pairs(tracks, P.PairParams())
        _assert_same_pairs(want, P.find_pairs(tracks).pairs)
        n_pairs += len(want)
        for rm in (road, as_stops):
            plain = [replace(p, control=c, priority=k, stop_s=st) for p in want
                     for c, k, st in [pair_rule(rm, p.s, p.x, p.y,
                                                np.asarray(p.occupancy, float))]]
            _assert_same_pairs(plain, annotate_pairs(want, rm))
    assert n_pairs > 100


# -- the pairs file written while the files are paired --------------------------------------


@pytest.fixture(scope="module")
def junction_folder(tmp_path_factory):
    """Three recordings of the junction, the middle one of two vehicles that never meet (no
    pair, no part)."""
    folder = tmp_path_factory.mktemp("junctions")
    for k, (seed, vehicles) in enumerate([(5, 70), (6, 2), (7, 50)]):
        write_interaction(folder / f"vehicle_tracks_{k:03d}.csv", _junction_rows(seed, vehicles))
    return folder


def test_the_streamed_pairs_file_is_the_one_written_after(junction_folder, tmp_path,
                                                          monkeypatch):
    """The file the stream writes (its footer's metadata given at the end) has the bytes of
    the one ``_write`` makes from the parts afterwards; files whose recording names are not in
    their order are written afterwards, and hold the same pairs."""
    import pyarrow.parquet as pq

    from persuasive.recordings import streaming as ST

    files = sorted(junction_folder.glob("*.csv"))
    params, smoothing = P.PairParams(), SmoothingParams()
    finished = []
    finish = ST._Stream.finish
    monkeypatch.setattr(ST._Stream, "finish",
                        lambda self, *a: finished.append(finish(self, *a)) or finished[-1])
    streamed = tmp_path / "streamed.parquet"
    site = ST.site_pairs(files, params, smoothing, out=streamed)
    assert [f.part is None for f in site.files] == [False, True, False]
    assert finished == [True]  # pyarrow orders the footer as expected: the stream wrote it
    monkeypatch.setattr(ST._Stream, "finish", lambda self, *a: False)
    after = tmp_path / "after.parquet"
    ST.site_pairs(files, params, smoothing, out=after)
    assert streamed.read_bytes() == after.read_bytes()
    # given in another order than their recordings' names: written afterwards, the same rows
    monkeypatch.setattr(ST._Stream, "finish",
                        lambda self, *a: finished.append(finish(self, *a)) or finished[-1])
    shuffled = tmp_path / "shuffled.parquet"
    ST.site_pairs([files[2], files[0], files[1]], params, smoothing, out=shuffled)
    assert finished == [True, False]
    assert pq.read_table(shuffled).equals(pq.read_table(streamed))
    frame, meta = P.read_pairs(shuffled)
    frame_0, meta_0 = P.read_pairs(streamed)
    assert meta.pop("sources") == [str(f) for f in (files[2], files[0], files[1])]
    assert meta_0.pop("sources") == [str(f) for f in files] and meta == meta_0
    assert frame["pair"].is_monotonic_increasing and frame["pair"].iloc[-1] > 50
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".parts")]


def test_a_stream_that_fails_leaves_the_file_to_be_written_after(junction_folder, tmp_path,
                                                                 monkeypatch):
    from persuasive.recordings import streaming as ST

    files = sorted(junction_folder.glob("*.csv"))
    params, smoothing = P.PairParams(), SmoothingParams()
    want = tmp_path / "want.parquet"
    ST.site_pairs(files, params, smoothing, out=want)
    calls = []
    real = ST._write_part

    def fail_once(*args):
        calls.append(args[1])
        if len(calls) == 1:
            raise OSError("no space left on device")
        return real(*args)

    monkeypatch.setattr(ST, "_write_part", fail_once)
    got = tmp_path / "got.parquet"
    ST.site_pairs(files, params, smoothing, out=got)
    assert got.read_bytes() == want.read_bytes()
    assert len(calls) == 3  # the stream's first part failed; _write wrote both parts


@pytest.mark.slow
def test_the_lanelets_of_points_are_lanelet2s_or_left_to_it(tiny_site):
    """Points anywhere in the view, and on, just beside and just off every edge of every
    lanelet: each one either left to lanelet2 (None) or given exactly lanelet2's lanelets;
    only points within BOUNDARY_M of an edge are left to it."""
    from persuasive.recordings.lanelet_map import (BOUNDARY_M, _lanelets_at_point,
                                                   lanelets_of_points, read_map)

    road = read_map(tiny_site / "site.osm")
    assert road.shapes and all(simple for _, _, simple in road.shapes)
    rng = np.random.default_rng(6)
    points = [rng.uniform(-65.0, 65.0, (20000, 2))]
    for _, poly, _ in road.shapes:
        a, b = poly, np.roll(poly, -1, axis=0)
        for t in (0.0, 0.3, 0.5):
            on = a + t * (b - a)
            points += [on, on + 0.5 * BOUNDARY_M, on + 10 * BOUNDARY_M,
                       on + rng.normal(size=on.shape) * 1e-4]
    points = np.vstack(points)
    got = lanelets_of_points(road, points)
    left = 0
    for q, ids in zip(points.tolist(), got):
        if ids is None:
            left += 1
        else:
            assert ids == set(_lanelets_at_point(road, tuple(q))), q
    assert 0 < left < 0.05 * len(got)


def test_a_polygon_that_is_not_simple_is_left_to_lanelet2():
    from types import SimpleNamespace

    from persuasive.recordings.lanelet_map import RoadMap, _simple, lanelets_of_points

    square = np.array([[0.0, 0.0], [0.0, 2.0], [2.0, 2.0], [2.0, 0.0]])
    bow_tie = np.array([[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]])
    pinched = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 2.0], [2.0, 2.0], [1.0, 1.0], [2.0, 0.0]])
    assert _simple(square) and not _simple(bow_tie) and not _simple(pinched)
    assert not _simple(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]))
    road = RoadMap("m.osm", (0.0, 0.0), SimpleNamespace(laneletLayer=[]), shapes=(
        (1, square, True), (2, bow_tie + [5.0, 0.0], False)))
    got = lanelets_of_points(road, [(1.0, 1.0), (3.0, 3.0), (1.0, 0.0), (6.0, 0.5), (6.0, 3.0)])
    assert got == [{1}, set(), None, None, set()]  # inside, outside, on an edge, in the bow tie
