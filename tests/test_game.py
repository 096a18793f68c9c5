"""The leader-follower game and the full prediction (spec section 4).

Layer 2: small hand-made games with known answers, ties included (quirk Q5 decides one).
Layer 3: the follower's pick is a max-min response and the leader's pick maximises its
aggregate (hypothesis, integer-valued matrices so that ties are common); the full prediction
equals the NumPy reference bit for bit and is symmetric between the two players' views.
Comparisons are exact throughout (the spec's ties are exact floating-point equality).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from persuasive import packing as slot
from persuasive import reference
from persuasive.game import (EGO_FOLLOWER, EGO_LEADER, OTHER_FOLLOWER, OTHER_LEADER,
                             Q_EGO_FOLLOWS_FOLLOWER, Q_EGO_FOLLOWS_LEADER,
                             Q_EGO_LEADS_FOLLOWER, Q_EGO_LEADS_LEADER, full_prediction,
                             leader_follower, predict_into, solve_game)
from persuasive.library import new_lib

finite = dict(allow_nan=False, allow_infinity=False)

# The reference's saturated step evaluates every branch (then picks one); a subnormal speed or
# acceleration overflows an unused branch, harmlessly.
pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")


def kernel(M_lead, M_fol, agg_max):
    M_lead, M_fol = np.asarray(M_lead, float), np.asarray(M_fol, float)
    Ql, Qf = np.empty(M_lead.shape[0]), np.empty(M_lead.shape[1])
    lead, fol = leader_follower(M_lead, M_fol, agg_max, Ql, Qf)
    return int(lead), int(fol), Ql, Qf


# -- layer 2: hand-made games -------------------------------------------------------------------


def test_2x2_unique_answers():
    # Follower rows (its trajectory f) x leader columns: Qf = min per row = [1, 3] -> f = 1.
    # The leader then reads column f = 1 of its matrix: Ql = [0, 7] -> l = 1.
    M_fol = [[1.0, 5.0], [3.0, 4.0]]
    M_lead = [[10.0, 0.0], [2.0, 7.0]]
    sol = solve_game(M_lead, M_fol)
    assert (sol.leader, sol.follower) == (1, 1)
    np.testing.assert_array_equal(sol.q_follower, [1.0, 3.0])
    np.testing.assert_array_equal(sol.q_leader, [0.0, 7.0])
    np.testing.assert_array_equal(sol.follower_set, [1])


# Follower rows: Qf = [2, 1, 2] -> optimal set {0, 2}, predicted follower 0.
TIE_FOL = [[2.0, 5.0, 3.0], [1.0, 1.0, 1.0], [2.0, 2.0, 9.0]]
# Leader rows over columns {0, 2}: l=0: (5, 1); l=1: (3, 3); l=2: (0, 4).
TIE_LEAD = [[5.0, 0.0, 1.0], [3.0, 9.0, 3.0], [0.0, 0.0, 4.0]]


def test_3x3_follower_tie_min_aggregation():
    # min: Ql = [1, 3, 0] -> the leader picks 1 (the paper's rule, corrected mode)
    sol = solve_game(TIE_LEAD, TIE_FOL, agg="min")
    assert (sol.leader, sol.follower) == (1, 0)
    np.testing.assert_array_equal(sol.follower_set, [0, 2])
    np.testing.assert_array_equal(sol.q_leader, [1.0, 3.0, 0.0])


def test_3x3_follower_tie_max_aggregation_q5():
    # max (Q5): Ql = [5, 3, 4] -> the leader picks 0; the predicted follower is still 0
    sol = solve_game(TIE_LEAD, TIE_FOL, agg="max")
    assert (sol.leader, sol.follower) == (0, 0)
    np.testing.assert_array_equal(sol.q_leader, [5.0, 3.0, 4.0])


def test_follower_tie_not_at_index_0():
    # Qf = [1, 3, 3]: optimal set {1, 2}, predicted follower 1 (the first)
    M_fol = [[1.0, 4.0], [3.0, 3.0], [5.0, 3.0]]
    M_lead = [[0.0, 2.0, 1.0], [0.0, 1.0, 2.0]]  # min over {1, 2}: [1, 1]; max: [2, 2]
    for agg in ("min", "max"):
        sol = solve_game(M_lead, M_fol, agg=agg)
        assert sol.follower == 1
        np.testing.assert_array_equal(sol.follower_set, [1, 2])
        assert sol.leader == 0  # the leader's tie goes to the lowest index


def test_leader_tie_goes_to_the_lowest_index():
    M_fol = [[0.0, 0.0, 0.0]]  # one follower trajectory
    assert solve_game([[2.0], [7.0], [7.0]], M_fol).leader == 1
    assert solve_game([[7.0], [2.0], [7.0]], M_fol).leader == 0
    assert solve_game([[-3.0], [-3.0], [-3.0]], M_fol).leader == 0


def test_all_follower_choices_tie():
    # Every Qf equal: the optimal set is everything, the predicted follower is 0.
    M_fol = [[1.0, 2.0], [1.0, 5.0], [1.0, 1.0]]
    M_lead = [[0.0, 9.0, 0.0], [1.0, 1.0, 1.0]]  # min: [0, 1] -> 1; max: [9, 1] -> 0
    assert (solve_game(M_lead, M_fol, "min").leader, solve_game(M_lead, M_fol).follower) == (1, 0)
    assert solve_game(M_lead, M_fol, "max").leader == 0


def test_non_square_game():
    # 2 leader trajectories, 3 follower trajectories.
    M_fol = [[0.0, 4.0], [2.0, 6.0], [-1.0, 9.0]]  # Qf = [0, 2, -1] -> f = 1
    M_lead = [[5.0, 1.0, 9.0], [0.0, 3.0, 0.0]]  # column 1: [1, 3] -> l = 1
    sol = solve_game(M_lead, M_fol)
    assert (sol.leader, sol.follower) == (1, 1)


def test_negative_infinity_rewards_do_not_break_the_pick():
    # All leader values -inf: the leader still picks index 0, never -1 or garbage.
    lead, fol, Ql, _ = kernel([[-np.inf], [-np.inf]], [[0.0, 0.0]], False)
    assert (lead, fol) == (0, 0)


def test_solve_game_rejects_bad_input():
    with pytest.raises(ValueError, match="agg"):
        solve_game([[1.0]], [[1.0]], agg="mean")
    with pytest.raises(ValueError, match="shapes"):
        solve_game(np.zeros((2, 3)), np.zeros((2, 3)))


# -- layer 3: max-min response (hypothesis) -----------------------------------------------------


@st.composite
def integer_games(draw):
    n_lead, n_fol = draw(st.integers(1, 6)), draw(st.integers(1, 6))
    vals = st.integers(-3, 3).map(float)  # few values: ties everywhere
    M_lead = draw(hnp.arrays(np.float64, (n_lead, n_fol), elements=vals))
    M_fol = draw(hnp.arrays(np.float64, (n_fol, n_lead), elements=vals))
    return M_lead, M_fol


@settings(max_examples=300)
@given(integer_games(), st.booleans())
def test_follower_is_max_min_and_leader_maximises_its_aggregate(game, agg_max):
    M_lead, M_fol = game
    sol = solve_game(M_lead, M_fol, agg="max" if agg_max else "min")
    # follower: Qf[f] = min_l M_fol[f, l]; its pick is the first maximiser of Qf
    np.testing.assert_array_equal(sol.q_follower, M_fol.min(axis=1))
    best = sol.q_follower.max()
    F = [f for f in range(M_fol.shape[0]) if sol.q_follower[f] == best]
    assert sol.follower == F[0]
    np.testing.assert_array_equal(sol.follower_set, F)
    # leader: Ql[l] = agg over the follower's optimal set; its pick is the first maximiser
    agg = np.max if agg_max else np.min
    np.testing.assert_array_equal(sol.q_leader, agg(M_lead[:, F], axis=1))
    assert sol.leader == min(l for l in range(M_lead.shape[0])
                             if sol.q_leader[l] == sol.q_leader.max())
    # and the NumPy reference agrees
    assert (sol.leader, sol.follower) == reference.solve(M_lead, M_fol, agg_max)


@settings(max_examples=100)
@given(hnp.arrays(np.float64, (4, 3), elements=st.floats(-1e3, 1e3, **finite)),
       hnp.arrays(np.float64, (3, 4), elements=st.floats(-1e3, 1e3, **finite)), st.booleans())
def test_kernel_equals_reference_on_real_valued_games(M_lead, M_fol, agg_max):
    lead, fol, _, _ = kernel(M_lead, M_fol, agg_max)
    assert (lead, fol) == reference.solve(M_lead, M_fol, agg_max)


# -- full prediction ----------------------------------------------------------------------------

# The ego is the HV and the other the AV (the human's view, as the closed loop solves it);
# ``unequal`` (conftest) gives the two vehicles different limits and sizes, so that a kernel
# reading the wrong vehicle's vector shows up.


@pytest.fixture(scope="module", params=["paper", "corrected", "unequal"])
def pk(request):
    return request.getfixturevalue(request.param)


def clip_speeds(states, pk):
    """Speeds inside each vehicle's limits (ego: HV, other: AV)."""
    (s_e, v_e), (s_o, v_o) = states
    return (s_e, min(v_e, pk.P_hv[slot.V_MAX])), (s_o, min(v_o, pk.P_av[slot.V_MAX]))


