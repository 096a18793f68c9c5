"""The four-way junction in Eclipse SUMO (issue 41 item 3, ``persuasive.many.sumo``): the
network has the spec's lanes, box and connections; every route is projected through the box;
every vehicle starts at our distance to the stop line; one short episode per driver gives sane
numbers, the same twice and whatever the workers; the paired table's arithmetic; bad input is
one line; the benchmark runs as a user would.

Tolerances: lengths read back from SUMO's network file to 0.01 m (it writes two decimals);
a vehicle's start to 1e-3 m and 1e-3 m/s (the route file writes three decimals); results of
one seed compared exactly.
"""

from __future__ import annotations

import importlib.util
import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from persuasive.config import ConfigError, JunctionSpec

pytest.importorskip("sumo")
pytest.importorskip("libsumo")

from persuasive.envs import sumo as S  # noqa: E402
from persuasive.many import sumo as M  # noqa: E402
from persuasive.many.junction import arrivals  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PLANNER = "persuasive/worst-case"


@pytest.fixture(scope="module")
def nets(tmp_path_factory):
    """``{(variant, lanes, n): (spec, net file)}`` built once for the module."""
    out = {}
    for variant, lanes, n in (("major", 1, 3), ("major", 2, 6), ("right-before-left", 1, 4),
                              ("all-way", 1, 4)):
        spec = JunctionSpec.of(variant, n_vehicles=n, lanes=lanes)
        out[(variant, lanes, n)] = (spec, M.build(spec, tmp_path_factory.mktemp(variant)))
    return out


def _net(net_file):
    root = ET.parse(net_file).getroot()
    lanes = {ln.get("id"): ln for ln in root.iter("lane")}
    return root, lanes


# -- the network --------------------------------------------------------------------------------


@pytest.mark.parametrize("key", [("major", 1, 3), ("major", 2, 6)])
def test_network_has_the_specs_lanes_box_and_connections(nets, key):
    """Every arm has ``lanes`` lanes of ``lane_width_m`` each way at the speed limit, the
    inbound ones ``approach_m`` long and ending at the box's edge (its half side ``lanes *
    lane_width_m``), the outbound ones ``exit_m``; the connections are exactly those our
    routes use (two lanes: left from the inner lane only, right from the outer only,
    straight from both, each keeping its lane index), and no U-turns."""
    spec, net_file = nets[key]
    root, lanes = _net(net_file)
    half = spec.lanes * spec.lane_width_m
    for arm in range(4):
        for kind, length in (("in", spec.approach_m), ("out", spec.exit_m)):
            edge = next(e for e in root.iter("edge") if e.get("id") == f"{kind}{arm}")
            own = edge.findall("lane")
            assert len(own) == spec.lanes
            for ln in own:
                assert float(ln.get("width")) == spec.lane_width_m
                assert float(ln.get("speed")) == pytest.approx(10.0)  # the config's v_max
                assert float(ln.get("length")) == pytest.approx(length, abs=0.01)
        end = np.array([tuple(map(float, p.split(","))) for p in
                        lanes[f"in{arm}_0"].get("shape").split()])[-1]
        assert max(abs(end)) == pytest.approx(half, abs=0.01)  # the stop line: the box
    conns = {(c.get("from"), c.get("to"), int(c.get("fromLane")), int(c.get("toLane")),
              c.get("dir")) for c in root.iter("connection") if not c.get("from")
             .startswith(":")}
    want = set()
    dirs = {"left": "l", "straight": "s", "right": "r"}
    for arm in range(4):
        for move, off in (("left", 3), ("straight", 2), ("right", 1)):
            ours = {0, 1} if spec.lanes == 2 and move == "straight" else \
                {0} if spec.lanes == 1 or move == "left" else {1}
            for lane in ours:
                k = M.sumo_lane(spec, lane)
                want.add((f"in{arm}", f"out{(arm + off) % 4}", k, k, dirs[move]))
    assert conns == want
    if spec.lanes == 2:  # SUMO's lane 1 is the inner one: left turns leave from it
        assert {c[2] for c in conns if c[4] == "l"} == {1}
        assert {c[2] for c in conns if c[4] == "r"} == {0}


def test_junction_type_follows_the_priority(nets):
    """``major`` -> ``priority`` with the east-west road major (its straight links have the
    right of way, the minor road's yield), ``right-before-left`` -> ``right_before_left``,
    ``first-come`` -> ``allway_stop``."""
    types = {}
    for (variant, _, _), (spec, net_file) in nets.items():
        root, _ = _net(net_file)
        centre = next(j for j in root.iter("junction") if j.get("id") == "C")
        types[spec.priority] = centre.get("type")
        if spec.priority == "major":
            state = {(c.get("from"), c.get("dir")): c.get("state")
                     for c in root.iter("connection") if c.get("from", "").startswith("in")}
            assert state[("in0", "s")] == state[("in2", "s")] == "M"
            assert state[("in1", "s")] == state[("in3", "s")] == "m"
    assert types == {"major": "priority", "right-before-left": "right_before_left",
                     "first-come": "allway_stop"}


