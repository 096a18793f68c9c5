"""Rewards along the trajectories (spec section 3).

Layer 1: tiny hand-made libraries whose rewards are computed by hand from
``R = sum_k lambda^(k-1) ((s_k - s_0) - w_c [d_k < 7.5] (1 + v_k) - w_u |u_k|)``
(w_c = 100, w_u = 0.1, lambda = 0.99). Layer 3: the exact distance threshold, and agreement with
the NumPy reference bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive import reference
from persuasive.library import Library, trajectory_library
from persuasive.packing import MIN_DIST_SQ, W_C as W_C_SLOT, sqrt_threshold
from persuasive.rewards import reward_matrix, reward_matrix_of, reward_terms, zone_windows

W_C, W_U, LAM = 100.0, 0.1, 0.99
TOL = 1e-12  # relative: hand sums in decimal vs. the kernel's sums in binary

finite = dict(allow_nan=False, allow_infinity=False)


def rewards(own: Library, other: Library, disc, pk) -> np.ndarray:
    """``R[own, other]`` with the AV's vector for ``own`` and the HV's for ``other``."""
    return reward_matrix_of(own, other, disc, pk.P_av, pk.P_hv)


def make_lib(s, v, a, s0, v0=0.0) -> Library:
    """A library from trajectory-major rows ``(n_traj, n)``."""
    s, v, a = (np.atleast_2d(np.asarray(x, float)) for x in (s, v, a))
    return Library(s, v, a, float(s0), float(v0), False)


def naive(own: Library, other: Library, disc) -> np.ndarray:
    """The spec's formula, one sample at a time, with ``math.sqrt``."""
    out = np.empty((own.s.shape[0], other.s.shape[0]))
    for m in range(own.s.shape[0]):
        for b in range(other.s.shape[0]):
            total = 0.0
            for k in range(own.s.shape[1]):
                d = math.sqrt(own.s[m, k] ** 2 + other.s[b, k] ** 2)
                c = (1.0 + own.v[m, k]) if d < 7.5 else 0.0
                total += disc[k] * ((own.s[m, k] - own.s0) - W_C * c - W_U * abs(own.a[m, k]))
            out[m, b] = total
    return out


# -- layer 1: hand-made cases -------------------------------------------------------------------


def test_collision_free_reward_by_hand(paper):
    # Own: constant 2 m/s from -30 with |u| = 0.5: s_k - s_0 = 0.2 k. Other: standing at -30.
    # R = (0.2 + 0.99 * 0.4 + 0.9801 * 0.6) - 0.1 * 0.5 * (1 + 0.99 + 0.9801)
    #   = 1.18406 - 0.148505 = 1.035555
    own = make_lib([-29.8, -29.6, -29.4], [2.0, 2.0, 2.0], [0.5, -0.5, 0.5], s0=-30.0, v0=2.0)
    other = make_lib([-30.0, -30.0, -30.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], s0=-30.0)
    R = rewards(own, other, paper.disc[:3], paper)
    assert R.shape == (1, 1)
    assert R[0, 0] == pytest.approx(1.035555, rel=TOL)


def test_rows_are_own_trajectories_columns_the_others(paper):
    # Two own trajectories (fast, slow), three far-away others: every row is constant.
    own = make_lib([[-29.0, -28.0], [-29.9, -29.8]], [[10.0, 10.0], [1.0, 1.0]], np.zeros((2, 2)),
                   s0=-30.0)
    other = make_lib(np.full((3, 2), -40.0), np.zeros((3, 2)), np.zeros((3, 2)), s0=-40.0)
    R = rewards(own, other, paper.disc[:2], paper)
    assert R.shape == (2, 3)
    np.testing.assert_allclose(R[0], 1.0 + 0.99 * 2.0, rtol=TOL)
    np.testing.assert_allclose(R[1], 0.1 + 0.99 * 0.2, rtol=TOL)