@st.composite
def joint_states(draw):
    """(x_ego, x_other), often with equal speeds or close positions."""
    s_e = draw(st.one_of(st.sampled_from([-20.0, -10.0, -6.5]), st.floats(-30.0, 0.0, **finite)))
    v_e = draw(st.one_of(st.sampled_from([0.0, 4.0, 10.0]), st.floats(0.0, 10.0, **finite)))
    s_o = draw(st.one_of(st.just(s_e), st.floats(-1.0, 1.0, **finite).map(lambda d: s_e + d),
                         st.floats(-30.0, 0.0, **finite)))
    v_o = draw(st.one_of(st.just(v_e), st.floats(0.0, 10.0, **finite)))
    return (s_e, v_e), (s_o, v_o)


@settings(max_examples=25)
@given(joint_states())
def test_full_prediction_equals_reference_bit_for_bit(pk, states):
    x_e, x_o = clip_speeds(states, pk)
    pred = full_prediction(x_e, x_o, pk.P_hv, pk.P_av, pk.disc)
    (Se, Ve, Ae), (So, Vo, Ao), idx = reference.full_prediction(x_e, x_o, pk.P_hv, pk.P_av,
                                                                pk.disc)
    assert (pred.ego_leader, pred.ego_follower, pred.other_leader, pred.other_follower) == idx
    for got, ref in [(pred.ego.s, Se), (pred.ego.v, Ve), (pred.ego.a, Ae),
                     (pred.other.s, So), (pred.other.v, Vo), (pred.other.a, Ao)]:
        np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(
        pred.rewards_ego,
        reference.reward_matrix(Se, Ve, Ae, x_e[0], So, pk.disc, pk.P_hv, pk.P_av))
    np.testing.assert_array_equal(
        pred.rewards_other,
        reference.reward_matrix(So, Vo, Ao, x_o[0], Se, pk.disc, pk.P_av, pk.P_hv))


