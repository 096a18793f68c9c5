"""The tables of a run (persuasive.tables): a two-vehicle run is their N = 2 case, read by the
measures of many exactly as a junction's run, and its long table is its log per vehicle."""

import math

import numpy as np
import pytest

from persuasive.config import Config
from persuasive.many import measures
from persuasive.many.world import JunctionWorld
from persuasive.simulation import simulate
from persuasive.tables import ACTIVE, CROSSING, MERGE, ConflictTable, Row, Trace

SCENARIOS = ("intersection", "crossing", "left-turn", "merge")


def _runs(scenario, hv, shield, seeds):
    over = {"scenario.kind": scenario, "hv.kind": hv}
    if shield is not None:
        over["av.shield"] = shield
    config = Config().with_overrides(over)
    return [simulate(config, s) for s in seeds]


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_a_two_vehicle_run_is_the_tables_two_vehicle_case(scenario):
    (run,) = _runs(scenario, "lfg", None, [1])
    trace = run.trace()
    assert isinstance(trace, Trace) and trace.n == 2 and trace.k == run.states.shape[0] - 1
    (row,) = trace.table.rows
    assert (row.i, row.j) == (0, 1) and trace.table.of == [[0], [0]]
    assert row.kind == (MERGE if run.scenario.lane_shared else CROSSING)
    assert row.ij.ego_occupancy == tuple(run.scenario.av.occupancy)
    assert row.ji.ego_occupancy == tuple(run.scenario.hv.occupancy)
    assert row.ij.other_occupancy == row.ji.ego_occupancy
    assert trace.through_m(0) == run.scenario.av.clear_s
    assert trace.vehicles.kind == ("av", "lfg")
    assert np.all(trace.STATUS == ACTIVE)
    conflicts = trace.conflicts_frame()
    assert list(conflicts["kind"]) == [row.kind] and conflicts["i_lo_m"][0] == row.ij.ego_occupancy[0]


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_the_long_table_is_the_log_per_vehicle(scenario):
    (run,) = _runs(scenario, "lfg", None, [2])
    frame = run.vehicles_frame()
    log = run.log
    n = len(log["step"])
    assert len(frame) == 2 * (n + 1)  # every state, the last one's acceleration NaN
    for i, who in enumerate(("av", "hv")):
        part = frame[frame["vehicle"] == i].iloc[:n]
        np.testing.assert_array_equal(part["s_m"], log[f"{who}_s_m"])
        np.testing.assert_array_equal(part["v_mps"], log[f"{who}_v_mps"])
        np.testing.assert_array_equal(part["x_m"], log[f"{who}_x_m"])
        np.testing.assert_array_equal(part["y_m"], log[f"{who}_y_m"])
        np.testing.assert_array_equal(part["heading_rad"], log[f"{who}_heading_rad"])
        np.testing.assert_array_equal(part["a_mps2"], log[f"{who}_accel_mps2"])
        assert set(part["path"]) == {who}
        last = frame[frame["vehicle"] == i].iloc[n]
        assert last["s_m"] == run.states[-1, 2 * i] and math.isnan(last["a_mps2"])
    # the human plays the AV at every step (none after the last state)
    assert list(frame[frame["vehicle"] == 1]["opponent"]) == [0] * n + [-1]
    assert set(frame[frame["vehicle"] == 0]["opponent"]) == {-1}
    # the junction's long table has the same columns, its own labels in place of the path
    world = JunctionWorld.of(Config(mode="corrected").with_overrides({"scenario.kind": "junction"}), 0)
    world.step()
    junction = world.frame()
    common = [c for c in frame.columns if c != "path"]
    assert [c for c in junction.columns if c not in ("arm", "movement", "lane")] == common


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("hv,shield", [("lfg", None), ("lfg", "worst-case"), ("adversary", None),
                                       ("aggressive", "worst-case")])
