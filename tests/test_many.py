"""The world of N vehicles at the four-way junction (``persuasive.many``): its geometry as
data, the conflict table, the humans who play each other, the closed loop, the measures of
liveness and safety, the study and the command.

Tolerances: geometry to 1e-9 m (exact constructions); positions after a step to 1e-12 m."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive.config import Config, ConfigError
from persuasive.envs.external import CROSSING, FOLLOW, MERGE
from persuasive.many import measures as M
from persuasive.many.junction import (EXIT_OFFSET, MOVEMENTS, VARIANTS, JunctionSpec, arrivals,
                                      geometry_of, right_of_way, route)
from persuasive.many.study import aggregate, run_seed, run_study
from persuasive.many.world import ACTIVE, CRASHED, DONE, JunctionWorld, conflict_table

from _cli import run_cli

CONFIG = Config(mode="corrected")


# -- the junction as data -----------------------------------------------------------------


@pytest.mark.parametrize("lanes", [1, 2])
@pytest.mark.parametrize("arm", range(4))
@pytest.mark.parametrize("movement", MOVEMENTS)
def test_routes_start_on_their_arm_and_leave_by_the_right_one(lanes, arm, movement):
    spec = JunctionSpec(n_vehicles=1, lanes=lanes, approach_m=50.0, exit_m=30.0)
    lane = 0 if movement == "left" else lanes - 1
    r = route(geometry_of(spec), arm, movement, lane)
    start, end = r.line.xy[0], r.line.xy[-1]
    u_in = np.array([math.cos(arm * math.pi / 2), math.sin(arm * math.pi / 2)])
    out = (arm + EXIT_OFFSET[movement]) % 4
    u_out = np.array([math.cos(out * math.pi / 2), math.sin(out * math.pi / 2)])
    half = spec.half_m
    # it starts approach_m + half out on its arm and ends exit_m + half out on the exit arm
    assert start @ u_in == pytest.approx(half + 50.0, abs=1e-9)
    assert end @ u_out == pytest.approx(half + 30.0, abs=1e-9)
    # right-hand traffic: the lane's centre is (lane + 1/2) widths right of the heading
    heading = -u_in
    right = np.array([heading[1], -heading[0]])
    assert start @ right == pytest.approx((lane + 0.5) * spec.lane_width_m, abs=1e-9)
    assert r.entry_m == pytest.approx(50.0, abs=1e-9)
    assert r.length_m - r.exit_m == pytest.approx(30.0, abs=1e-9)
    # a left turn is the longest way through the box, a right turn the shortest
    through = r.exit_m - r.entry_m
    if movement == "straight":
        assert through == pytest.approx(2 * half, abs=1e-9)
    elif movement == "left":
        assert through > 2 * half * math.pi / 4
    else:
        assert through < 2 * half


@pytest.mark.parametrize("fields, name", [
    ({"lanes": 3}, "lanes"), ({"n_vehicles": 0}, "n_vehicles"), ({"priority": "x"}, "priority"),
    ({"mix": (0, 0, 0)}, "mix"), ({"av_arm": 4}, "av_arm"), ({"av_movement": "u"}, "av_movement"),
    ({"lane_width_m": 1.0}, "lane_width_m"), ({"approach_m": 10.0}, "approach_m"),
    ({"gap_m": (5.0, 1.0)}, "gap_m"), ({"hv_kinds": "lfg:0.5,human"}, "hv_kinds"),
    ({"n_vehicles": 30, "approach_m": 100.0}, "n_vehicles"), ({"duration_s": 0.0}, "duration_s"),
])
def test_bad_geometry_is_refused_in_one_line_naming_the_field(fields, name):
    with pytest.raises(ConfigError) as err:
        JunctionSpec(**fields)
    message = str(err.value)
    assert f"junction.{name}" in message and "\n" not in message and "allowed" in message


def test_the_approach_grows_with_the_number_of_vehicles():
    small, large = JunctionSpec(n_vehicles=3), JunctionSpec(n_vehicles=20)
    assert small.approach_m == 100.0 and large.approach_m > 100.0
    assert large.max_vehicles() >= 20
    arrivals(large, 7)  # every one of them fits whatever the seed draws


def test_variants_set_priority_and_mix():
    assert JunctionSpec.of("left-heavy").mix[0] == 0.6
    assert JunctionSpec.of("all-way").priority == "first-come"
    with pytest.raises(ConfigError, match="allowed: major"):
        JunctionSpec.of("roundabout")
    with pytest.raises(ConfigError, match="junction.wheels is not a parameter"):
        JunctionSpec.of(None, wheels=4)


def test_right_of_way_by_rule():
    geo = geometry_of(JunctionSpec())
    east_s, north_s = route(geo, 0, "straight", 0), route(geo, 1, "straight", 0)
    west_l, east_l = route(geo, 2, "left", 0), route(geo, 0, "left", 0)
    x = (0.0, 5.0)
    major = JunctionSpec(priority="major")
    assert right_of_way(major, east_s, north_s, x, x) == 1  # the east-west road is major
    assert right_of_way(major, north_s, east_s, x, x) == -1
    assert right_of_way(major, west_l, east_s, x, x) == -1  # a left turn yields on its road
    assert right_of_way(major, west_l, east_l, x, x) == 0
    rbl = JunctionSpec(priority="right-before-left")
    # heading west from the east arm, the north arm is on the right
    assert right_of_way(rbl, east_s, north_s, x, x) == -1
    assert right_of_way(rbl, north_s, east_s, x, x) == 1
    first = JunctionSpec(priority="first-come")
    near, far = (east_s.entry_m - 5.0, 5.0), (north_s.entry_m - 20.0, 5.0)
    assert right_of_way(first, east_s, north_s, near, far) == 1
    assert right_of_way(first, east_s, north_s, far, near) == -1


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 2), n=st.integers(1, 12), lanes=st.integers(1, 2),
       variant=st.sampled_from(list(VARIANTS)))
def test_arrivals_place_every_vehicle_in_its_lane_apart_from_the_next(seed, n, lanes, variant):
    spec = JunctionSpec.of(variant, n_vehicles=n, lanes=lanes)
    a = arrivals(spec, seed)
    b = arrivals(spec, seed)
    assert np.array_equal(a.s0_m, b.s0_m) and a.routes == b.routes  # the seed decides
    assert a.routes[0].arm == spec.av_arm and a.routes[0].movement == spec.av_movement
    for i in range(n):
        r = a.routes[i]
        assert r.entry_m - a.s0_m[i] >= spec.first_m[0] - 1e-9
        assert spec.v0_mps[0] <= a.v0_mps[i] <= spec.v0_mps[1]
        for j in range(i + 1, n):
            if a.routes[j].inbound == r.inbound:  # one lane: at least a length and a gap apart
                assert abs(a.s0_m[i] - a.s0_m[j]) >= 5.0 + spec.gap_m[0] - 1e-9


def test_the_humans_draws_do_not_depend_on_the_avs_movement():
    base = arrivals(JunctionSpec(n_vehicles=6), 11)
    other = arrivals(JunctionSpec(n_vehicles=6, av_movement="left"), 11)
    assert [(r.arm, r.movement) for r in base.routes[1:]] == \
        [(r.arm, r.movement) for r in other.routes[1:]]


# -- the conflict table -------------------------------------------------------------------


def test_the_table_has_a_row_for_every_pair_that_can_touch_and_none_for_the_others():
    spec = JunctionSpec(n_vehicles=2)
    geo = geometry_of(spec)
    lim = JunctionWorld(CONFIG, spec, 1).limits

    def kind(a, b):
        from persuasive.many.junction import Arrivals
        arr = Arrivals((a, b), np.array([0.0, 0.0]), np.array([4.0, 4.0]), ("av", "lfg"),
                       np.zeros(2))
        rows = conflict_table(spec, arr, lim, 7.5).rows
        return rows[0].kind if rows else None

    south, north = route(geo, 3, "straight", 0), route(geo, 1, "straight", 0)
    east = route(geo, 0, "straight", 0)
    assert kind(south, north) is None  # opposite straight lanes, 4 m apart: never touch
    assert kind(south, east) == CROSSING
    assert kind(south, route(geo, 3, "left", 0)) == FOLLOW  # one inbound lane
    # west's right turn and east's left turn leave by the south arm's one exit lane
    assert kind(route(geo, 2, "right", 0), route(geo, 0, "left", 0)) == MERGE


def test_crossing_rows_see_each_side_from_its_own_route():
    w = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=8), 3)
    crossings = [r for r in w.table.rows if r.kind == CROSSING]
    assert crossings
    for r in crossings:
        assert r.ij.ego_at_m == r.ji.other_at_m and r.ij.other_at_m == r.ji.ego_at_m
        assert r.ij.ego_occupancy == r.ji.other_occupancy
        # the yield line is the stop line, never after the occupancy starts
        assert r.ij.ego_line_m <= r.ij.ego_occupancy[0]
        pi = w.routes[r.i].line.at(np.array([r.ij.ego_at_m]))[0]
        pj = w.routes[r.j].line.at(np.array([r.ij.other_at_m]))[0]
        assert np.hypot(*(pi - pj)) < 3.2  # the closest approach of two crossing lines


# -- the closed loop ----------------------------------------------------------------------


def test_a_run_is_bit_identical_from_its_seed():
    spec = JunctionSpec(n_vehicles=6, hv_kinds="lfg:0.5,noisy:0.5")
    a, b = (JunctionWorld(CONFIG, spec, 5).run() for _ in range(2))
    assert np.array_equal(a.S, b.S, equal_nan=True) and a.verdicts == b.verdicts


def test_free_road_humans_drive_the_idm_and_the_step_is_the_saturated_one():
    # one human alone, no AV in the way: the free-road IDM, integrated exactly
    w = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=2), 1, with_av=False)
    s0, v0 = float(w.s[1]), float(w.v[1])
    w.step()
    p = CONFIG.hv.idm
    a = p.max_accel_mps2 * (1 - (v0 / p.desired_speed_mps) ** p.delta)
    assert w.a[1] == pytest.approx(a, abs=1e-12)
    assert w.s[1] == pytest.approx(s0 + v0 * 0.1 + 0.5 * a * 0.01, abs=1e-12)
    assert w.status[0] == DONE  # the AV never entered


def test_humans_play_their_pair_game_against_the_next_conflict():
    # some seed where a human meets a crossing: its pair decision is recorded
    for seed in range(1, 30):
        w = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=4), seed).run()
        opp = w.opponents[: w.k]
        if (opp >= 0).any():
            k, i = map(int, np.argwhere(opp >= 0)[0])
            j = int(opp[k, i])
            assert any({r.i, r.j} == {i, j} and r.kind in (CROSSING, MERGE)
                       for r in w.table.rows)
            return
    pytest.fail("no human met a crossing in 30 seeds")


def test_lfg_humans_keep_one_pair_per_opponent_and_forget_it_once_clear():
    w = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=5), 2)
    seen = 0
    while not w.step().done:
        for h in w.humans[1:]:
            assert len(h._pairs) <= w.n - 1
            seen = max(seen, len(h._pairs))
    assert seen >= 1
    assert all(len(h._pairs) == 0 or w.status[i] == ACTIVE
               for i, h in enumerate(w.humans) if h is not None)


def test_the_shield_keeps_the_av_out_of_collisions_over_many_seeds():
    spec = JunctionSpec(n_vehicles=6)
    for seed in range(1, 16):
        w = JunctionWorld(CONFIG, spec, seed).run()
        assert not any(c for _, i, _, c in w.collisions if i == 0)
        assert "uncertified" not in w.verdicts
        assert w.min_gap_av_m > 0.0


def test_without_the_shield_an_aggressive_crowd_can_hit_the_av():
    """The collision check has teeth: with the shield off and a cv AV, some seed collides."""
    config = CONFIG.with_overrides({"av.shield": "off", "av.kind": "cv"})
    spec = JunctionSpec(n_vehicles=6, hv_kinds="aggressive")
    hits = [w for w in (JunctionWorld(config, spec, s).run() for s in range(1, 15))
            if w.collisions]
    assert hits
    w = hits[0]
    t, i, j, _ = w.collisions[0]
    assert w.status[j] == CRASHED or i == 0


def test_agents_replace_a_vehicles_policy_and_pass_through_the_shield():
    unshielded = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=4), 3)
    shielded = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=4), 3)
    unshielded.step({0: 1.0}, shield=False)
    assert unshielded.a[0] == 1.0
    info = shielded.step({0: 1.0})
    assert info.verdict in ("admitted", "brake", "go")  # the shield judged the agent's action
    assert unshielded.verdicts == [None] and shielded.verdicts == [info.verdict]
    w = unshielded
    with pytest.raises(ConfigError, match="action of vehicle 0"):
        w.step({0: float("nan")})


# -- measures -----------------------------------------------------------------------------


def test_free_flow_time_by_hand():
    # 0 -> 10 m/s at 1 m/s^2 takes 50 m and 10 s; 50 m more at 10 m/s: 5 s
    assert M.free_flow_s(0.0, 0.0, 100.0, 1.0, 10.0) == pytest.approx(15.0)
    assert M.free_flow_s(0.0, 0.0, 8.0, 1.0, 10.0) == pytest.approx(4.0)
    assert M.free_flow_s(5.0, 3.0, 5.0, 1.0, 10.0) == 0.0


def test_a_standoff_is_a_deadlock_and_a_queue_is_not():
    from persuasive.many.junction import Arrivals

    spec = JunctionSpec(n_vehicles=3)
    geo = geometry_of(spec)
    south, east = route(geo, 3, "straight", 0), route(geo, 0, "straight", 0)
    w = JunctionWorld(CONFIG, spec, 1)
    # rebuild the run by hand: AV from the south, one human from the east, one behind it
    arr = Arrivals((south, east, east), np.array([south.entry_m - 2.0, east.entry_m - 2.0,
                                                  east.entry_m - 12.0]),
                   np.zeros(3), ("av", "lfg", "lfg"), np.zeros(3))
    w.arrivals, w.routes = arr, arr.routes
    w.table = conflict_table(spec, arr, w.limits, w.keep_out_m)
    steps = int(round(6.0 / w.dt))
    w.k = steps
    w.S[: steps + 1] = arr.s0_m
    w.V[: steps + 1] = 0.0
    w.STATUS[: steps + 1] = ACTIVE
    edges = set(M.wait_edges(w, 0))
    assert {(0, 1), (1, 0), (2, 1)} <= edges  # a standoff, and a queue behind it
    lock = M.deadlock(w)
    assert lock is not None and {0, 1} <= set(lock[1]) and lock[0] == 0.0
    assert np.allclose(M.waiting_s(w), 6.0 + w.dt)
    # humans that go break the cycles: no deadlock
    w.V[:, 1:] = 5.0
    assert M.deadlock(w) is None


def test_pet_is_the_time_between_the_centres_passing():
    for seed in range(1, 60):
        w = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=3), seed).run()
        pets = M.pets(w)
        if pets:
            break
    else:
        pytest.fail("no crossing passed by both in 60 seeds")
    i, j, p = pets[0]
    r = next(r for r in w.table.rows if (r.i, r.j) == (i, j))

    def passed(v, at):
        s = w.S[: w.k + 1, v]
        ok = np.isfinite(s)
        return float(np.interp(at, s[ok], np.arange(w.k + 1)[ok] * w.dt))

    assert p == pytest.approx(abs(passed(i, r.ij.ego_at_m) - passed(j, r.ji.ego_at_m)),
                              abs=1e-9)


def test_the_delay_caused_compares_the_same_seed_without_the_av():
    row, ms = run_seed(CONFIG, JunctionSpec(n_vehicles=5), 4)
    assert ms.size == row["steps"] and row["step_ms_median"] > 0
    w = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=5), 4).run()
    ref = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=5), 4, with_av=False).run()
    a, b = M.clear_times(w)[1:], M.clear_times(ref)[1:]
    d = np.where(np.isfinite(a), a, 30.0) - np.where(np.isfinite(b), b, 30.0)
    assert row["caused_delay_s"] == pytest.approx(float(d.mean()), abs=1e-12)
    passed = [(ti, tj) for i, _, ti, tj in M.passings(w) if i == 0]
    assert row["av_conflicts_passed"] == len(passed)
    assert row["av_first_conflicts"] == sum(ti < tj for ti, tj in passed)


def test_a_study_is_the_same_with_one_or_two_workers():
    spec = JunctionSpec(n_vehicles=4, duration_s=10.0)
    one, _ = run_study(CONFIG, spec, range(1, 5), workers=1)
    two, _ = run_study(CONFIG, spec, range(1, 5), workers=2)
    drop = ("step_ms_median", "step_ms_max")
    strip = [[{k: v for k, v in r.items() if k not in drop} for r in rows] for rows in (one, two)]
    assert json.dumps(strip[0], default=str) == json.dumps(strip[1], default=str)
    agg = aggregate(one, np.ones(3))
    assert agg["runs"] == 4 and agg["step_ms_median"] == 1.0


# -- the command --------------------------------------------------------------------------


def test_the_command_runs_writes_and_refuses(capsys, tmp_path):
    out = tmp_path / "j"
    code, text, err = run_cli(capsys, "junction", "--vehicles", 3, "--seeds", 3, "--workers",
                              1, "--duration", 10, "--out", out, "--plot", tmp_path / "j.png",
                              "--quiet")
    assert code == 0, err
    assert "| 3 | 3 |" in text
    assert sorted(p.name for p in out.iterdir()) == ["runs.parquet", "summary.json",
                                                      "summary.md"]
    assert (tmp_path / "j.png").stat().st_size > 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs"] == 3 and summary["n_vehicles"] == 3
    (out / "notes.txt").write_text("mine")
    code, _, err = run_cli(capsys, "junction", "--vehicles", 3, "--seeds", 2, "--duration", 5,
                           "--out", out, "--quiet", "--workers", 1)
    assert code == 2 and "holds other files" in err
    code, _, err = run_cli(capsys, "junction", "--vehicles", 3, "--seeds", 2, "--duration", 5,
                           "--out", out, "--quiet", "--workers", 1, "--force")
    assert code == 0 and (out / "notes.txt").read_text() == "mine"
    assert json.loads((out / "summary.json").read_text())["runs"] == 2
    code, _, err = run_cli(capsys, "junction", "--vehicles", 65)
    assert code == 2 and err.startswith("error: --vehicles = 65 is out of range")
    assert len(err.strip().splitlines()) == 1
    code, _, err = run_cli(capsys, "junction", "--hv", "lfg,bus")
    assert code == 2 and "junction.hv_kinds" in err
    code, _, err = run_cli(capsys, "junction", "--video", tmp_path / "v.avi")
    assert code == 2 and "unsupported extension" in err


def test_the_video_has_one_frame_per_state(capsys, tmp_path):
    import imageio.v3 as iio

    code, _, err = run_cli(capsys, "junction", "--vehicles", 3, "--seeds", 1, "--workers", 1,
                           "--duration", 2, "--video", tmp_path / "v.gif", "--quiet")
    assert code == 0, err
    frames = iio.imread(tmp_path / "v.gif", index=None)
    w = JunctionWorld(CONFIG, JunctionSpec(n_vehicles=3, duration_s=2.0), 1).run()
    assert frames.shape[0] == w.k + 1 and frames.shape[-1] in (3, 4)


# -- Poisson arrivals -----------------------------------------------------------------------


def test_poisson_arrivals_enter_in_time_at_the_start_of_the_approach():
    spec = JunctionSpec(n_vehicles=8, arrival="poisson", flow_veh_h=900.0, duration_s=60.0,
                        av_arrival_s=5.0)
    a = arrivals(spec, 4)
    assert np.all(np.diff(a.t0_s[1:]) >= 0.0) and a.t0_s[1] > 0.0
    assert a.t0_s[0] == 5.0 and np.all(a.s0_m == 0.0)
    # the placed draws come first: the humans' routes are those of the placed arrivals
    placed = arrivals(JunctionSpec(n_vehicles=8), 4)
    assert a.routes == placed.routes
    w = JunctionWorld(CONFIG, spec, 4)
    from persuasive.many.world import PENDING
    assert (w.status == PENDING).all()
    while not w.step().done:
        t = w.k * w.dt
        on = w.STATUS[w.k] != PENDING
        assert np.all(w.t0[on] <= t + 1e-9)  # nobody before its arrival time
    # a vehicle that entered did so at its arrival time or later, at the start of its lane
    for i in range(w.n):
        k = np.flatnonzero(np.isfinite(w.S[:, i]))
        if k.size:
            assert k[0] * w.dt >= w.t0[i] - 1e-9


def test_an_entry_waits_while_its_lane_is_blocked():
    spec = JunctionSpec(n_vehicles=3, arrival="poisson", duration_s=20.0)
    w = JunctionWorld(CONFIG, spec, 2)
    from persuasive.many.junction import Arrivals
    from persuasive.many.world import PENDING
    r = w.routes[1]
    arr = Arrivals((w.routes[0], r, r), np.zeros(3), np.array([4.0, 0.0, 4.0]),
                   ("av", "idm", "idm"), np.array([19.0, 0.1, 0.2]))
    w.arrivals, w.routes, w.t0 = arr, arr.routes, arr.t0_s
    w.s, w.v = arr.s0_m.copy(), arr.v0_mps.copy()
    w.table = conflict_table(spec, arr, w.limits, w.keep_out_m)
    w._prepare_views()
    w._lines()
    w.status[:] = PENDING
    for _ in range(5):
        w.step()
    # the first entered at 0.1 s standing; the second stays off the road behind it
    assert w.status[1] == ACTIVE and w.status[2] == PENDING
    assert w.s[1] - w.s[2] < 5.0 + spec.gap_m[0]


def test_stand_ins_cover_the_newcomers():
    """With humans still to arrive the AV's shield sees one stand-in per route a newcomer may
    take; over a dense flow no step is left uncertified."""
    spec = JunctionSpec(n_vehicles=10, arrival="poisson", flow_veh_h=1200.0, duration_s=40.0,
                        av_arrival_s=3.0)
    for seed in range(1, 9):
        w = JunctionWorld(CONFIG, spec, seed)
        saw = False
        while not w.step().done:
            if w.status[0] == ACTIVE and (w.status == 3).any():
                c = w.conflicts_of(0)
                saw |= any(x.extra.get("stand_in") for x in c)
        assert saw and "uncertified" not in w.verdicts
        assert not any(c for _, i, _, c in w.collisions if i == 0)


# -- the guarantee over configurations --------------------------------------------------------


@given(seed=st.integers(0, 10_000), n=st.integers(2, 8), lanes=st.integers(1, 2),
       variant=st.sampled_from(list(VARIANTS)), arm=st.integers(0, 3),
       movement=st.sampled_from(MOVEMENTS), poisson=st.booleans(),
       kinds=st.sampled_from(["lfg", "idm", "aggressive", "adversary",
                              "lfg:0.6,aggressive:0.2,adversary:0.2", "random,noisy"]))
def test_the_shield_holds_over_junction_configurations(seed, n, lanes, variant, arm, movement,
                                                        poisson, kinds):
    """Whatever the junction, the crowd and its arrivals: no collision the AV causes and no
    uncertified step (the humans stay inside the envelope the shield assumes)."""
    spec = JunctionSpec.of(variant, n_vehicles=n, lanes=lanes, av_arm=arm,
                           av_movement=movement, hv_kinds=kinds, duration_s=15.0,
                           arrival="poisson" if poisson else "placed", flow_veh_h=1200.0,
                           av_arrival_s=2.0)
    w = JunctionWorld(CONFIG, spec, seed).run()
    assert not any(c for _, i, _, c in w.collisions if i == 0)
    assert "uncertified" not in w.verdicts