def test_collision_penalty_by_hand(paper):
    # Own passes the conflict point while the other stands at -3:
    # d_k = sqrt(s_k^2 + 9) = 10.44, 5.83, 3.61, 3.16, 8.54 -> samples 2, 3, 4 unsafe.
    s = [-10.0, -5.0, -2.0, 1.0, 8.0]
    v = [3.0, 2.0, 1.0, 0.5, 4.0]
    a = [-1.0, -1.0, -0.5, 0.5, 1.0]
    own = make_lib(s, v, a, s0=-13.0)
    near = make_lib([-3.0] * 5, [0.0] * 5, [0.0] * 5, s0=-3.0)
    far = make_lib([-30.0] * 5, [0.0] * 5, [0.0] * 5, s0=-30.0)
    disc = paper.disc[:5]
    R_near = rewards(own, near, disc, paper)[0, 0]
    R_far = rewards(own, far, disc, paper)[0, 0]
    # collision-free base: sum lambda^(k-1) ((s_k + 13) - 0.1 |u_k|)
    base = sum(LAM**k * ((s[k] + 13.0) - W_U * abs(a[k])) for k in range(5))
    assert R_far == pytest.approx(base, rel=TOL)
    # penalty: 100 (0.99 (1 + 2) + 0.99^2 (1 + 1) + 0.99^3 (1 + 0.5)) = 638.56485
    assert R_far - R_near == pytest.approx(638.56485, rel=TOL)


def test_distance_exactly_min_dist_is_safe(paper):
    # 4.5^2 + 6^2 = 56.25 = 7.5^2 exactly: d = 7.5 is not < 7.5, so no penalty;
    # one ulp closer is unsafe.
    own = make_lib([4.5], [1.0], [0.0], s0=4.4)
    at = make_lib([6.0], [0.0], [0.0], s0=6.0)
    closer = make_lib([np.nextafter(6.0, 0.0)], [0.0], [0.0], s0=6.0)
    R_at = rewards(own, at, paper.disc[:1], paper)[0, 0]
    R_closer = rewards(own, closer, paper.disc[:1], paper)[0, 0]
    assert R_at == pytest.approx(0.1, rel=TOL)
    assert R_closer == pytest.approx(0.1 - W_C * 2.0, rel=TOL)


def test_unsafe_samples_apart_are_all_counted(paper):
    # Own enters the zone, leaves it, re-enters: samples 1 and 3 unsafe, 2 safe, and the
    # other's two trajectories have different zone samples. Penalties by hand:
    # other 0 (at 0 throughout): 100 (1 + 1) + 100 * 0.9801 (1 + 3) = 592.04
    # other 1 (far, near, near): 100 * 0.9801 (1 + 3) = 392.04
    own = make_lib([-2.0, -20.0, -2.0], [1.0, 2.0, 3.0], [0.0, 0.0, 0.0], s0=-2.0)
    other = make_lib([[0.0, 0.0, 0.0], [-30.0, -1.0, 1.0]], np.zeros((2, 3)), np.zeros((2, 3)),
                     s0=0.0)
    R = rewards(own, other, paper.disc[:3], paper)[0]
    base = 0.0 + 0.99 * (-18.0) + 0.0
    np.testing.assert_allclose(R, [base - 592.04, base - 392.04], rtol=TOL)


@st.composite
def small_library_pairs(draw):
    """Arbitrary (not OVM) trajectories inside +-12 m, so that the zone is often entered."""
    n = draw(st.integers(1, 8))
    n_own, n_other = draw(st.integers(1, 4)), draw(st.integers(1, 4))
    pos = st.floats(-12.0, 12.0, **finite)

    def arr(shape, elems):
        return np.array(draw(st.lists(elems, min_size=shape[0] * shape[1],
                                      max_size=shape[0] * shape[1]))).reshape(shape)

    own = make_lib(arr((n_own, n), pos), arr((n_own, n), st.floats(0.0, 10.0, **finite)),
                   arr((n_own, n), st.floats(-2.0, 1.0, **finite)), s0=draw(pos))
    other = make_lib(arr((n_other, n), pos), np.zeros((n_other, n)), np.zeros((n_other, n)),
                     s0=0.0)
    return own, other


@settings(max_examples=100)
@given(small_library_pairs())
def test_matches_a_straightforward_sum(paper, pair):
    own, other = pair
    n = own.s.shape[1]
    got = rewards(own, other, paper.disc[:n], paper)
    # absolute 1e-9 [reward units] on values up to ~1e4: the two sums group terms differently
    np.testing.assert_allclose(got, naive(own, other, paper.disc), rtol=TOL, atol=1e-9)


