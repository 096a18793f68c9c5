"""Uniform measurement noise as state sets in the shield (docs/method.md §12.2).

With ``simulation.measurement_noise = "uniform"`` every measured state stands for the box of
true states within the noise's half-widths; the shield certifies against the whole box. Layers:
a verdict on the box implies the verdict on every true state in it (hypothesis); without noise
nothing changes; closed loops in which every step was certified have no AV-caused collision.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive import Config
from persuasive.record import static_setup
from persuasive.safety import shield as sh
from persuasive.simulation import simulate

DS, DV = 0.3, 0.3


def conflict(scenario: str, ds: float, dv: float) -> np.ndarray:
    config = Config(mode="corrected").with_overrides({
        "scenario.kind": scenario, "simulation.measurement_noise": "uniform",
        "simulation.noise_s_m": ds, "simulation.noise_v_mps": dv})
    _, P_av, P_hv, _ = static_setup(config)
    C = np.empty(sh.N_CONFLICT)
    sh.conflict_vector(P_av, P_hv, C)
    return C


def test_the_box_is_packed_only_for_uniform_noise():
    C = conflict("intersection", DS, DV)
    assert C[sh.C_MEAS_S] == pytest.approx(DS) and C[sh.C_MEAS_S] >= DS
    assert C[sh.C_MEAS_V] >= DV
    gaussian = Config(mode="corrected").with_overrides({
        "simulation.measurement_noise": "gaussian", "simulation.noise_s_m": DS})
    _, P_av, P_hv, _ = static_setup(gaussian)
    C2 = np.empty(sh.N_CONFLICT)
    sh.conflict_vector(P_av, P_hv, C2)
    assert C2[sh.C_MEAS_S] == 0.0 == C2[sh.C_MEAS_V]  # unbounded: outside the guarantee


@settings(max_examples=300, deadline=None)
@given(scenario=st.sampled_from(["intersection", "left-turn", "merge"]),
       s_R=st.floats(-25.0, 8.0), v_R=st.floats(0.0, 10.0), s_H=st.floats(-25.0, 8.0),
       v_H=st.floats(0.0, 10.0), a=st.sampled_from([-2.0, -1.0, 0.0, 0.5, 1.0]),
       fallback=st.sampled_from([-2.0, 1.0]), corner=st.tuples(*[st.floats(-1.0, 1.0)] * 4))
def test_a_verdict_on_the_box_holds_for_every_state_in_it(scenario, s_R, v_R, s_H, v_H, a,
                                                          fallback, corner):
    """Soundness of the set: certified from the measured states with the box implies
    certified from any true state in the box without one (the true state is certified)."""
    C = conflict(scenario, DS, DV)
    exact = C.copy()
    exact[sh.C_MEAS_S] = exact[sh.C_MEAS_V] = 0.0
    if not sh.certified(s_R, v_R, a, 0.1, fallback, s_H, v_H, C,
                        *sh.human_window(s_H, v_H, C)):
        return
    u = np.asarray(corner)
    tR = (s_R + u[0] * DS, min(max(v_R + u[1] * DV, 0.0), 10.0))
    tH = (s_H + u[2] * DS, min(max(v_H + u[3] * DV, 0.0), 10.0))
    assert sh.certified(*tR, a, 0.1, fallback, *tH, exact, *sh.human_window(*tH, exact)), \
        (scenario, (s_R, v_R), (s_H, v_H), tR, tH)


def test_the_humans_window_is_its_corners():
    """The box's window: the earliest arrival is the exact one of the furthest and fastest
    corner, the latest exit that of the nearest and slowest, and a human past its interval
    only when even its nearest corner is."""
    C = conflict("intersection", DS, DV)
    exact = C.copy()
    exact[sh.C_MEAS_S] = exact[sh.C_MEAS_V] = 0.0
    ds, dv = C[sh.C_MEAS_S], C[sh.C_MEAS_V]
    rng = np.random.default_rng(3)
    for _ in range(200):
        s, v = rng.uniform(-20.0, 2.0), rng.uniform(0.5, 9.5)
        t_in, t_out, past = sh.human_window(s, v, C)
        assert t_in == sh.human_window(s + ds, v + dv, exact)[0]
        assert t_out == sh.human_window(s - ds, v - dv, exact)[1]
        assert past == (s - ds > C[sh.C_H_HI])
    # without noise the box is the state: the same window as the exact check
    C0 = conflict("intersection", 0.0, 0.0)
    assert C0[sh.C_MEAS_S] == 0.0 == C0[sh.C_MEAS_V]
    assert sh.human_window(-7.0, 4.0, C0) == sh.human_window(-7.0, 4.0, exact)


def test_a_box_certifies_less_than_its_centre():
    """The set is not the point: a state certified exactly can fail with the box around it."""
    C = conflict("intersection", DS, DV)
    exact = C.copy()
    exact[sh.C_MEAS_S] = exact[sh.C_MEAS_V] = 0.0
    found = False
    rng = np.random.default_rng(8)
    for _ in range(2000):
        s_R, v_R, s_H, v_H = rng.uniform([-12, 0, -12, 0], [0, 8, 0, 8])
        args = (s_R, v_R, 1.0, 0.1, 1.0, s_H, v_H)
        if sh.certified(*args, exact, *sh.human_window(s_H, v_H, exact)) and not \
                sh.certified(*args, C, *sh.human_window(s_H, v_H, C)):
            found = True
            break
    assert found


@pytest.mark.parametrize("human", ["adversary", "random", "aggressive"])
def test_certified_runs_under_uniform_noise_cause_no_collision(human):
    """Closed loops with 0.3 m and 0.3 m/s of uniform measurement noise: a run every step of
    which was certified against the boxes has no AV-caused collision, and says so."""
    config = Config(mode="corrected").with_overrides({
        "av.kind": "cv", "hv.kind": human, "simulation.measurement_noise": "uniform",
        "simulation.noise_s_m": DS, "simulation.noise_v_mps": DV})
    held = 0
    for seed in range(1, 41):
        o = simulate(config, seed).outcome
        assert o.guarantee_held == (o.uncertified_steps == 0)
        if o.guarantee_held:
            held += 1
            assert not o.collision_caused_by_av, seed
    assert held >= 30