def test_the_measures_of_many_agree_with_the_two_vehicle_outcome(scenario, hv, shield):
    """The N = 2 identity: what the measures read from the tables is what the two-vehicle
    outcome says, where both measure the same thing (the clear time interpolated between
    the steps the outcome counts)."""
    runs = _runs(scenario, hv, shield, range(12))
    firsts = set()
    for run in runs:
        o, dt = run.outcome, run.config.simulation.dt_s
        m = run.measures()
        assert m["n_vehicles"] == 2 and m["steps"] == run.states.shape[0] - 1
        clear = measures.clear_times(run.trace())
        for i, who in enumerate(("av", "hv")):
            t_out = getattr(o, f"{who}_time_to_clear_s")
            if math.isnan(t_out):
                assert math.isnan(clear[i])
            else:
                assert t_out - dt - 1e-12 < clear[i] <= t_out + 1e-12
        assert m["av_through"] == (not math.isnan(o.av_time_to_clear_s))
        # who passed the conflict point first
        both = bool((run.states[:, 0] >= 0.0).any() and (run.states[:, 2] >= 0.0).any())
        assert m["av_conflicts_passed"] == int(both)
        if both and o.first_at_conflict_point in (1, 2):
            assert m["av_first_conflicts"] == (1 if o.first_at_conflict_point == 1 else 0)
            firsts.add(o.first_at_conflict_point)
        assert m["av_collisions"] == int(o.collision)
        assert m["av_caused_collisions"] == int(o.collision_caused_by_av)
        assert m["human_collisions"] == 0 and m["crashed_humans"] == 0
        assert m["min_gap_av_m"] == o.min_gap_m
        if not o.rear_end_by_human:
            assert m["uncertified_steps"] == o.uncertified_steps
            assert m["uncertified_steps"] + m["shield_overrides"] == o.shield_interventions
    if hv == "adversary":  # the cases are exercised, not only the easy one
        assert any(r.outcome.collision for r in runs)
    if scenario in ("intersection", "crossing"):  # both orders are exercised
        if hv == "lfg" and shield is None:
            assert 1 in firsts
        if hv == "adversary":
            assert 2 in firsts


def test_a_two_vehicle_standoff_is_a_cycle_of_the_wait_for_graph():
    """Two vehicles that stand before a crossing, each within reach of it and waiting for
    the other, are a deadlock of the wait-for graph once it has lasted DEADLOCK_S; one that
    stands while the other is far away is not."""
    (run,) = _runs("intersection", "lfg", None, [1])
    base = run.trace()
    n_steps = 80
    row = base.table.rows[0]
    lo_av, lo_hv = row.ij.ego_occupancy[0], row.ji.ego_occupancy[0]

    def standing(s_hv: float) -> Trace:
        S = np.tile([lo_av - 3.0, s_hv], (n_steps + 1, 1))
        return Trace(base.vehicles, base.table, 0, base.dt, n_steps * base.dt, True, S,
                     np.zeros_like(S), np.zeros((n_steps, 2)),
                     np.zeros((n_steps + 1, 2), np.int8), n_steps, [None] * n_steps, [], 5.0,
                     np.full((n_steps, 2), -1, np.int16), base.place)

    stuck = standing(lo_hv - 3.0)
    assert measures.wait_edges(stuck, 0) == [(0, 1), (1, 0)]
    t, members = measures.deadlock(stuck)
    assert t == 0.0 and members == (0, 1)
    assert measures.summary(stuck)["deadlock"] and measures.summary(stuck)["av_in_deadlock"]
    far = standing(lo_hv - measures.APPROACH_M - 5.0)
    assert measures.wait_edges(far, 0) == [] and measures.deadlock(far) is None
    # a table without the row: nothing to wait for
    alone = Trace(**{**vars(stuck), "table": ConflictTable.of_rows([], 2)})
    assert measures.deadlock(alone) is None


def test_a_junction_world_and_its_trace_measure_the_same():
    config = Config(mode="corrected").with_overrides({"scenario.kind": "junction",
                                                      "junction.n_vehicles": 4})
    world = JunctionWorld.of(config, 5).run()
    reference = JunctionWorld.of(config, 5, with_av=False).run()
    trace = world.trace()
    assert trace.S is world.S and trace.table is world.table
    np.testing.assert_equal(measures.summary(trace, reference.trace()),
                            measures.summary(world, reference))
    assert list(trace.vehicles.labels) == ["arm", "movement", "lane"]
    assert isinstance(world.table.rows[0], Row)


