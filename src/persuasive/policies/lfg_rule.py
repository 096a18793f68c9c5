"""The LFG AV whose role the traffic rule fixes (``lfg-rule``, docs/method.md §11.1): Li et
al.'s pairwise leader-follower player.

Li, Yao, Kolmanovsky, Atkins and Girard ("Game-theoretic modeling of multi-vehicle
interactions at uncontrolled intersections", arXiv 1904.05423, IEEE T-ITS) model every
vehicle at an uncontrolled intersection as a player of one leader-follower game with each
vehicle it conflicts with, the roles *induced from the traffic rule*: of a pair, the vehicle
that has the right of way leads and the other follows. A vehicle in several pairs chooses the
action whose worst value over its pairs is the highest. As we read the paper, written here on
this project's game (``persuasive.game``, the paper's LFG of docs/method.md §4, no code or
text of theirs):

- **The pair's values.** In the game of the AV and one human, the AV's value of its trajectory
  ``c`` is the leader's ``Ql(c)`` when the AV has the right of way (the human answers ``c``
  with its follower's choice) and the follower's ``Qf(c)`` when the human has it (the worst
  over the human's trajectories, the follower's caution): the rows ``Q_EGO_LEADS_LEADER`` and
  ``Q_EGO_FOLLOWS_FOLLOWER`` of a full prediction with the AV as ego.
- **The role is the rule's, fixed** for the encounter (:func:`rule_role`, taken at its first
  decision): ``responsibility.right_of_way = "av"`` leads, ``"hv"`` follows; unset, the rule of
  an uncontrolled junction without signs, *first come*: the vehicle that would reach the
  conflict point first at its speed (at least 1 m/s, as the junction's ``first-come``) leads;
  a tie, or the AV not first, follows. The role never adapts (``p_a = 0``) and the AV keeps no
  belief that matters to it: it is the ``stubborn`` LFG in the rule's role.
- **Two vehicles**: the AV plays its role's trajectory of the game (the LFG's step with the
  AV as ego, ``persuasive.policies.lfg.lfg_step``, so its log is the LFG's).
- **Many vehicles** (:func:`maximin_choice`, used by the junction's planner
  ``persuasive.many.rule.RulePlanner``): per pair the AV's role from that pair's right of way
  and the values over one set of candidates; the AV takes the candidate with the highest of
  its lowest values over the pairs, the lowest index on ties.

No chance constraint, no persuasion and no shield awareness: the baseline as published. The
shield over every conflict filters its proposal afterwards, as for every AV kind.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import packing as slot
from ..roles import FOLLOWER, LEADER

#: The first-come rule's lowest speed [m/s] (the junction's ``first-come`` uses the same).
FIRST_COME_MIN_V = 1.0


@njit(cache=True, _nrt=False)
def rule_role(priority: float, s_av: float, v_av: float, s_hv: float, v_hv: float) -> int:
    """The AV's role from the traffic rule: ``priority`` ``+1`` (the AV has the right of way)
    leads, ``-1`` follows, ``0`` (no rule) first come: the AV leads only when it would reach
    the conflict point (``s = 0``) strictly first at its speed (at least
    :data:`FIRST_COME_MIN_V`)."""
    if priority > 0.0:
        return LEADER
    if priority < 0.0:
        return FOLLOWER
    t_av = max(-s_av, 0.0) / max(v_av, FIRST_COME_MIN_V)
    t_hv = max(-s_hv, 0.0) / max(v_hv, FIRST_COME_MIN_V)
    return LEADER if t_av < t_hv else FOLLOWER


@njit(cache=True, _nrt=False)
def first_role(P_av: np.ndarray, s_av: float, v_av: float, s_hv: float, v_hv: float) -> int:
    """:func:`rule_role` of the configuration's right of way (``P_av[RIGHT_OF_WAY]``)."""
    return rule_role(P_av[slot.RIGHT_OF_WAY], s_av, v_av, s_hv, v_hv)


@njit(cache=True, _nrt=False)
def maximin_choice(Q: np.ndarray) -> int:
    """The candidate (column of ``Q`` ``(pairs, n_traj)``) with the highest lowest value over
    the pairs (rows); the lowest index on ties (exact equality, the game's rule)."""
    best, best_q = 0, -np.inf
    for c in range(Q.shape[1]):
        q = Q[0, c]
        for h in range(1, Q.shape[0]):
            if Q[h, c] < q:
                q = Q[h, c]
        if c == 0 or q > best_q:
            best, best_q = c, q
    return best