def kernel_prediction(x_e, x_o, pk, Le=None, ego_built=False):
    """:func:`predict_into` with the HV as ego: ``(libraries, indices, q_values, work)``."""
    Le = new_lib(50, 11) if Le is None else Le
    Lo, out = new_lib(50, 11), np.empty(4, np.int64)
    q_values, work = np.full((4, 11), np.nan), np.zeros(slot.N_WORK, np.int64)
    predict_into(x_e[0], x_e[1], x_o[0], x_o[1], pk.P_hv, pk.P_av, pk.disc, Le, Lo, out,
                 q_values, work, ego_built)
    return (Le, Lo), tuple(int(i) for i in out), q_values, work


@settings(max_examples=25)
@given(joint_states())
def test_predict_into_equals_reference_bit_for_bit(pk, states):
    x_e, x_o = clip_speeds(states, pk)
    (Le, Lo), idx_k, q_values, work = kernel_prediction(x_e, x_o, pk)
    (Se, Ve, Ae), (So, Vo, Ao), idx = reference.full_prediction(x_e, x_o, pk.P_hv, pk.P_av,
                                                                pk.disc)
    assert idx_k == idx
    # kernel arrays are sample-major (n_samples, n_traj)
    for got, ref in [(Le.S, Se), (Le.V, Ve), (Le.A, Ae), (Lo.S, So), (Lo.V, Vo), (Lo.A, Ao)]:
        np.testing.assert_array_equal(got.T, ref)
    # the Q-values are the two solves' (rows: "ego leads" Ql, Qf, then "ego follows" Ql, Qf)
    pred = full_prediction(x_e, x_o, pk.P_hv, pk.P_av, pk.disc)
    agg = "max" if pk.config.effective_quirks.q5_leader_agg_max else "min"
    lead = solve_game(pred.rewards_ego, pred.rewards_other, agg)
    follow = solve_game(pred.rewards_other, pred.rewards_ego, agg)
    np.testing.assert_array_equal(q_values[Q_EGO_LEADS_LEADER], lead.q_leader)
    np.testing.assert_array_equal(q_values[Q_EGO_LEADS_FOLLOWER], lead.q_follower)
    np.testing.assert_array_equal(q_values[Q_EGO_FOLLOWS_LEADER], follow.q_leader)
    np.testing.assert_array_equal(q_values[Q_EGO_FOLLOWS_FOLLOWER], follow.q_follower)
    # work: two libraries built, none reused; pair tests at most the full n_traj^2 n per matrix
    assert work[slot.WORK_LIBRARIES] == 2 and work[slot.WORK_LIBRARIES_REUSED] == 0
    assert 0 <= work[slot.WORK_PAIRS_GAME] <= 2 * 11 * 11 * 50