def test_the_n_vehicle_figures_draw_a_two_vehicle_run_from_its_tables():
    from matplotlib.patches import Polygon

    from persuasive.plots import junction as draw

    (run,) = _runs("intersection", "adversary", None, [1])
    assert run.outcome.collision
    trace = run.trace()
    fig = draw.topview_figure(trace, snapshots=4)
    ax = fig.axes[0]
    paths = [ln for ln in ax.lines if ln.get_marker() in ("None", "")]
    marks = [ln for ln in ax.lines if ln.get_marker() == "x"]
    assert len(paths) == 2 and len(marks) == 2
    np.testing.assert_array_equal(paths[0].get_xdata(), run.log["av_x_m"].tolist()
                                  + [run.scenario.positions("av", run.states[-1:, 0])[0][0]])
    polys = [p for p in ax.patches if isinstance(p, Polygon)]
    assert len(polys) == 2 * 5
    # the first AV footprint is centred on the AV's logged position
    np.testing.assert_allclose(polys[0].get_xy()[:4].mean(axis=0),
                               [run.log["av_x_m"][0], run.log["av_y_m"][0]], atol=1e-9)
    assert "2 vehicles" in ax.get_title() and "junction" not in ax.get_title()
    prof = draw.profile_figure(trace)
    np.testing.assert_array_equal(prof.axes[0].lines[-1].get_ydata(), run.states[:, 1])
    (frame, *_) = draw.frames(trace)
    assert frame.ndim == 3 and frame.shape[2] == 3


def test_simulate_writes_any_run_per_vehicle_in_the_same_columns(tmp_path, capsys):
    import pandas as pd

    from _cli import run_cli

    two, log = tmp_path / "two.csv", tmp_path / "log.parquet"
    code, text, err = run_cli(capsys, "simulate", "--seed", 3, "--vehicles-out", two,
                              "--out", log)
    assert code == 0, err
    assert f"per-vehicle table written to {two}" in text and log.exists()
    got = pd.read_csv(two)
    want = simulate(Config(), 3).vehicles_frame()
    assert list(got.columns) == list(want.columns)
    np.testing.assert_allclose(got["x_m"], want["x_m"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got["vehicle"], want["vehicle"])
    # a junction: the same columns, its labels in place of the path; --out writes the same
    many, out = tmp_path / "many.parquet", tmp_path / "out.parquet"
    code, text, err = run_cli(capsys, "simulate", "--scenario", "junction", "--vehicles", 3,
                              "--set", "junction.duration_s=3", "--seed", 1, "--vehicles-out",
                              many, "--out", out)
    assert code == 0, err
    a, b = pd.read_parquet(many), pd.read_parquet(out)
    pd.testing.assert_frame_equal(a, b)
    assert [c for c in a.columns if c not in ("arm", "movement", "lane")] == \
        [c for c in got.columns if c != "path"]
    # one file named twice is refused before any work, and nothing is written
    same = tmp_path / "same.csv"
    code, text, err = run_cli(capsys, "simulate", "--seed", 3, "--vehicles-out", same,
                              "--out", same)
    assert code == 2 and "--vehicles-out" in err and not same.exists()
    assert len(err.strip().splitlines()) == 1


def test_a_saved_run_read_back_has_the_same_tables(tmp_path):
    import pandas as pd

    from persuasive.record import load_record

    (run,) = _runs("left-turn", "lfg", "worst-case", [4])
    run.save(tmp_path / "run.parquet")
    back = load_record(tmp_path / "run.parquet")
    pd.testing.assert_frame_equal(back.vehicles_frame(), run.vehicles_frame())
    pd.testing.assert_frame_equal(back.trace().conflicts_frame(), run.trace().conflicts_frame())
    np.testing.assert_equal(back.measures(), run.measures())
