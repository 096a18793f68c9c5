"""Belief update, plausible role, role transition (spec section 5).

Layer 3 (hypothesis) with a few hand cases. W = diag(0.03, 0.01) as in the paper. Tolerances:
belief sums within 1e-12 of 1; a flat likelihood returns the prior exactly for (0.5, 0.5) and
within 1e-15 otherwise; transition columns sum to 1 within 1e-15 (one rounding of 1 - p_a).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from persuasive import reference
from persuasive.roles import (FOLLOWER, LEADER, bayes_update, gaussian_density,
                              next_role, plausible_leader, transition_matrix)

W_S, W_V = 0.03, 0.01
finite = dict(allow_nan=False, allow_infinity=False)

priors = st.floats(0.01, 0.99, **finite)
# Residuals [m, m/s] whose densities are normal doubles (quadratic form below ~600).
moderate = st.floats(0.0, 3.0, **finite)
# ... and residuals that make both densities underflow to 0 (quadratic form above ~745).
huge = st.floats(50.0, 1e6, **finite)
residuals = st.one_of(moderate, huge)


def update(prior_l, e_l, e_f, prior_f=None):
    prior_f = 1.0 - prior_l if prior_f is None else prior_f
    return bayes_update(float(prior_l), float(prior_f), float(e_l[0]), float(e_l[1]),
                        float(e_f[0]), float(e_f[1]), W_S, W_V)


def quad(e):
    return e[0] ** 2 / W_S + e[1] ** 2 / W_V


# -- Bayes update -------------------------------------------------------------------------------


def test_density_by_hand():
    # N(0; 0, W) = 1 / (2 pi sqrt(0.03 * 0.01)); at (0.1, 0.1): times exp(-0.5 (1/3 + 1))
    peak = 1.0 / (2.0 * math.pi * math.sqrt(3e-4))
    assert gaussian_density(0.0, 0.0, W_S, W_V) == pytest.approx(peak, rel=1e-15)
    assert gaussian_density(0.1, 0.1, W_S, W_V) == pytest.approx(
        peak * math.exp(-2.0 / 3.0), rel=1e-14)


def test_update_by_hand():
    # prior (0.5, 0.5); residual (0.1, 0) for L, (0, 0.1) for F:
    # likelihood ratio L/F = exp(-0.5 (0.01/0.03)) / exp(-0.5 (0.01/0.01)) = exp(1/3)
    b_l, b_f = update(0.5, (0.1, 0.0), (0.0, 0.1))
    ratio = math.exp(1.0 / 3.0)
    assert b_l == pytest.approx(ratio / (1.0 + ratio), abs=1e-15)
    assert b_f == pytest.approx(1.0 / (1.0 + ratio), abs=1e-15)


@settings(max_examples=300)
@given(priors, st.tuples(residuals, residuals), st.tuples(residuals, residuals))
def test_belief_stays_a_probability_vector(prior_l, e_l, e_f):
    b_l, b_f = update(prior_l, e_l, e_f)
    assert not (math.isnan(b_l) or math.isnan(b_f))
    assert b_l >= 0.0 and b_f >= 0.0
    assert abs(b_l + b_f - 1.0) <= 1e-12


def test_both_likelihoods_underflow_the_smaller_residual_wins():
    assert gaussian_density(1e3, 0.0, W_S, W_V) == 0.0  # both products underflow
    assert update(0.5, (1e3, 0.0), (2e3, 0.0)) == (1.0, 0.0)
    assert update(0.5, (2e3, 0.0), (1e3, 0.0)) == (0.0, 1.0)
    assert update(0.5, (1e3, 1e3), (1e3, 1e3)) == (0.5, 0.5)


@settings(max_examples=200)
@given(st.tuples(residuals, residuals))
def test_flat_likelihood_keeps_the_even_prior_exactly(e):
    assert update(0.5, e, e) == (0.5, 0.5)


@settings(max_examples=200)
@given(priors, st.tuples(moderate, moderate))
def test_flat_likelihood_keeps_the_prior(prior_l, e):
    b_l, b_f = update(prior_l, e, e)
    assert abs(b_l - prior_l) <= 1e-15
    assert abs(b_f - (1.0 - prior_l)) <= 1e-15


@pytest.mark.parametrize("e", [100.0, 1e6])
def test_flat_likelihood_keeps_the_prior_when_both_likelihoods_underflow(e):
    b_l, _ = update(0.3, (e, 0.0), (e, 0.0))
    assert abs(b_l - 0.3) <= 1e-15


def test_flat_likelihood_keeps_the_prior_with_subnormal_likelihoods():
    e = math.sqrt(2.0 * W_S * 744.0)  # density ~ 1e-322
    assert 0.0 < gaussian_density(e, 0.0, W_S, W_V) < 2.3e-308
    b_l, _ = update(0.3, (e, 0.0), (e, 0.0))
    assert abs(b_l - 0.3) <= 1e-15


def test_never_nan_when_the_squares_overflow():
    b_l, b_f = update(0.5, (1e200, 0.0), (1e200, 0.0))
    assert not (math.isnan(b_l) or math.isnan(b_f))


@settings(max_examples=300)
@given(priors, st.tuples(moderate, moderate), st.tuples(moderate, moderate))
def test_the_role_with_the_smaller_residual_gains_probability(prior_l, e_l, e_f):
    assume(quad(e_l) != quad(e_f))
    b_l, b_f = update(prior_l, e_l, e_f)
    # never loses more than rounding (1e-15: equal likelihoods in floating point give the
    # prior back up to normalisation), and gains strictly when the likelihoods clearly differ
    if quad(e_l) < quad(e_f):
        assert b_l >= prior_l - 1e-15 and b_f <= (1.0 - prior_l) + 1e-15
        if quad(e_f) - quad(e_l) > 1e-6:
            assert b_l > prior_l and b_f < 1.0 - prior_l
    else:
        assert b_l <= prior_l + 1e-15 and b_f >= (1.0 - prior_l) - 1e-15
        if quad(e_l) - quad(e_f) > 1e-6:
            assert b_l < prior_l and b_f > 1.0 - prior_l


@settings(max_examples=100)
@given(priors, st.tuples(residuals, residuals), st.tuples(residuals, residuals))
def test_reference_bayes_is_the_same_computation(prior_l, e_l, e_f):
    assert reference.bayes_update(prior_l, 1.0 - prior_l, e_l, e_f, W_S, W_V) == update(
        prior_l, e_l, e_f)


# -- plausible role -----------------------------------------------------------------------------


def test_plausible_role_rules():
    assert plausible_leader(0.7, 0.3, LEADER) == 0.0  # the other likely leads: I follow
    assert plausible_leader(0.7, 0.3, FOLLOWER) == 0.0
    assert plausible_leader(0.3, 0.7, LEADER) == 1.0  # the other likely follows: I lead
    assert plausible_leader(0.3, 0.7, FOLLOWER) == 1.0
    assert plausible_leader(0.5, 0.5, LEADER) == 1.0  # exact tie: my own role
    assert plausible_leader(0.5, 0.5, FOLLOWER) == 0.0
    # one ulp away from the tie is not a tie
    assert plausible_leader(math.nextafter(0.5, 1.0), 0.5, LEADER) == 0.0
    assert plausible_leader(0.5, math.nextafter(0.5, 1.0), FOLLOWER) == 1.0


@settings(max_examples=200)
@given(st.floats(0.0, 1.0, **finite), st.floats(0.0, 1.0, **finite),
       st.sampled_from([LEADER, FOLLOWER]))
def test_plausible_role_matches_the_reference(b_l, b_f, own):
    got = plausible_leader(b_l, b_f, own)
    assert got in (0.0, 1.0)
    assert got == reference.plausible_leader(b_l, b_f, own == LEADER)
    if b_l != b_f:
        assert got == (1.0 if b_l < b_f else 0.0)


# -- transition matrix and next role ------------------------------------------------------------

p_as = st.one_of(st.sampled_from([0.0, 0.3, 0.5, 0.7, 1.0]), st.floats(0.0, 1.0, **finite))


@settings(max_examples=200)
@given(st.one_of(st.sampled_from([0.0, 1.0]), st.floats(0.0, 1.0, **finite)), p_as)
def test_transition_matrix_is_column_stochastic(pl, p_a):
    Pi = transition_matrix(pl, p_a)
    assert Pi.shape == (2, 2)
    assert np.all((Pi >= 0.0) & (Pi <= 1.0))
    np.testing.assert_allclose(Pi.sum(axis=0), [1.0, 1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(Pi, reference.transition_matrix(pl, p_a), rtol=0, atol=1e-15)


@pytest.mark.parametrize("pl", [0.0, 1.0])
def test_transition_with_fixed_roles(pl):
    # p_a = 0: nobody changes role, whatever the plausible role
    np.testing.assert_array_equal(transition_matrix(pl, 0.0), np.eye(2))


def test_transition_with_p_a_1():
    # p_a = 1: everyone takes the plausible role with certainty
    np.testing.assert_array_equal(transition_matrix(1.0, 1.0), [[1.0, 1.0], [0.0, 0.0]])
    np.testing.assert_array_equal(transition_matrix(0.0, 1.0), [[0.0, 0.0], [1.0, 1.0]])


def test_transition_by_hand():
    # plausible L, p_a = 0.3: a leader stays (1), a follower becomes leader w.p. 0.3
    np.testing.assert_allclose(transition_matrix(1.0, 0.3), [[1.0, 0.3], [0.0, 0.7]],
                               rtol=0, atol=1e-15)
    # plausible F, p_a = 0.3: a leader becomes follower w.p. 0.3, a follower stays
    np.testing.assert_allclose(transition_matrix(0.0, 0.3), [[0.7, 0.0], [0.3, 1.0]],
                               rtol=0, atol=1e-15)


def test_next_role_thresholds():
    Pi = transition_matrix(0.0, 0.3)  # Pi[L, L] = 0.7, Pi[F, F] = 1
    ll = Pi[0, 0]
    assert next_role(LEADER, ll, Pi) == LEADER  # r == Pi[L, L]: no change
    assert next_role(LEADER, math.nextafter(ll, 1.0), Pi) == FOLLOWER
    assert next_role(LEADER, math.nextafter(ll, 0.0), Pi) == LEADER
    assert next_role(FOLLOWER, 0.999999, Pi) == FOLLOWER  # Pi[F, F] = 1: never leaves
    Pi = transition_matrix(1.0, 0.3)  # Pi[F, F] = 0.7, Pi[L, L] = 1
    ff = Pi[1, 1]
    assert next_role(FOLLOWER, ff, Pi) == FOLLOWER
    assert next_role(FOLLOWER, math.nextafter(ff, 1.0), Pi) == LEADER
    assert next_role(LEADER, 0.999999, Pi) == LEADER


@settings(max_examples=200)
@given(st.sampled_from([0.0, 1.0]), p_as, st.sampled_from([LEADER, FOLLOWER]),
       st.floats(0.0, 1.0, exclude_min=True, exclude_max=True, **finite))
def test_next_role_follows_the_diagonal(pl, p_a, role, r):
    Pi = transition_matrix(pl, p_a)
    changed = next_role(role, r, Pi) != role
    assert changed == (r > Pi[role, role])
