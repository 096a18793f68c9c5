"""The rest of the safety layer (docs/method.md §12): occupancy intervals, the confidence
filter, the humans that test the shield, the surrogate safety measures, and the shield in the
planner API, the Python loop, the compare study and the command line. The shield's own verdicts
are tested in tests/test_shield.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive import Config, Planner, simulate
from persuasive.geometry import footprints_overlap, occupancy_interval
from persuasive.record import static_setup
from persuasive.safety import measures
from persuasive.safety.confidence import confidence_update, plausible_of, role_prediction

SCENARIOS = {"intersection": {}, "crossing": {"scenario.angle_deg": 60.0}, "left-turn": {},
             "merge": {}}


def scenario_of(kind: str, **extra):
    config = Config(mode="corrected").with_overrides({"scenario.kind": kind, **SCENARIOS[kind],
                                                      **extra})
    return static_setup(config)[0]


# -- occupancy intervals -------------------------------------------------------------------


def test_occupancy_of_straight_paths_by_hand():
    """Two straight roads at 60 degrees, 5 x 2.5 m cars: the footprint touches the other's
    2.5 m strip when |s| sin 60 <= 1.25 + 2.5 sin 60 + 1.25 cos 60."""
    sc = scenario_of("crossing")
    sin, cos = math.sin(math.radians(60)), math.cos(math.radians(60))
    reach = (1.25 + 2.5 * sin + 1.25 * cos) / sin
    assert sc.av.occupancy == pytest.approx((-reach, reach), abs=1e-12)
    assert scenario_of("intersection").av.occupancy == (-3.75, 3.75)


@pytest.mark.parametrize("kind", ["crossing", "left-turn", "merge"])
def test_occupancy_contains_every_overlap(kind):
    """Every pair of positions whose footprints overlap lies inside both intervals (the merge:
    the AV's interval is the side zone up to the merge point, so only the AV's positions
    before it are checked against the HV's side zone)."""
    sc = scenario_of(kind)
    rng = np.random.default_rng(3)
    s_av, s_hv = rng.uniform(-20, 15, 200_000), rng.uniform(-20, 15, 200_000)
    if kind == "merge":
        s_av = rng.uniform(-20, 0, 200_000)
    hit = sc.collides(s_av, s_hv)
    assert hit.sum() > 100
    (a_lo, a_hi), (h_lo, h_hi) = sc.av.occupancy, sc.hv.occupancy
    assert np.all((s_av[hit] >= a_lo) & (s_av[hit] <= a_hi))
    assert np.all((s_hv[hit] >= h_lo) & (s_hv[hit] <= h_hi))
    # and is not far too wide: the numerical margins add about 0.1 m at each end
    assert s_av[hit].min() - a_lo < 0.2 and h_hi - s_hv[hit].max() < 0.2


def test_numerical_occupancy_agrees_with_the_exact_one():
    sc = scenario_of("intersection")
    lo, hi = occupancy_interval(sc.av, sc.hv, other_range=(-150.0, 150.0))
    assert -3.75 - 0.1 < lo <= -3.75 and 3.75 <= hi < 3.75 + 0.1


# -- the confidence filter ---------------------------------------------------------------


def test_confidence_update_by_hand():
    # a perfect prediction in the role the model was sure of: the likelihood ratio is
    # N(0; 0.3) / (1/3) = 3.99 and the prior after switching 0.95
    p, alpha = confidence_update(1.0, 1.0, 0.0, 2.0, 0.3, 0.05, 3.0)
    lik = 1.0 / (math.sqrt(2 * math.pi) * 0.3)
    assert p == pytest.approx(0.95 * lik / (0.95 * lik + 0.05 / 3.0), rel=1e-12)
    assert alpha == pytest.approx(1.0)
    # evidence that matches the uniform density exactly leaves only the switching
    z = math.sqrt(-2.0 * math.log(1.0 / 3.0 * math.sqrt(2 * math.pi) * 0.3))
    p, _ = confidence_update(0.7, 0.5, z * 0.3, z * 0.3, 0.3, 0.05, 3.0)
    assert p == pytest.approx(0.95 * 0.7 + 0.05 * 0.3, rel=1e-9)
    # an acceleration 2 m/s^2 off in the only role predicted: confidence collapses
    p, _ = confidence_update(0.98, 1.0, 2.0, 0.0, 0.3, 0.05, 3.0)
    assert p < 1e-6
    # the role posterior follows the residuals
    _, alpha = confidence_update(0.9, 0.5, 0.0, 1.0, 0.3, 0.05, 3.0)
    assert alpha > 0.99


def test_role_prediction_is_the_transition():
    assert plausible_of(0.7, 0.3) == 0.0 and plausible_of(0.3, 0.7) == 1.0
    assert plausible_of(0.5, 0.5) == 0.5
    # plausible F (it believes the AV leads): a leader switches with p_a, a follower stays
    assert role_prediction(1.0, 0.0, 0.8) == pytest.approx(0.2)
    assert role_prediction(0.0, 0.0, 0.8) == pytest.approx(0.0)
    # plausible L: a follower becomes leader with p_a
    assert role_prediction(0.0, 1.0, 0.8) == pytest.approx(0.8)
    # a tie keeps the roles
    assert role_prediction(0.3, 0.5, 0.8) == 0.3


def test_the_model_is_trusted_against_its_own_human_and_not_against_others():
    """Against the paper's human (p_a_hat = p_a) the confidence stays at its ceiling; the
    adversary and the random human drive it below the threshold."""
    base = Config(mode="corrected")
    for seed in range(1, 6):
        conf = simulate(base, seed).log["av_model_confidence"]
        assert np.nanmin(conf) > 0.9
    for hv in ("adversary", "random"):
        lows = [np.nanmin(simulate(base.with_overrides({"hv.kind": hv}), s)
                          .log["av_model_confidence"]) for s in range(1, 6)]
        assert max(lows) < 0.2


def test_without_the_shield_nothing_is_tracked_and_everything_is_allowed():
    log = simulate(Config(mode="corrected").with_overrides({"av.shield": "off"}), 3).log
    assert np.all(np.isnan(log["av_model_confidence"]))
    assert np.all(log["av_n_allowed"] == 11)


# -- the humans that test the shield ---------------------------------------------------------


@given(seed=st.integers(1, 2**32 - 1), kind=st.sampled_from(["adversary", "deceptive",
                                                              "random"]))
@settings(max_examples=15)
def test_test_humans_stay_within_their_limits(seed, kind):
    config = Config(mode="corrected").with_overrides({"hv.kind": kind})
    log = simulate(config, seed).log
    a = log["hv_accel_mps2"]
    assert np.all((a >= -2.0) & (a <= 1.0))


def test_the_adversary_aims_at_the_av():
    """Without the shield it hits the persuasive AV in most runs; it aims at the AV's
    constant-speed arrival at its conflict point (logged), with the acceleration that arrives
    then."""
    config = Config(mode="corrected").with_overrides({"hv.kind": "adversary",
                                                      "av.shield": "off"})
    hits = sum(simulate(config, s).outcome.collision for s in range(1, 21))
    assert hits >= 8
    log = simulate(config.with_overrides({"av.kind": "yield"}), 1).log
    s, v = log["av_meas_s_m"], log["av_meas_v_mps"]
    coming = (s < 0) & (v > 0.1)
    assert coming.sum() > 20
    assert np.allclose(log["hv_target_time_s"][coming], -s[coming] / v[coming])
    t_aim = log["hv_target_time_s"][coming]
    a_aim = 2.0 * (-log["hv_meas_s_m"][coming] - log["hv_meas_v_mps"][coming] * t_aim) / t_aim**2
    assert np.allclose(log["hv_accel_mps2"][coming], np.clip(a_aim, -2.0, 1.0))


def test_the_deceptive_human_waits_for_the_av_to_commit():
    config = Config(mode="corrected").with_overrides({"hv.kind": "deceptive",
                                                      "av.shield": "off"})
    for seed in range(1, 6):
        log = simulate(config, seed).log
        committed = log["hv_committed"]
        if committed.any():
            k = int(np.argmax(committed))
            assert np.all(log["hv_accel_mps2"][k:] == 1.0)  # full throttle from then on
            assert np.all(log["hv_accel_mps2"][:k] < 1.0)  # yielding before


def test_the_random_human_holds_its_accelerations():
    config = Config(mode="corrected").with_overrides({"hv.kind": "random",
                                                      "hv.random.hold_min_s": 0.5,
                                                      "hv.random.hold_max_s": 0.5})
    a = simulate(config, 4).log["hv_accel_mps2"]
    assert np.all(a[:5] == a[0]) and a[5] != a[0]  # new draw every 5 steps


# -- surrogate safety measures -------------------------------------------------------------


def test_pet_by_hand():
    """The AV crosses [-3.75, 3.75] between 1.0 and 2.0 s, the HV enters its own at 3.5 s:
    PET 1.5 s; overlapping windows give 0; a vehicle that never comes gives NaN."""
    t = np.arange(0, 61) * 0.1
    s_av = -13.75 + 10.0 * t  # at -3.75 m at 1.0 s, at 3.75 m at 1.75 s
    s_hv = -7.25 + 1.0 * t  # at -3.75 m at 3.5 s
    assert measures.pet(s_av, s_hv, (-3.75, 3.75), (-3.75, 3.75), 0.1) == pytest.approx(
        3.5 - 1.75, abs=1e-9)
    assert measures.pet(s_av, s_av - 0.5, (-3.75, 3.75), (-3.75, 3.75), 0.1) == 0.0
    assert math.isnan(measures.pet(s_av, np.full(61, -20.0), (-3.75, 3.75), (-3.75, 3.75), 0.1))


def test_min_ttc_by_hand():
    # both at constant speed toward the crossing: the AV inside from 1.0 s, the HV from 1.5 s
    ttc = measures.min_ttc(np.array([-13.75]), np.array([10.0]), np.array([-18.75]),
                           np.array([10.0]), -3.75, 3.75, -3.75, 3.75, False, 5.0)
    assert ttc == pytest.approx(1.5)
    # the AV is through before the HV arrives: never on a collision course
    ttc = measures.min_ttc(np.array([-13.75]), np.array([10.0]), np.array([-40.0]),
                           np.array([2.0]), -3.75, 3.75, -3.75, 3.75, False, 5.0)
    assert math.isnan(ttc)
    # a shared lane: a follower 10 m behind closing at 2 m/s, gap 10 - 5 = 5 m: 2.5 s
    ttc = measures.min_ttc(np.array([10.0]), np.array([5.0]), np.array([20.0]),
                           np.array([3.0]), -7.0, 0.0, -7.0, 5.0, True, 5.0)
    assert ttc == pytest.approx(2.5)


def test_footprint_gap_by_hand():
    """Two 5 x 2.5 m rectangles along x, 10 m apart centre to centre: 5 m apart; crossed at
    right angles with centres (0, 0) and (5, 0): 5 - 2.5 - 1.25 = 1.25 m."""
    out = np.empty(3)
    measures.footprint_gaps(np.array([0.0, 0.0, 0.0]), np.zeros(3), np.ones(3), np.zeros(3),
                            5.0, 2.5, np.array([10.0, 5.0, 1.0]), np.zeros(3), np.array([1.0, 0.0, 0.0]),
                            np.array([0.0, 1.0, 1.0]), 5.0, 2.5, out)
    assert out == pytest.approx([5.0, 1.25, 0.0])
    # agrees with the overlap test where they touch
    assert footprints_overlap(0.0, 0.0, (1.0, 0.0), 5.0, 2.5, 1.0, 0.0, (0.0, 1.0), 5.0, 2.5)


def test_collisions_are_attributed_by_their_first_state():
    overlap = np.array([False, True, True, True, False, True, True])
    rear = np.array([False, True, False, False, False, False, True])
    # the first collision starts as a rear-end (all of it is the human's), the second not
    assert measures.caused_by_av(overlap, rear).tolist() == [False, False, False, False,
                                                             False, True, True]


def test_run_summaries_carry_the_measures():
    rec = simulate(Config(mode="corrected").with_overrides({"hv.kind": "aggressive"}), 2)
    s = rec.summary()
    for key in ("collision_caused_by_av", "rear_end_by_human", "min_gap_m", "pet_s",
                "min_ttc_s", "shield_interventions", "av_max_brake_mps2"):
        assert key in s
    assert s["min_gap_m"] > 0.0 and not s["collision_caused_by_av"]
    assert s["av_max_brake_mps2"] == pytest.approx(-min(0.0, rec.log["av_accel_mps2"].min()))


# -- the shield in the planner API, the study and the command line -----------------------------


def test_planner_reports_the_shield():
    """A planner that does not anticipate the shield (the cv planner, shield_aware off) has
    some of its proposals overridden; an override applies a fallback and says so."""
    config = Config(mode="corrected").with_overrides({"av.kind": "cv",
                                                      "mpc.shield_aware": False})
    overridden = 0
    for s_av in np.linspace(-14.0, -8.0, 13):
        plan = Planner(config).plan(av=(float(s_av), 6.0), hv=(-15.0, 4.0))
        assert plan.shield_verdict in ("admitted", "brake", "go", "uncertified")
        if plan.shielded:
            overridden += 1
            assert plan.shield_verdict != "admitted" and plan.accel_mps2 in (-2.0, 1.0)
        else:
            assert plan.accel_mps2 == plan.proposed_accel_mps2
    assert overridden > 0
    off = Planner(Config(mode="corrected").with_overrides({"av.shield": "off"}))
    p = off.plan(av=(-12.76, 6.0), hv=(-15.0, 4.0))
    assert p.shield_verdict is None and not p.shielded and p.accel_mps2 == p.proposed_accel_mps2


def test_compare_puts_shields_side_by_side(tmp_path):
    from persuasive.studies import compare as cmp

    base = Config(mode="corrected")
    result = cmp.run_comparison(base, ("persuasive",), ("adversary", "lfg"), seeds=4,
                                out=tmp_path / "c", workers=1, timing_seeds=1,
                                shields=("off", "worst-case"))
    rows = {(r["shield"], r["hv"]): r for r in result.summary["rows"]}
    assert set(rows) == {("off", "adversary"), ("off", "lfg"), ("worst-case", "adversary"),
                         ("worst-case", "lfg")}
    assert rows[("worst-case", "adversary")]["collisions_caused_by_av"] == 0
    assert rows[("off", "adversary")]["collisions_caused_by_av"] > 0
    for hv in ("adversary", "lfg"):  # the guarantee, row by row
        on_row, off_row = rows[("worst-case", hv)], rows[("off", hv)]
        assert on_row["uncertified_steps"] == 0 and on_row["guarantee_held_runs"] == 4
        assert off_row["guarantee_held_runs"] == 0
    (diff,) = [p for p in result.summary["paired_shield"] if p["hv"] == "adversary"]
    runs = result.runs
    on = runs[(runs["av.shield"] == "worst-case") & (runs["hv.kind"] == "adversary")]
    off = runs[(runs["av.shield"] == "off") & (runs["hv.kind"] == "adversary")]
    expected = 100 * (on.set_index("seed")["collision_caused_by_av"].astype(float)
                      - off.set_index("seed")["collision_caused_by_av"].astype(float)).mean()
    assert diff["collision_pct"]["mean"] == pytest.approx(expected)
    text = cmp.to_markdown(result.summary)
    assert "| persuasive | worst-case | adversary |" in text and "shield minus off" in text


def test_study_and_sweep_take_a_shield(tmp_path):
    from persuasive.sweep import Grid
    from persuasive.web.study import default_study

    study = default_study().with_shield("responsive")
    assert all(c.config.shield == "responsive" for c in study.conditions)
    grid_file = tmp_path / "g.toml"
    grid_file.write_text('seeds = 2\n[base]\nmode = "corrected"\n[axes]\n"roles.p_a" = [0.5]\n')
    assert Grid.from_toml(grid_file, {"av.shield": "off"}).base.shield == "off"
    grid_file.write_text('seeds = 2\n[axes]\n"av.shield" = ["off", "worst-case"]\n')
    from persuasive.config import ConfigError

    with pytest.raises(ConfigError, match="av.shield is an axis"):
        Grid.from_toml(grid_file, {"av.shield": "off"})


def test_the_command_line_takes_a_shield(capsys):
    import json

    from _cli import run_cli

    def run(*args):
        return run_cli(capsys, *args)

    code, out, _ = run("simulate", "--mode", "corrected", "--hv", "adversary", "--seed", "3",
                       "--shield", "off", "--json")
    unshielded = json.loads(out)
    code2, out2, _ = run("simulate", "--mode", "corrected", "--hv", "adversary", "--seed", "3",
                         "--json")
    shielded = json.loads(out2)
    assert code == code2 == 0
    assert unshielded["collision_caused_by_av"] and not shielded["collision_caused_by_av"]
    assert shielded["shield_interventions"] >= 0 and shielded["min_gap_m"] > 0
    for args in (("simulate", "--shield", "maybe"), ("compare", "--shield", "off,bogus")):
        code, out, err = run(*args)
        assert code == 2 and out == "" and err.startswith("error: ") and "shield" in err
        assert err.count("\n") == 1
