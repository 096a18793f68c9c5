"""The persuasive branch MPC, one decision (spec section 6, quirks Q1, Q2, Q4), and the passive
planner that shares it (no role transition at T1).

Layer 3: the compiled :func:`persuasive.mpc.decide` equals the plain NumPy reference
(:func:`persuasive.reference.mpc`, every re-solve done separately) bit for bit, in both modes,
persuasive and passive, and with vehicles of different limits, on a fixed set of random states
(the reference is slow: ~0.1-0.3 s per decision), and its diagnostics satisfy the spec's
invariants on many more states (hypothesis, compiled only).
Tolerances: branch probabilities and beliefs sum to 1 within 1e-12; P(safe) lies in [0, 1]
within 1e-12 (it is a sum of four probabilities).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive import packing as slot
from persuasive import reference
from persuasive.game import EGO_FOLLOWER, EGO_LEADER, predict_into
from persuasive.library import new_lib, trajectory_library
from persuasive.mpc import (AHEAD_S, AHEAD_V, AHEAD_VALID, D_BELIEF_F, D_BELIEF_L, D_EXPECTED,
                            D_MAX_SAFE, D_MIN_SAFE, D_P_FF, D_P_LL, D_PLAUSIBLE_L, N_DIAG,
                            decide)
from persuasive.roles import LEADER, FOLLOWER, plausible_leader, transition_matrix

EPSILON = 0.02

# The reference's saturated step evaluates every branch (then picks one); a subnormal speed or
# acceleration overflows an unused branch, harmlessly.
pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
P_A_HATS = (1.0, 0.95, 0.7)


def _cases():
    """(x_R, x_H, q_l, tie_leader, p_a_hat): random states approaching the intersection,
    plus the paper's nominal start and two identical vehicles."""
    rng = np.random.default_rng(2026)
    cases = []
    for k in range(10):
        s_R, s_H = rng.uniform(-22.0, -5.0, 2)
        v_R, v_H = rng.uniform(0.0, 10.0, 2)
        cases.append(((float(s_R), float(v_R)), (float(s_H), float(v_H)),
                      float(rng.uniform(0.05, 0.95)), k % 2 == 0, P_A_HATS[k % 3]))
    cases.append(((-20.0, 4.0), (-18.0, 4.5), 0.5, True, 1.0))
    cases.append(((-12.0, 6.0), (-12.0, 6.0), 0.3, False, 0.95))
    return cases


CASES = _cases()


class Decision:
    """One compiled decision with everything it wrote."""

    def __init__(self, x_R, x_H, q_l, tie_leader, p_a_hat, pk, persuade=True):
        self.LH, self.LR = new_lib(50, 11), new_lib(50, 11)
        self.idx = np.empty(4, np.int64)
        self.work = np.zeros(slot.N_WORK, np.int64)
        predict_into(float(x_H[0]), float(x_H[1]), float(x_R[0]), float(x_R[1]), pk.P_hv,
                     pk.P_av, pk.disc, self.LH, self.LR, self.idx, np.empty((4, 11)),
                     np.zeros(slot.N_WORK, np.int64))
        self.diag = np.full((11, N_DIAG), np.nan)
        # scratch: the HV's libraries at T1, and the record of which states they hold
        self.LH1a, self.LH1b = new_lib(50, 11), new_lib(50, 11)
        self.ahead = np.full((2, 3), np.nan)
        c, feasible = decide(float(x_R[0]), float(x_R[1]), float(x_H[0]), float(x_H[1]),
                             self.LH, self.LR, self.idx, float(q_l), 1.0 - float(q_l),
                             bool(tie_leader), float(p_a_hat), persuade, pk.P_av, pk.P_hv,
                             pk.disc, self.diag, self.LH1a, self.LH1b, self.ahead, self.work,
                             np.ones(11, np.bool_))
        self.c, self.feasible = int(c), bool(feasible)


def compiled(x_R, x_H, q_l, tie_leader, p_a_hat, pk, persuade=True):
    """``decide`` fed as the closed loop feeds it: the human's full prediction of (x_H, x_R)."""
    d = Decision(x_R, x_H, q_l, tie_leader, p_a_hat, pk, persuade)
    return d.c, d.feasible, d.diag


