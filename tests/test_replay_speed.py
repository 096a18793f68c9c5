"""Foresight at replay speed (``persuasive.safety.foresight``, "Cost"; issue 42 item 2): the
shortcuts pick the line the plain computation picks.

Layers: a line that cannot win is left unfinished, on any table of predicted scores (ties,
runs that never clear, one to eight lines), and the pick is the reference's; the compiled
loop stopped once both vehicles are through is the whole run's beginning, bit for bit, and
its score the whole run's summary's; on random scenarios, starts and seeds, the fast pick is
the reference's; a replay with the fast pick is the replay with the reference's.
Tolerances: none, every comparison is exact.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive import Config
from persuasive.safety import foresight
from persuasive.world import (predicted_score, predicted_states, predicted_summary,
                              run_compiled)

#: clear times that tie often, a run that never cleared (None), one past the run's end
CLEARS = (None, 3.0, 5.0, 5.0, 6.5, 40.0)


def table_predict(table: dict, calls: list):
    """A ``predict`` that reads each model run's summary from ``table`` by (line, kind,
    role), counting its calls."""

    def predict(config, seed, interaction, x0):
        calls.append(1)
        return table[(config.av.yield_line_m, config.hv.kind, config.hv.role)]

    return predict


@settings(max_examples=300, deadline=None)
@given(lines=st.lists(st.sampled_from([0.0, 1.5, 3.0, 3.75, 4.5, 6.0, 8.0, 12.0]),
                      min_size=1, max_size=8, unique=True),
       data=st.data())
def test_a_line_that_cannot_win_is_not_finished_and_the_pick_is_the_references(lines, data):
    """Any scores: live or not, AV first or not, clear times that tie, never clear, or
    clear after the run's end. The bounded pick is the plain one (ties to the earlier line),
    from no more model runs."""
    table = {}
    for line in lines:
        for kind, role in foresight.MODELS:
            live = data.draw(st.booleans())
            table[(line, kind, role)] = {
                "both_cleared": live or data.draw(st.booleans()),
                "deadlock": not live and data.draw(st.booleans()),
                "av_first_through": data.draw(st.booleans()),
                "av_time_to_clear_s": data.draw(st.sampled_from(CLEARS))}
    config = Config(mode="corrected").with_overrides({"simulation.n_steps": 200,
                                                      "av.yield_line_choices_m": lines})
    fast, plain = [], []
    x0 = np.array([-20.0, 5.0, -20.0, 5.0])
    pick = foresight.choose_line(config, 3, x0, table_predict(table, fast))
    assert pick == foresight.choose_line_reference(config, 3, x0, table_predict(table, plain))
    assert len(fast) <= len(plain) == len(lines) * len(foresight.MODELS)


def test_the_bound_leaves_a_line_as_soon_as_it_cannot_win():
    live_first, live, dead = (True, True, -5.0), (True, False, -5.0), (False, False, -20.0)
    best = (5, 5, -5.0)  # every model run live, the AV first in all, 5 s
    assert foresight.bounded_line_value(iter([live]), 5, best) is None  # first already lost
    drawn = []

    def scores():
        for s in (live_first, dead, live_first, live_first, live_first):
            drawn.append(s)
            yield s

    # the best so far: every model run live, the AV first in none, 30 s
    assert foresight.bounded_line_value(scores(), 5, (5, 0, -30.0)) is None
    assert len(drawn) == 2  # after one standoff at most 4 of 5 live: the rest not drawn
    # a tie is no win: the earlier line keeps it
    assert foresight.bounded_line_value(iter([live_first] * 5), 5, best) is None
    assert foresight.bounded_line_value(iter([live_first] * 5), 5, None) == best
    assert foresight.bounded_line_value(iter([live_first] * 5), 5, (5, 4, -5.0)) == best


#: random scenarios: the kinds, angles, the human's envelope, the run's length
SCENARIOS = st.one_of(
    st.builds(lambda a: {"scenario.kind": "crossing", "scenario.angle_deg": float(a)},
              st.integers(4, 32).map(lambda k: 5 * k)),
    st.builds(lambda a: {"scenario.kind": "merge", "scenario.angle_deg": float(a)},
              st.integers(3, 18).map(lambda k: 5 * k)),
    st.just({"scenario.kind": "intersection"}),
    st.just({"scenario.kind": "left-turn"}))


def random_config(scenario: dict, envelope: str | None, n_steps: int, v_max: float) -> Config:
    over = {**scenario, "simulation.n_steps": n_steps}
    if envelope is not None:  # (it sets the human's speed limit too)
        over["hv.envelope"] = envelope
    else:
        over["hv.vehicle.v_max_mps"] = v_max
    return Config(mode="corrected").with_overrides(over)


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(scenario=SCENARIOS, envelope=st.sampled_from([None, "real-driver", "sumo"]),
       n_steps=st.integers(20, 160), v_max=st.sampled_from([10.0, 13.5]),
       seed=st.integers(0, 2**32 - 1),
       x0=st.tuples(st.floats(-60.0, 5.0), st.floats(0.0, 10.0), st.floats(-60.0, 5.0),
                    st.floats(0.0, 10.0)))
def test_the_fast_pick_is_the_references_on_random_states(scenario, envelope, n_steps, v_max,
                                                           seed, x0):
    """Every model run of every line: the loop stopped once both vehicles are through is the
    whole run's beginning bit for bit, stopped no later than the first such state, and its
    score is the whole run's summary's; the pick is the reference's."""
    from persuasive.policies import kinds as kd
    from persuasive.policies import policy_params
    from persuasive.record import setup, static_setup

    config = random_config(scenario, envelope, n_steps, v_max)
    x0 = np.array(x0)
    run_s = n_steps * config.simulation.dt_s
    p_seed = foresight.prediction_seed(seed)
    for line in config.yield_line_choices:
        for kind, role in foresight.MODELS:
            model = foresight.model_config(config, line, kind, role)
            sc = static_setup(model)[0]
            stop = (max(sc.av.clear_s, 0.0), max(sc.hv.clear_s, 0.0))
            _, part = predicted_states(model, p_seed, 0, x0, *stop)
            s = setup(model, p_seed, interaction=0, x0=x0)
            whole = run_compiled(s, policy_params(model, kd.AV),
                                 policy_params(model, kd.HV))[0]
            assert np.array_equal(part, whole.states[:len(part)])
            through = (whole.states[:, 0] >= stop[0]) & (whole.states[:, 2] >= stop[1])
            k = np.flatnonzero(through[1:])
            assert len(part) - 1 == (k[0] + 1 if k.size else n_steps)
            assert predicted_score(model, p_seed, 0, x0, run_s) == \
                foresight.score(whole.summary(), run_s)
    assert foresight.choose_line(config, seed, x0, predicted_summary) == \
        foresight.choose_line_reference(config, seed, x0, predicted_summary)