def test_every_route_is_projected_through_the_box(nets):
    """Each route's lanes, from the lane it starts on, are SUMO's: the inbound lane, every
    internal lane of the connection (a major road's left turn is split at its waiting
    position: both halves), the exit lane; so no vehicle inside the box is lost to the
    projection (it was, before the split was followed: the shield then missed a car turning
    left in front of the AV)."""
    import libsumo

    spec, net_file = nets[("major", 2, 6)]
    root, _ = _net(net_file)
    via = {}
    for c in root.iter("connection"):
        lane = f"{c.get('from')}_{c.get('fromLane')}"
        via[(lane, c.get("to"))] = (c.get("via"), f"{c.get('to')}_{c.get('toLane')}")
    libsumo.start(["sumo", "-n", str(net_file), "--no-step-log", "true"])
    try:
        pr = S.Projector(M.av_route_edges(spec), (5.0, 2.5), libsumo.lane.getLinks,
                         libsumo.lane.getShape, libsumo.lane.getLength)
        split = 0
        for (first, to), (v, out) in via.items():
            if first.startswith(":"):
                continue
            want = [first]
            while v:  # the internal lanes, in order, to the exit lane
                want.append(v)
                nxt = next(c for c in root.iter("connection")
                           if c.get("from") == v.rsplit("_", 1)[0])
                v = nxt.get("via")
            want.append(out)
            split += len(want) > 3
            assert list(pr.route((first.rsplit("_", 1)[0], to), first).lanes) == want
    finally:
        libsumo.close()
    assert split == 2  # the major road's two left turns (one lane each)


# -- the arrivals --------------------------------------------------------------------------------


@pytest.mark.parametrize("key, arrival", [(("major", 2, 6), "placed"),
                                          (("major", 1, 3), "placed"),
                                          (("major", 1, 3), "poisson")])
def test_vehicles_start_at_our_distance_to_the_stop_line(nets, key, arrival):
    """Right after its insertion every vehicle is on its drawn SUMO lane, its centre at our
    distance to the stop line (``entry_m - s0``) and at its drawn speed; with Poisson
    arrivals at its arrival time."""
    import libsumo

    spec, net_file = nets[key]
    spec = spec.with_(arrival=arrival, av_arrival_s=2.0) if arrival == "poisson" else spec
    arr = arrivals(spec, 7)
    from persuasive.tables import Limits

    limits = [Limits(5.0, 2.5, -2.0, 1.0, 0.0, 10.0)] * arr.n
    lengths = M._approach_lengths(net_file)
    deps = M.departures(spec, arr, limits, lengths)
    folder = net_file.parent / f"start-{arrival}"
    folder.mkdir(exist_ok=True)
    routes = folder / "r.rou.xml"
    routes.write_text(M.routes_xml(deps, limits[0], limits[1], True), encoding="utf-8")
    libsumo.start(S.sumo_args(net_file, routes, folder, 7, 60.0, True))  # its SSM file there
    seen: dict[str, tuple] = {}
    try:
        while len(seen) < arr.n and libsumo.simulation.getTime() < 60.0:
            libsumo.simulationStep()
            for vid in libsumo.simulation.getDepartedIDList():
                seen[vid] = (libsumo.vehicle.getLaneID(vid),
                             libsumo.vehicle.getLanePosition(vid),
                             libsumo.vehicle.getSpeed(vid),
                             libsumo.simulation.getTime() - S.DT_S)
    finally:
        libsumo.close()
    assert len(seen) == arr.n
    for i, d in enumerate(deps):
        lane, pos, v, t = seen[d.vehicle]
        r = arr.routes[i]
        assert lane == f"in{r.arm}_{spec.lanes - 1 - r.lane}"
        centre_to_line = lengths[lane] - pos + 0.5 * limits[i].length_m
        assert centre_to_line == pytest.approx(r.entry_m - arr.s0_m[i], abs=1e-3)
        assert v == pytest.approx(arr.v0_mps[i], abs=1e-3)
        if arrival == "placed":
            assert t == pytest.approx(0.0, abs=1e-9)
        else:  # its arrival time, later only if SUMO held it at a busy entry
            assert t >= round(float(arr.t0_s[i]), 1) - 1e-9