def check_against_reference(case, pk, persuade):
    x_R, x_H, q_l, tie, p_a_hat = case
    c, feasible, diag = compiled(x_R, x_H, q_l, tie, p_a_hat, pk, persuade)
    c_ref, feasible_ref, diag_ref = reference.mpc(x_R, x_H, (q_l, 1.0 - q_l), tie, p_a_hat,
                                                  pk.P_av, pk.P_hv, pk.disc, persuade=persuade)
    assert (c, feasible) == (c_ref, feasible_ref)
    np.testing.assert_array_equal(diag, diag_ref)  # NaN (passive beliefs) equals NaN


@pytest.mark.parametrize("case", CASES, ids=[f"case{k}" for k in range(len(CASES))])
def test_decide_equals_reference_bit_for_bit(packed, case):
    check_against_reference(case, packed, persuade=True)


@pytest.mark.parametrize("case", CASES, ids=[f"case{k}" for k in range(len(CASES))])
def test_passive_decide_equals_reference_bit_for_bit(packed, case):
    check_against_reference(case, packed, persuade=False)


@pytest.mark.parametrize("case", CASES[::2], ids=[f"case{k}" for k in range(0, len(CASES), 2)])
def test_decide_with_unequal_vehicles_equals_reference_bit_for_bit(unequal, case):
    # conftest's ``unequal``: the HV 4 m long, v_max = 8 m/s, u_min = -3 m/s^2
    x_R, (s_H, v_H), *rest = case
    check_against_reference((x_R, (s_H, min(v_H, 8.0)), *rest), unequal, persuade=True)


def test_the_cases_exercise_the_chance_constraint(packed):
    # Guard against a vacuous comparison: the fixed cases include an infeasible decision, a
    # decision where only some candidates are feasible, and candidates whose plausible role
    # differs (the human's belief on the AV is not a tie for all of them).
    results = [compiled(*case, packed) for case in CASES]
    n_feasible = [int(np.sum(d[:, D_MIN_SAFE] > 1.0 - EPSILON)) for _, _, d in results]
    assert any(not f for _, f, _ in results)
    assert any(0 < n < 11 for n in n_feasible)
    assert any(len(set(d[:, D_PLAUSIBLE_L])) > 1 for _, _, d in results)
    assert len({c for c, _, _ in results}) >= 4


def test_modes_differ_somewhere(paper, corrected):
    # Q1/Q2 change the decision diagnostics: the two modes must not compute the same thing.
    differs = [not np.array_equal(compiled(*case, paper)[2], compiled(*case, corrected)[2])
               for case in CASES]
    assert any(differs)


# -- diagnostics invariants (compiled only) -----------------------------------------------------

finite = dict(allow_nan=False, allow_infinity=False)


@st.composite
def decisions(draw):
    s_R = draw(st.floats(-25.0, -3.0, **finite))
    s_H = draw(st.one_of(st.just(s_R), st.floats(-25.0, -3.0, **finite)))
    v_R = draw(st.floats(0.0, 10.0, **finite))
    v_H = draw(st.one_of(st.just(v_R), st.floats(0.0, 10.0, **finite)))
    q_l = draw(st.one_of(st.just(0.5), st.floats(0.01, 0.99, **finite)))
    return ((s_R, v_R), (s_H, v_H), q_l, draw(st.booleans()), draw(st.sampled_from(P_A_HATS)))