@settings(max_examples=100)
@given(small_library_pairs())
def test_arbitrary_trajectories_equal_reference_bit_for_bit(paper, pair):
    own, other = pair
    n = own.s.shape[1]
    got = rewards(own, other, paper.disc[:n], paper)
    ref = reference.reward_matrix(own.s, own.v, own.a, own.s0, other.s, paper.disc[:n],
                                  paper.P_av, paper.P_hv)
    np.testing.assert_array_equal(got, ref)


# -- layer 3: the exact threshold and the reference ---------------------------------------------


def neighbours(x: float, k: int = 4):
    lo, hi = [x], [x]
    for _ in range(k):
        lo.append(math.nextafter(lo[-1], -math.inf))
        hi.append(math.nextafter(hi[-1], math.inf))
    return lo[1:] + [x] + hi[1:]


def test_sqrt_threshold_for_min_dist(paper):
    thr = sqrt_threshold(7.5)
    assert thr == 56.25  # sqrt(56.25) = 7.5 and sqrt of the double below rounds below 7.5
    assert paper.P[MIN_DIST_SQ] == thr
    for x in neighbours(thr):
        assert (x < thr) == (math.sqrt(x) < 7.5), x


@settings(max_examples=200)
@given(st.floats(1e-3, 1e3, **finite))
def test_sqrt_threshold_agrees_with_sqrt(c):
    thr = sqrt_threshold(c)
    for x in neighbours(thr) + neighbours(c * c):
        assert (x < thr) == (math.sqrt(x) < c), (c, x)


@st.composite
def joint_states(draw):
    s_a = draw(st.floats(-30.0, 5.0, **finite))
    s_b = draw(st.one_of(st.just(s_a), st.floats(-30.0, 5.0, **finite)))
    v_a = draw(st.floats(0.0, 10.0, **finite))
    v_b = draw(st.one_of(st.just(v_a), st.floats(0.0, 10.0, **finite)))
    return (s_a, v_a), (s_b, v_b)


@settings(max_examples=60)
@given(joint_states())
def test_library_pairs_equal_reference_bit_for_bit(paper, states):
    (s_a, v_a), (s_b, v_b) = states
    own = trajectory_library(s_a, v_a, paper.P_av)
    other = trajectory_library(s_b, v_b, paper.P_hv)
    got = rewards(own, other, paper.disc, paper)
    ref = reference.reward_matrix(own.s, own.v, own.a, s_a, other.s, paper.disc, paper.P_av,
                                  paper.P_hv)
    assert got.shape == (11, 11)
    np.testing.assert_array_equal(got, ref)


# -- the kernel's parts: windows, positions, pair tests -----------------------------------------


def kernel_parts(lib: Library, disc, P):
    """:func:`reward_terms` of ``lib`` (sample-major, as the kernels store it)."""
    n_traj, n = lib.s.shape
    base, win = np.empty(n_traj), np.empty((n_traj, 2), np.int64)
    coll, pos = np.empty((n, n_traj)), np.full((2, n, n_traj), np.nan)
    reward_terms(np.ascontiguousarray(lib.s.T), np.ascontiguousarray(lib.v.T),
                 np.ascontiguousarray(lib.a.T), lib.s0, disc, P, base, coll, pos, win)
    return base, coll, pos, win