def test_routes_file_has_our_vehicles_and_sumos_default_driver():
    """The humans: SUMO's default Krauss driver (sigma 0.5) with our ``hv`` limits; the AV
    our ``av`` limits at speed factor 1 with the SSM device; placed vehicles inserted as
    drawn; the AV left out of the run without it."""
    from persuasive.tables import Limits

    lim = Limits(5.0, 2.5, -2.0, 1.0, 0.0, 10.0)
    deps = [M.Departure("ego", ("in3", "out1"), 0, 0.0, 80.0, 4.0, True),
            M.Departure("h1", ("in0", "out2"), 0, 0.0, 70.0, 3.5, True)]
    text = M.routes_xml(deps, lim, lim, True)
    assert ('<vType id="human" length="5" width="2.5" accel="1" decel="2" '
            'emergencyDecel="2" maxSpeed="10" sigma="0.5"/>') in text
    assert 'speedFactor="1" speedDev="0"' in text and "has.ssm.device" in text
    assert text.count('insertionChecks="none"') == 2
    assert 'id="ego"' not in M.routes_xml(deps, lim, lim, False)


# -- episodes -----------------------------------------------------------------------------------


def _sane(results, n):
    ref, sumo, ours = results
    assert [r.driver for r in results] == [M.NO_AV, M.SUMO_DRIVER, PLANNER]
    for r in results:
        assert r.humans == n - 1 and r.n_vehicles == n
        assert r.av_caused_collisions <= r.av_collisions
    assert not ref.av_through and ref.av_clear_s is None and ref.caused_time_loss_s is None
    assert ref.ego_steps == 0 and ref.min_pet_s is None
    for r in (sumo, ours):
        assert r.av_through and 0.0 < r.av_clear_s <= M.EPISODE_S
        assert r.caused_time_loss_s == pytest.approx(r.traffic_time_loss_s
                                                     - ref.traffic_time_loss_s)
        assert r.av_caused_collisions == 0
    assert sumo.ego_steps == 0 and sumo.shield_overrides == 0
    assert ours.ego_steps > 10 * ours.av_clear_s - 1 and ours.uncertified == 0
    # the planner drives until the AV leaves the network
    assert ours.ego_steps * S.DT_S >= ours.av_clear_s


@pytest.mark.parametrize("key", [("major", 1, 3), ("right-before-left", 1, 4),
                                 ("all-way", 1, 4), ("major", 2, 6)])
def test_one_short_episode_per_driver_gives_sane_numbers(nets, key):
    spec, net_file = nets[key]
    _sane(M.run_seed(spec, 2, (M.SUMO_DRIVER, PLANNER), net_file), spec.n_vehicles)


def test_poisson_arrivals_run_with_the_stand_ins(nets):
    """Poisson arrivals: the AV departs at its arrival time, its clear time counts from
    then; the shield checks the stand-ins of the humans still to come and stays
    certified."""
    spec, net_file = nets[("major", 1, 3)]
    spec = spec.with_(arrival="poisson", av_arrival_s=3.0, flow_veh_h=900.0)
    out = M.run_seed(spec, 4, (M.SUMO_DRIVER, PLANNER), net_file)
    _sane(out, 3)
    assert out[2].t_end_s > 3.0


def test_same_seed_twice_gives_identical_results(nets):
    spec, net_file = nets[("major", 2, 6)]
    a = M.run_seed(spec, 5, (M.SUMO_DRIVER, PLANNER), net_file)
    b = M.run_seed(spec, 5, (M.SUMO_DRIVER, PLANNER), net_file)
    assert [r.to_dict() for r in a] == [r.to_dict() for r in b]


@pytest.mark.slow
def test_study_does_not_depend_on_the_workers():
    kw = dict(vehicles=(2, 4), seeds=2, seed=3, avs=("persuasive",))
    one = M.run_study(workers=1, **kw)
    two = M.run_study(workers=2, **kw)
    assert [e.to_dict() for e in one.episodes] == [e.to_dict() for e in two.episodes]
    assert one.table() == two.table()
    assert [(e.n_vehicles, e.seed, e.driver) for e in one.episodes][:3] == \
        [(2, 3, "none"), (2, 3, "sumo"), (2, 3, PLANNER)]


# -- the paired table ------------------------------------------------------------------------


def _result(seed, driver, through, clear, caused, n=3):
    return M.EpisodeResult(seed, n, "major", 1, driver, through, clear, 0, 0, 0, 10.0, caused,
                           n - 1, None, None, 0.0, 0, 0, 0, 60.0)


