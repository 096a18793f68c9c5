"""The constant-acceleration step with speed saturation (spec section 1).

Layer 1 (hand-computed steps) and layer 3 (hypothesis invariants, agreement with the NumPy
reference). Default limits: v_min = 0, v_max = 10 m/s, dt = 0.1 s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive import reference
from persuasive.kinematics import saturated_step

V_MIN, V_MAX, DT = 0.0, 10.0, 0.1
TOL = 1e-12  # [m] or [m/s]: hand values written in decimal vs. binary floating point


def step(s, v, a, dt=DT, v_min=V_MIN, v_max=V_MAX):
    return saturated_step(float(s), float(v), float(a), float(dt), float(v_min), float(v_max))


# -- layer 1: hand-computed steps ---------------------------------------------------------------


@pytest.mark.parametrize("s, v", [(-20.0, 4.0), (-3.25, 7.5), (0.0, 0.0), (12.0, 10.0)])
def test_pure_cruise_is_exact(s, v):
    # a = 0 takes the last branch: ds = v dt + 0, no division anywhere.
    s1, v1 = step(s, v, 0.0)
    assert v1 == v
    assert s1 == s + v * DT


def test_normal_step():
    # v' = 5 + 1 * 0.1 = 5.1; ds = 5 * 0.1 + 1 * 0.01 / 2 = 0.505
    s1, v1 = step(-20.0, 5.0, 1.0)
    assert v1 == pytest.approx(5.1, abs=TOL)
    assert s1 == pytest.approx(-20.0 + 0.505, abs=TOL)


def test_normal_braking_step():
    # v' = 4 - 2 * 0.1 = 3.8; ds = 0.4 - 2 * 0.01 / 2 = 0.39
    s1, v1 = step(-20.0, 4.0, -2.0)
    assert v1 == pytest.approx(3.8, abs=TOL)
    assert s1 == pytest.approx(-19.61, abs=TOL)


def test_hits_v_max_mid_step():
    # v = 9.95, a = 1: v_max is reached at t1 = 0.05 s, then the vehicle cruises 0.05 s.
    # ds = (100 - 99.0025) / 2 + 10 * 0.05 = 0.49875 + 0.5 = 0.99875
    s1, v1 = step(-20.0, 9.95, 1.0)
    assert v1 == V_MAX  # exact: the branch returns v_max itself
    assert s1 == pytest.approx(-20.0 + 0.99875, abs=TOL)
    # Not the unsaturated formula, which would give 9.95 * 0.1 + 0.005 = 1.0
    assert abs(s1 - (-20.0 + 1.0)) > 1e-4


def test_at_v_max_accelerating_cruises():
    # t1 = 0: ds = 0 / (2a) + v_max * dt = 1.0
    s1, v1 = step(-5.0, 10.0, 1.0)
    assert v1 == V_MAX
    assert s1 == pytest.approx(-4.0, abs=TOL)


def test_stops_mid_step():
    # v = 0.1, a = -2: stops at t1 = 0.05 s, ds = (0 - 0.01) / (-4) + 0 = 0.0025
    s1, v1 = step(-10.0, 0.1, -2.0)
    assert v1 == 0.0
    assert s1 == pytest.approx(-10.0 + 0.0025, abs=TOL)


def test_stays_stopped():
    # v = 0 and braking: v' = v_min, s unchanged (exactly)
    for a in (-2.0, -0.5, -1e-9):
        s1, v1 = step(-7.25, 0.0, a)
        assert v1 == 0.0
        assert s1 == -7.25


def test_reaches_positive_v_min_mid_step():
    # v_min = 1: v = 1.05, a = -1 reaches v_min at t1 = 0.05 s, then cruises at 1 m/s.
    # ds = (1 - 1.1025) / (-2) + 1 * 0.05 = 0.05125 + 0.05 = 0.10125
    s1, v1 = step(0.0, 1.05, -1.0, v_min=1.0)
    assert v1 == 1.0
    assert s1 == pytest.approx(0.10125, abs=TOL)


# -- layer 3: invariants ------------------------------------------------------------------------

finite = dict(allow_nan=False, allow_infinity=False)
positions = st.floats(-100.0, 100.0, **finite)
limits = st.tuples(st.floats(0.0, 3.0, **finite), st.floats(1.0, 20.0, **finite)).map(
    lambda t: (t[0], t[0] + t[1])
)


@st.composite
def step_inputs(draw):
    v_min, v_max = draw(st.one_of(st.just((V_MIN, V_MAX)), limits))
    v = draw(st.one_of(st.sampled_from([v_min, v_max]), st.floats(v_min, v_max, **finite)))
    a = draw(st.one_of(st.sampled_from([0.0, -2.0, 1.0]), st.floats(-10.0, 10.0, **finite)))
    dt = draw(st.one_of(st.just(DT), st.floats(1e-3, 2.0, **finite)))
    return draw(positions), v, a, dt, v_min, v_max


@settings(max_examples=300)
@given(step_inputs())
def test_speed_stays_within_limits_and_s_never_decreases(args):
    s, v, a, dt, v_min, v_max = args
    s1, v1 = step(*args)
    assert math.isfinite(s1) and math.isfinite(v1)
    assert v_min <= v1 <= v_max
    assert s1 >= s


# The reference evaluates every branch (then picks one); a tiny |a| overflows an unused one.
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@settings(max_examples=300)
@given(step_inputs())
def test_compiled_step_equals_reference_bit_for_bit(args):
    s1, v1 = step(*args)
    s_ref, v_ref = reference.saturated_step(*args)
    assert (s1, v1) == (float(s_ref), float(v_ref))


def test_reference_step_is_elementwise():
    # The reference is vectorised: one call over several vehicles equals the scalar steps.
    s = np.array([-20.0, -20.0, -10.0, -7.25])
    v = np.array([5.0, 9.95, 0.1, 0.0])
    a = np.array([1.0, 1.0, -2.0, -2.0])
    s1, v1 = reference.saturated_step(s, v, a, DT, V_MIN, V_MAX)
    for k in range(4):
        assert (s1[k], v1[k]) == step(s[k], v[k], a[k])