def test_reward_parts_and_pair_tests_by_hand(paper):
    # The case of test_unsafe_samples_apart_are_all_counted. s^2: own (4, 400, 4), others
    # (0, 0, 0) and (900, 1, 1); below 56.25: own samples 0 and 2, so its window is [0, 3)
    # (scanned from both ends: the safe sample 1 inside it stays), the others' [0, 3), [1, 3).
    own = make_lib([-2.0, -20.0, -2.0], [1.0, 2.0, 3.0], [0.0, 0.0, 0.0], s0=-2.0)
    other = make_lib([[0.0, 0.0, 0.0], [-30.0, -1.0, 1.0]], np.zeros((2, 3)), np.zeros((2, 3)),
                     s0=0.0)
    disc = paper.disc[:3]
    base, coll, pos, win = kernel_parts(own, disc, paper.P_av)
    _, _, pos_o, win_o = kernel_parts(other, disc, paper.P_hv)
    np.testing.assert_array_equal(pos[0, :, 0], [4.0, 400.0, 4.0])  # pos[0] = s^2
    np.testing.assert_array_equal(pos_o[0].T, [[0.0, 0.0, 0.0], [900.0, 1.0, 1.0]])
    np.testing.assert_array_equal(win, [[0, 3]])
    np.testing.assert_array_equal(win_o, [[0, 3], [1, 3]])
    # B = 0 + 0.99 (-18) + 0; weights lambda^(k-1) (1 + v_k) = 2, 0.99 * 3, 0.9801 * 4
    assert base[0] == pytest.approx(0.99 * -18.0, rel=TOL)
    np.testing.assert_allclose(coll[:, 0], [2.0, 2.97, 3.9204], rtol=TOL)
    C, out = np.empty((1, 2)), np.empty((1, 2))
    tests = reward_matrix(base, coll, pos, win, pos_o, win_o, paper.P[W_C_SLOT],
                          paper.P[MIN_DIST_SQ], True, C, out)
    # own window [0, 3) against the hull [0, 3) of the others': 3 samples x 2 trajectories
    assert tests == 6
    np.testing.assert_allclose(C[0], [5.9204, 3.9204], rtol=TOL)
    np.testing.assert_array_equal(out, rewards(own, other, disc, paper))


def test_pair_tests_skip_samples_outside_the_windows(paper):
    # Own inside the zone only at sample 3; the other's window covers samples 1..2: no
    # sample of both, so no pair test at all, and no penalty
    own = make_lib([-30.0, -20.0, -10.0, -1.0], np.ones(4), np.zeros(4), s0=-31.0)
    other = make_lib([-30.0, -1.0, 1.0, 30.0], np.zeros(4), np.zeros(4), s0=-31.0)
    disc = paper.disc[:4]
    base, coll, pos, win = kernel_parts(own, disc, paper.P_av)
    _, _, pos_o, win_o = kernel_parts(other, disc, paper.P_hv)
    np.testing.assert_array_equal(win, [[3, 4]])
    np.testing.assert_array_equal(win_o, [[1, 3]])
    C, out = np.empty((1, 1)), np.empty((1, 1))
    assert reward_matrix(base, coll, pos, win, pos_o, win_o, 100.0, 56.25, True, C, out) == 0
    assert C[0, 0] == 0.0 and out[0, 0] == base[0]


@settings(max_examples=200)
@given(st.lists(st.floats(0.0, 120.0, **finite), min_size=1, max_size=12))
def test_zone_windows_hold_every_unsafe_sample(squares):
    n = len(squares)
    pos = np.zeros((2, n, 1))
    pos[0, :, 0] = squares
    win = np.empty((1, 2), np.int64)
    zone_windows(pos, 56.25, win)
    inside = [k for k, x in enumerate(squares) if x < 56.25]
    lo, hi = win[0]
    if inside:  # the tightest window holding them all
        assert (lo, hi) == (inside[0], inside[-1] + 1)
    else:
        assert lo >= hi


@settings(max_examples=30)
@given(joint_states())
def test_unequal_vehicles_equal_reference_bit_for_bit(unequal, states):
    # each library built with its own vehicle's vector (conftest: the HV is smaller and
    # slower); both read the pair's safety distance 6.75 m
    (s_a, v_a), (s_b, v_b) = states
    v_b = min(v_b, 8.0)
    own = trajectory_library(s_a, v_a, unequal.P_av)
    other = trajectory_library(s_b, v_b, unequal.P_hv)
    for mine, theirs, P_m, P_t in ((own, other, unequal.P_av, unequal.P_hv),
                                   (other, own, unequal.P_hv, unequal.P_av)):
        got = reward_matrix_of(mine, theirs, unequal.disc, P_m, P_t)
        ref = reference.reward_matrix(mine.s, mine.v, mine.a, mine.s0, theirs.s, unequal.disc,
                                      P_m, P_t)
        np.testing.assert_array_equal(got, ref)