def test_paired_row_by_hand():
    """Through 2 of 3 (SUMO) against 3 of 3 (ours): +33.3 points, the normal interval of the
    mean paired difference (0, 0, 100: mean 33.3, s = 57.7); the restricted mean counts the
    run not through at 60 s; the delay caused is per human (n - 1 = 2)."""
    sumo = [_result(1, "sumo", True, 10.0, 2.0), _result(2, "sumo", False, None, 4.0),
            _result(3, "sumo", True, 20.0, 0.0)]
    ours = [_result(1, PLANNER, True, 12.0, 4.0), _result(2, PLANNER, True, 30.0, 4.0),
            _result(3, PLANNER, True, 14.0, 2.0)]
    row = M.paired_row(sumo, ours, PLANNER)
    assert row["through_pct_sumo"] == pytest.approx(200.0 / 3)
    assert row["through_pct_ours"] == 100.0
    half = 1.959963984540054 * np.std([0.0, 100.0, 0.0], ddof=1) / math.sqrt(3)
    assert row["through_diff_points"] == pytest.approx(100.0 / 3)
    assert row["through_diff_ci"] == pytest.approx([100.0 / 3 - half, 100.0 / 3 + half])
    assert row["clear_s_sumo"] == pytest.approx((10.0 + 60.0 + 20.0) / 3)
    assert row["clear_s_ours"] == pytest.approx((12.0 + 30.0 + 14.0) / 3)
    assert row["caused_delay_s_sumo"] == pytest.approx(1.0)
    assert row["caused_delay_s_ours"] == pytest.approx(10.0 / 6)
    assert row["delay_diff_s"] == pytest.approx(2.0 / 3)
    with pytest.raises(ValueError):
        M.paired_row(sumo, ours[:2], PLANNER)


# -- bad input -----------------------------------------------------------------------------------


def test_a_junction_sumo_cannot_build_is_one_line(tmp_path, monkeypatch):
    """netconvert refusing the junction (here: an arm's edge from a node it does not have)
    is one line naming netconvert's error and the junction; a negative radius is refused
    before netconvert (which would accept it)."""
    from dataclasses import replace

    real = M.junction_network

    def broken(spec, config=None, radius_m=M.RADIUS_M):
        net = real(spec, config, radius_m)
        return replace(net, edges=(("in0", "nowhere", "C", 2),) + net.edges[1:])

    monkeypatch.setattr(M, "junction_network", broken)
    spec = JunctionSpec.of("major", n_vehicles=3)
    with pytest.raises(ConfigError) as err:
        M.build(spec, tmp_path)
    text = str(err.value)
    assert "\n" not in text and "netconvert cannot build" in text and "nowhere" in text
    assert "junction: 1 lane(s) of 4 m, approach 100 m, exit 40 m" in text
    monkeypatch.undo()
    with pytest.raises(ConfigError, match="radius_m = -1.0 is out of range"):
        M.build(spec, tmp_path, radius_m=-1.0)


@pytest.mark.parametrize("kw, name", [
    ({"vehicles": (0,)}, "junction.n_vehicles"), ({"vehicles": ()}, "--vehicles"),
    ({"seeds": 0}, "--seeds"), ({"avs": ("nobody",)}, "--av = 'nobody'"),
    ({"shield": "maybe"}, "--shield"), ({"workers": 0}, "--workers"),
    ({"lanes": 3}, "junction.lanes"), ({"variant": "roundabout"}, "junction.variant")])
def test_bad_study_arguments_are_one_line(kw, name):
    args = dict(vehicles=(2,), seeds=1, seed=1, avs=("persuasive",), shield="worst-case",
                workers=1, variant="major", lanes=1)
    args.update(kw)
    with pytest.raises(ConfigError) as err:
        M.check_study(**args)
    assert name in str(err.value) and "\n" not in str(err.value)


# -- the benchmark, as a user runs it ------------------------------------------------------


def _benchmark():
    spec = importlib.util.spec_from_file_location("junction_sumo",
                                                  ROOT / "benchmarks" / "junction_sumo.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_benchmark_bad_input_is_one_line_exit_2(capsys, tmp_path):
    bench = _benchmark()
    assert bench.main(["--vehicles", "2,x", "--out", str(tmp_path / "o")]) == 2
    assert bench.main(["--vehicles", "2", "--av", "nobody"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("error: ") for line in err)
    assert "--vehicles = '2,x'" in err[0] and "--av = 'nobody'" in err[1]
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_benchmark_prints_the_paired_table_and_writes_it(capsys, tmp_path):
    bench = _benchmark()
    out = tmp_path / "o"
    assert bench.main(["--vehicles", "2,3", "--seeds", "2", "--workers", "1",
                       "--out", str(out)]) == 0
    text = capsys.readouterr().out
    rows = [ln for ln in text.splitlines() if ln.startswith("| 2 |") or ln.startswith("| 3 |")]
    assert len(rows) == 2 and all("| persuasive | 2 |" in r for r in rows)
    assert "difference points [95 % CI]" in text
    data = json.loads((out / "study.json").read_text())
    assert len(data["episodes"]) == 2 * 2 * 3 and len(data["table"]) == 2
    assert (out / "table.md").read_text().strip() in text
    assert sorted(p.name for p in out.iterdir()) == ["study.json", "table.md"]