def test_predict_into_reuses_a_built_ego_library(paper):
    x_e, x_o = (-12.0, 5.0), (-11.0, 5.5)
    (Le, _), idx, q_values, work = kernel_prediction(x_e, x_o, paper)
    # The same ego library handed back as built: nothing of it is recomputed, same answer
    (Le2, _), idx2, q_values2, work2 = kernel_prediction(x_e, x_o, paper, Le, ego_built=True)
    assert Le2 is Le and idx2 == idx
    np.testing.assert_array_equal(q_values2, q_values)
    assert (work2[slot.WORK_LIBRARIES], work2[slot.WORK_LIBRARIES_REUSED]) == (1, 1)
    assert work2[slot.WORK_PAIRS_GAME] == work[slot.WORK_PAIRS_GAME] > 0  # they do meet
    # ego_built is taken at its word: a library of another state gives that state's game
    (Lf, _), _, _, _ = kernel_prediction((-30.0, 2.0), x_o, paper)
    _, idx_far, _, _ = kernel_prediction(x_e, x_o, paper, Lf, ego_built=True)
    assert idx_far == kernel_prediction((-30.0, 2.0), x_o, paper)[1]


@settings(max_examples=40)
@given(joint_states())
def test_full_prediction_is_symmetric(packed, states):
    # the paper's two vehicles are alike, so either view uses the same vectors up to the
    # path's direction, which the intersection's distance does not read
    x_a, x_b = states
    ab = full_prediction(x_a, x_b, packed.P_hv, packed.P_av, packed.disc)
    ba = full_prediction(x_b, x_a, packed.P_av, packed.P_hv, packed.disc)
    # "a leads" is the same game seen from either side, and so is "b leads"
    assert ab.ego_leader == ba.other_leader
    assert ab.ego_follower == ba.other_follower
    assert ab.other_leader == ba.ego_leader
    assert ab.other_follower == ba.ego_follower
    np.testing.assert_array_equal(ab.rewards_ego, ba.rewards_other)
    np.testing.assert_array_equal(ab.rewards_other, ba.rewards_ego)


def test_full_prediction_indices_come_from_the_two_solves(packed):
    # ego-L and other-F from "ego leads" (leader matrix M_e), other-L and ego-F from
    # "ego follows" (leader matrix M_o).
    pred = full_prediction((-12.0, 5.0), (-11.0, 5.5), packed.P_hv, packed.P_av, packed.disc)
    agg = "max" if packed.config.effective_quirks.q5_leader_agg_max else "min"
    lead = solve_game(pred.rewards_ego, pred.rewards_other, agg)
    follow = solve_game(pred.rewards_other, pred.rewards_ego, agg)
    assert (pred.ego_leader, pred.other_follower) == (lead.leader, lead.follower)
    assert (pred.other_leader, pred.ego_follower) == (follow.leader, follow.follower)
    assert (EGO_LEADER, EGO_FOLLOWER, OTHER_LEADER, OTHER_FOLLOWER) == (0, 1, 2, 3)


def test_prediction_state_readout(paper):
    pred = full_prediction((-20.0, 4.0), (-18.0, 4.5), paper.P_hv, paper.P_av, paper.disc)
    assert pred.ego_state("leader", 0) == (-20.0, 4.0)  # time 0 is the current state
    assert pred.other_state("follower", 0) == (-18.0, 4.5)
    assert pred.ego_state("leader", 1) == (pred.ego.s[pred.ego_leader, 0],
                                           pred.ego.v[pred.ego_leader, 0])
    assert pred.other_state("follower", 50) == (pred.other.s[pred.other_follower, 49],
                                                pred.other.v[pred.other_follower, 49])


def test_predict_buffers_is_predict_into_on_buffers(unequal):
    from persuasive.game import predict_buffers
    from persuasive.library import as_lib, lib_buffers

    x_e, x_o = (-10.0, 6.5), (-9.0, 7.5)
    (Le, Lo), idx, q_values, work = kernel_prediction(x_e, x_o, unequal)
    (buf_e, win_e), (buf_o, win_o) = lib_buffers(50, 11), lib_buffers(50, 11)
    out, q2, work2 = np.empty(4, np.int64), np.empty((4, 11)), np.zeros(slot.N_WORK, np.int64)
    predict_buffers(*x_e, *x_o, unequal.P_hv, unequal.P_av, unequal.disc, buf_e, win_e, buf_o,
                    win_o, out, q2, work2)
    assert tuple(int(i) for i in out) == idx
    np.testing.assert_array_equal(q2, q_values)
    np.testing.assert_array_equal(work2, work)
    for got, ref in ((as_lib(buf_e, win_e), Le), (as_lib(buf_o, win_o), Lo)):
        for name in ("S", "V", "A", "base", "coll", "win"):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
        np.testing.assert_array_equal(got.pos[0], ref.pos[0])
