"""Li et al.'s pairwise leader-follower AV among many humans (``av.kind = "lfg-rule"``,
docs/method.md §11.1 and §15.8; issue 41 item 3).

:class:`RulePlanner` is the junction's planner for the ``lfg-rule`` AV
(``persuasive.policies.lfg_rule``: the rule's role in each pair, the worst pair decides). Per
decision, against the humans the part-1 planner plans against
(:meth:`~persuasive.envs.external.ExternalPlanner._planned`):

- **One set of candidates**: the AV's library at its state in the frame of the conflict it
  reaches first (the largest ``s``, first on ties), shifted into each pair's frame
  (``persuasive.game.shifted_into``), as the joint plan does (``persuasive.many.joint``).
- **Per pair, the rule's role and the game's values.** The role comes from the conflict's
  right of way (``Conflict.right_of_way``: the junction's priority rule,
  ``persuasive.many.junction.right_of_way``; for a conflict without one, the configuration's
  ``responsibility.right_of_way``, first come when unset), taken when the human is first
  planned against and kept while it is (:func:`persuasive.policies.lfg_rule.rule_role`). The
  pair's game (``persuasive.game.solve_buffers``: the AV's candidates in that frame against
  the human's library at its state) gives the leader's values ``Ql`` when the AV leads and
  the follower's ``Qf`` when it follows.
- **The worst pair decides**: the candidate with the highest lowest value over the pairs
  (:func:`persuasive.policies.lfg_rule.maximin_choice`); its first acceleration is the
  proposal.

With one human it is the two-vehicle ``lfg-rule`` AV of the same role (the same game on the
same libraries: ``tests/test_lfg_rule.py``). The shield over every conflict filters the
proposal, and the leader in the AV's lane caps it (IDM), as for every AV kind
(:meth:`ExternalPlanner.act`).
"""

from __future__ import annotations

from typing import Hashable, Sequence

import numpy as np

from ..config import Config
from ..envs.external import ExternalPlanner
from ..game import Q_EGO_FOLLOWS_FOLLOWER, Q_EGO_LEADS_LEADER, build_buffers, shifted_into, \
    solve_buffers
from ..library import lib_buffers
from .. import packing as slot
from ..packing import RIGHT_OF_WAY_IDS
from ..policies.lfg_rule import maximin_choice, rule_role
from ..roles import LEADER
from ..tables import Conflict


class RulePlanner(ExternalPlanner):
    """Li et al.'s pairwise LFG AV among many humans (module docstring). Parameters as
    :class:`~persuasive.envs.external.ExternalPlanner`'s."""

    def __init__(self, config: Config, seed: int = 0, plan_horizon_s: float | None = None):
        super().__init__(config, seed, plan_horizon_s)
        from ..record import static_setup

        _, self._P_av, self._P_hv, self._disc = static_setup(self.config)  # cached per config
        n, n_traj = self.config.library.n_samples, self.config.library.n_traj
        self._ref, self._cand, self._hv = (lib_buffers(n, n_traj), lib_buffers(n, n_traj),
                                           lib_buffers(n, n_traj))
        self._idx = np.zeros(4, np.int64)
        self._q = np.zeros((4, n_traj))
        self.work = np.zeros(slot.N_WORK, np.int64)  #: the kernels' counters
        self._default = RIGHT_OF_WAY_IDS[self.config.responsibility.right_of_way]
        self._priority: dict[Hashable, float] = {}
        #: the AV's role per human planned against (0 = leader, 1 = follower), kept while it is
        self.roles: dict[Hashable, int] = {}
        #: the last decision's values per pair ``(pairs, n_traj)`` and its choice (-1: none)
        self.values = np.zeros((0, n_traj))
        self.chosen = -1

    def act(self, ego_v_mps: float, conflicts: Sequence[Conflict], dt_s: float,
            shield_lead_m=0.0):
        self._priority = {c.key: (self._default if c.right_of_way is None
                                  else float(c.right_of_way)) for c in conflicts}
        return super().act(ego_v_mps, conflicts, dt_s, shield_lead_m)

    def _propose(self, v: float, planned: list) -> float | None:
        self.chosen = -1
        live = {key for key, _, _ in planned}
        for key in [k for k in self.roles if k not in live]:
            del self.roles[key]
        if not planned:
            self.values = self.values[:0]
            return None
        f = max(range(len(planned)), key=lambda h: planned[h][1][0])
        s_f = planned[f][1][0]
        build_buffers(s_f, v, self._P_av, self._disc, *self._ref)
        ref = self._ref[0]
        n = self.config.library.n_samples
        S, V, A = ref[0:n], ref[n:2 * n], ref[2 * n:3 * n]
        Q = np.empty((len(planned), S.shape[1]))
        for h, (key, ego, other) in enumerate(planned):
            role = self.roles.get(key)
            if role is None:
                role = self.roles[key] = int(rule_role(
                    self._priority.get(key, self._default), ego[0], ego[1], other[0],
                    other[1]))
            cand = self._ref
            if h != f:
                shifted_into(S, V, A, ego[0] - s_f, ego[0], self._P_av, self._disc,
                             *self._cand)
                cand = self._cand
            build_buffers(other[0], other[1], self._P_hv, self._disc, *self._hv)
            solve_buffers(*cand, *self._hv, self._P_av, self._idx, self._q, self.work)
            Q[h] = self._q[Q_EGO_LEADS_LEADER if role == LEADER else Q_EGO_FOLLOWS_FOLLOWER]
        self.values = Q
        self.chosen = int(maximin_choice(Q))
        return float(A[0, self.chosen])


__all__ = ["RulePlanner"]