@settings(max_examples=150)
@given(decisions(), st.booleans())
def test_diagnostics_invariants(packed, case, persuade):
    x_R, x_H, q_l, tie, p_a_hat = case
    c, feasible, diag = compiled(x_R, x_H, q_l, tie, p_a_hat, packed, persuade)
    probs = diag[:, D_P_LL:D_P_FF + 1]
    q = (q_l, 1.0 - q_l)
    if persuade:
        assert not np.isnan(diag).any()
        # branch probabilities: P(i, j) = Pi_hat[j, i] q[i], summing to 1
        np.testing.assert_allclose(probs.sum(axis=1), 1.0, rtol=0, atol=1e-12)
        for k in range(11):
            b_l, b_f, pl = diag[k, D_BELIEF_L], diag[k, D_BELIEF_F], diag[k, D_PLAUSIBLE_L]
            assert abs(b_l + b_f - 1.0) <= 1e-12
            assert pl == plausible_leader(b_l, b_f, LEADER if tie else FOLLOWER)
            Pi = transition_matrix(pl, p_a_hat)
            np.testing.assert_array_equal(
                probs[k], [Pi[j, i] * q[i] for i in range(2) for j in range(2)])
    else:
        # passive: the human keeps its role after T1 (Pi_hat = I) and no belief is modelled
        assert np.isnan(diag[:, [D_BELIEF_L, D_BELIEF_F, D_PLAUSIBLE_L]]).all()
        assert not np.isnan(np.delete(diag, [D_BELIEF_L, D_BELIEF_F, D_PLAUSIBLE_L],
                                      axis=1)).any()
        np.testing.assert_array_equal(probs, np.tile([q[0], 0.0, 0.0, q[1]], (11, 1)))
    # P(safe) over the samples: min <= max, both probabilities
    lo, hi = diag[:, D_MIN_SAFE], diag[:, D_MAX_SAFE]
    assert np.all(lo <= hi)
    assert np.all((lo >= -1e-12) & (hi <= 1.0 + 1e-12))
    # the choice: best expected reward among the feasible (first on ties), else among all
    ok = lo > 1.0 - EPSILON
    assert feasible == bool(ok.any())
    pool = np.flatnonzero(ok) if ok.any() else np.arange(11)
    assert c == pool[np.argmax(diag[pool, D_EXPECTED])]
    assert diag[c, D_EXPECTED] == diag[pool, D_EXPECTED].max()


def test_without_collision_risk_every_candidate_is_safe(packed):
    # Far apart and slow: no branch ever comes within 7.5 m, so P(safe) = 1 everywhere and the
    # choice is the candidate with the best collision-free reward.
    d = Decision((-60.0, 2.0), (-60.0, 2.0), 0.5, True, 1.0, packed)
    c, feasible, diag = d.c, d.feasible, d.diag
    assert feasible
    np.testing.assert_allclose(diag[:, D_MIN_SAFE], 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(diag[:, D_MAX_SAFE], 1.0, rtol=0, atol=1e-12)
    assert c == int(np.argmax(diag[:, D_EXPECTED]))
    # and no re-solve can matter: all 2 x 11 (HV role, candidate) re-solves are skipped
    assert (d.work[slot.WORK_RESOLVES], d.work[slot.WORK_RESOLVES_SKIPPED]) == (0, 22)


@pytest.mark.parametrize("case", CASES, ids=[f"case{k}" for k in range(len(CASES))])
def test_lookahead_libraries_hold_the_hvs_states_at_t1(paper, case):
    # ahead[i] records the HV's role-i state one sample ahead and lib_h1a / lib_h1b hold its
    # library there (lib_h1b only when the role-F state differs from the role-L one): the
    # closed loop reuses them for the next step's prediction.
    d = Decision(*case, paper)
    states = [(d.LH.S[0, d.idx[r]], d.LH.V[0, d.idx[r]]) for r in (EGO_LEADER, EGO_FOLLOWER)]
    assert d.ahead[0, AHEAD_VALID] == 1.0
    assert (d.ahead[0, AHEAD_S], d.ahead[0, AHEAD_V]) == states[0]
    assert d.ahead[1, AHEAD_VALID] == (0.0 if states[1] == states[0] else 1.0)
    built = 0
    for i, lib in enumerate((d.LH1a, d.LH1b)):
        if d.ahead[i, AHEAD_VALID]:
            built += 1
            assert (d.ahead[i, AHEAD_S], d.ahead[i, AHEAD_V]) == states[i]
            np.testing.assert_array_equal(lib.S.T, trajectory_library(*states[i], paper.P_hv).s)
    # libraries built: the HV's at T1, plus the AV's from each distinct re-solve start;
    # re-solves done and skipped: at most the full 2 x 11
    assert d.work[slot.WORK_LIBRARIES] >= built
    assert d.work[slot.WORK_RESOLVES] + d.work[slot.WORK_RESOLVES_SKIPPED] <= 22


def test_persuading_changes_the_branch_weights_somewhere(paper):
    # Guard against a passive planner that still persuades (or a persuasive one that does
    # not): over the fixed cases the expected rewards differ somewhere.
    assert any(not np.array_equal(compiled(*case, paper)[2][:, D_EXPECTED],
                                  compiled(*case, paper, persuade=False)[2][:, D_EXPECTED])
               for case in CASES)