@pytest.mark.parametrize("seed", (15, 22, 1, 2))
def test_the_paper_intersections_picks_by_hand(seed):
    """Seeds where the line at the interval ends in a standoff (15, 22: the far line) and
    where it persuades (1, 2: the line at the interval), from the run's measured start: the
    fast pick is the reference's, and a model run stops well before the run's end."""
    from persuasive.record import setup, static_setup

    config = Config(mode="corrected").with_overrides({"simulation.n_steps": 200,
                                                      "av.yield_line_choices_m": [0, 8]})
    x0 = setup(config, seed, predict=lambda *a: {  # the run's start (no noise: as measured)
        "both_cleared": True, "deadlock": False, "av_first_through": False,
        "av_time_to_clear_s": 1.0}).x0
    pick = foresight.choose_line(config, seed, x0, predicted_summary)
    assert pick == foresight.choose_line_reference(config, seed, x0, predicted_summary)
    assert pick == (8.0 if seed in (15, 22) else 0.0)
    model = foresight.model_config(config, pick, "lfg", "leader")
    sc = static_setup(model)[0]
    _, part = predicted_states(model, foresight.prediction_seed(seed), 0, x0,
                               max(sc.av.clear_s, 0.0), max(sc.hv.clear_s, 0.0))
    assert len(part) < 150  # of 201 states


def test_the_fast_path_is_the_compiled_loops_only():
    """Any other ``predict`` (a test's, another loop's) is read through its summaries."""
    seen = []

    def predict(config, seed, interaction, x0):
        seen.append(config.hv.kind)
        return {"both_cleared": True, "deadlock": False, "av_first_through": False,
                "av_time_to_clear_s": 5.0}

    config = Config(mode="corrected").with_overrides({"simulation.n_steps": 50})
    assert foresight.choose_line(config, 1, np.array([-20.0, 5.0, -20.0, 5.0]), predict) == 0.0
    assert len(seen) == len(config.yield_line_choices) * len(foresight.MODELS)


@pytest.mark.slow
def test_a_replay_with_the_fast_pick_is_the_replay_with_the_references(tmp_path, monkeypatch):
    """A crossing read from hand-made tracks (the second driver slows), both seats: the runs
    are the same field for field with foresight's plain computation in place of the fast
    one (merges and the other scenarios: the test on random states)."""
    from test_recordings import straight, write

    from persuasive.recordings.formats import read_tracks
    from persuasive.recordings.pairs import find_pairs, pairs_frame
    from persuasive.recordings.replay import ReplaySettings, replay_pairs
    from persuasive.recordings.tracks import smooth_tracks

    speeds = np.concatenate([np.full(30, 8.0), np.linspace(8.0, 4.0, 20), np.full(70, 4.0)])
    write(tmp_path / "vehicle_tracks_000.csv", straight(1, (-40.0, 0.0), 0.0, [8.0] * 120),
          straight(2, (0.0, -40.0), 90.0, speeds))
    frame = pairs_frame(find_pairs(smooth_tracks(read_tracks([str(tmp_path)]))).pairs)
    assert len(frame) and set(frame["kind"]) == {"crossing"}
    fast = replay_pairs(frame, ReplaySettings()).frame()
    monkeypatch.setattr(foresight, "choose_line", foresight.choose_line_reference)
    plain = replay_pairs(frame, ReplaySettings()).frame()
    pd.testing.assert_frame_equal(fast, plain, check_exact=True)
