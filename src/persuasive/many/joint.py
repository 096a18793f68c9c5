"""One plan against every human at once: the AV's joint branch MPC at the junction
(docs/method.md §15.8; issue 41 item 1).

The part-1 AV (``persuasive.envs.external.ExternalPlanner``, ``junction.av_plan =
"pairwise"``) runs one planner per human it conflicts with, each choosing from its own
library as if that human were alone, and applies the lowest of their accelerations. The
**joint** AV (``junction.av_plan = "joint"``, :class:`JointPlanner`) chooses one candidate
trajectory for all of them:

- **One set of candidates.** The AV's library at its state in the frame of the conflict it
  reaches first (the planned conflict with the largest ``s``, the nearest ahead; its
  stop-at-the-line trajectory stops before every other conflict too). Against human ``h`` the
  same trajectories are shifted into ``h``'s pair frame (``s_h = s_f + (s_R^h - s_R^f)``,
  ``persuasive.game.shifted_into``) and their reward parts recomputed there.
- **One belief per human.** Human ``h`` keeps its own planner (``persuasive.planner.Planner``:
  its role belief ``q_h``, its stored prediction, its confidence filter), which predicts ``h``
  from ``h``'s view (the full prediction with the AV's own library in ``h``'s frame: what the
  human expects of the AV) and evaluates the common candidates against ``h``'s four branches
  (``persuasive.mpc.decide``): per candidate ``c`` the branch probabilities ``P^h_b(c)``
  (persuasion: what candidate ``c`` makes ``h`` believe and so do), the expected reward
  ``J_h(c) = B(c) - w_c sum_b P^h_b(c) C^h_b(c)`` and the lowest P(safe) over the horizon
  ``p_h(c) = min_k sum_b P^h_b(c) [safe^h_{k,b}(c)]``.
- **The expectation over the product of branches.** The humans' branches are independent in
  the model (each human's role and its change depend on the AV's candidate, not on another
  human), and the reward is the AV's progress ``B(c)`` less ``w_c`` times the collision
  weights summed over the humans, so its expectation over the ``4^H`` joint branches is
  exactly ``J(c) = B(c) - w_c sum_h E_h[C^h(c)] = B(c) + sum_h (J_h(c) - B_h(c))``: linear in
  the number of humans ``H``, no branch is pruned. The persuasion reward is per human: each
  ``E_h`` is taken under ``h``'s own persuaded branch probabilities.
- **A joint chance constraint.** P(safe with every human at once at every sample) >
  ``1 - epsilon``. ``junction.joint_bound = "product"`` (the default) requires
  ``prod_h p_h(c) > 1 - epsilon``: with the branches independent the exact joint probability
  at sample ``k`` is ``prod_h p_h(c, k)`` and ``min_k prod_h p_h(c, k) >= prod_h min_k
  p_h(c, k)``, so the constraint is sufficient, conservative only by taking each human's
  lowest sample (``benchmarks/joint_chance.py`` measures by how much, against Monte Carlo over
  the joint branches). ``"union"`` requires ``sum_h (1 - p_h(c)) < epsilon`` (Boole's
  inequality, no independence assumed; more conservative).
- **Choice.** The feasible candidate (the joint constraint holds and every human's planner
  allows it: ``persuasive.policies.planners.shield_allowed``, the pair shield and the
  confidence filter) with the highest ``J(c)``, the lowest index on ties. When no candidate is
  feasible against all at once, the AV falls back to the part-1 rule over the same candidates:
  the lowest of each human's own choice (each planner's proposal, its yield-at-the-line
  fallback included).

With one human planned the joint AV *is* the pairwise one (the same planner, the same call,
bit for bit): the joint plan starts at two. What it does not change: the shield over every
conflict (``ExternalPlanner.shield``) filters the proposal; the yield line is each conflict's
stop line; the leader in the AV's lane caps it (IDM).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import JOINT_BOUNDS, Config, ConfigError
from ..envs.external import ExternalPlanner
from ..mpc import D_EXPECTED, D_MIN_SAFE


@dataclass(frozen=True)
class JointChoice:
    """What the last joint decision computed (:attr:`JointPlanner.last`; None when fewer than
    two humans were planned against). Arrays over the candidates ``(n_traj,)``, per human
    ``(H, n_traj)`` in the planned conflicts' order."""

    keys: tuple  #: the humans planned against
    frame: int  #: the human whose frame the candidates are in (its conflict comes first)
    expected: np.ndarray  #: ``J(c)``, the expectation over the joint branches
    p_safe: np.ndarray  #: the joint P(safe) the constraint reads (the bound's)
    p_safe_each: np.ndarray  #: ``p_h(c)`` per human ``(H, n_traj)``
    allowed: np.ndarray  #: allowed by every human's planner
    feasible: np.ndarray  #: the joint constraint holds and every planner allows it
    chosen: int  #: the candidate chosen (-1: the fallback)
    fallback: bool  #: no candidate was feasible: the lowest of the humans' own choices


class JointPlanner(ExternalPlanner):
    """The AV's one plan against every human it conflicts with (module docstring).

    ``bound``: the joint chance constraint, ``product`` or ``union``. The other parameters are
    :class:`~persuasive.envs.external.ExternalPlanner`'s. Only the model-based planners
    (``av.kind`` ``persuasive``, ``passive``, ``cv``) have candidates to share; the others
    plan pairwise.
    """

    #: the AV kinds that evaluate candidates (their decisions' diagnostics hold ``J_h`` and
    #: ``p_h`` per candidate)
    KINDS = ("persuasive", "passive", "cv")

    def __init__(self, config: Config, seed: int = 0, plan_horizon_s: float | None = None,
                 bound: str = "product"):
        if bound not in JOINT_BOUNDS:
            raise ConfigError(f"junction.joint_bound = {bound!r} is out of range; allowed: "
                              f"{' | '.join(JOINT_BOUNDS)}")
        super().__init__(config, seed, plan_horizon_s)
        self.bound = bound
        self.joint = config.av.kind in self.KINDS
        self._threshold = 1.0 - float(config.mpc.epsilon)
        n_traj = config.library.n_traj
        self._allowed = np.empty(n_traj, np.bool_)
        #: the last joint decision (:class:`JointChoice`; None: not a joint one)
        self.last: JointChoice | None = None

    def _propose(self, v: float, planned: list) -> float | None:
        self.last = None
        if len(planned) < 2 or not self.joint:
            return super()._propose(v, planned)
        planners = [self.planner_for(key) for key, _, _ in planned]  # seeds in planned order
        # the frame: the conflict the AV reaches first (its s nearest ahead; first on ties)
        f = max(range(len(planned)), key=lambda h: planned[h][1][0])
        own = [math.nan] * len(planned)
        own[f] = planners[f].accel(planned[f][1], planned[f][2])
        ref = planners[f].candidate_view()
        S, V, A = ref.S, ref.V, ref.A
        s_f = planned[f][1][0]
        H, n_traj = len(planned), S.shape[1]
        p_each = np.empty((H, n_traj))
        allowed = np.ones(n_traj, np.bool_)
        expected_each, base_each = np.empty((H, n_traj)), np.empty((H, n_traj))
        for h, (key, ego, other) in enumerate(planned):
            if h != f:
                own[h] = planners[h].accel_among(ego, other, (S, V, A, ego[0] - s_f))
            view = planners[h].candidate_view()
            expected_each[h] = view.diag[:, D_EXPECTED]
            base_each[h] = view.base
            p_each[h] = view.diag[:, D_MIN_SAFE]
            planners[h].allowed_now(ego, other, self._allowed)
            allowed &= self._allowed
        expected = joint_expectation(ref.base, expected_each, base_each)
        c, p_safe, feasible = combine(expected, p_each, allowed, self._threshold, self.bound)
        a = float(A[0, c]) if c >= 0 else min(own)
        self.last = JointChoice(tuple(key for key, _, _ in planned), f, expected, p_safe,
                                p_each, allowed, feasible, c, c < 0)
        return a


def joint_expectation(base: np.ndarray, expected_each: np.ndarray, base_each: np.ndarray
                      ) -> np.ndarray:
    """``J(c) = B(c) + sum_h (J_h(c) - B_h(c))`` ``(n_traj,)``: the expected reward over the
    product of the humans' branches, from the candidates' progress ``base`` ``B`` and each
    human's ``J_h`` and ``B_h`` ``(H, n_traj)`` (module docstring)."""
    return base + np.sum(expected_each - base_each, axis=0)


def joint_p_safe(p_each: np.ndarray, bound: str) -> np.ndarray:
    """The joint P(safe) the constraint reads, per candidate, from each human's lowest
    P(safe) over the horizon ``p_each`` ``(H, n_traj)``: ``product`` or ``union`` (module
    docstring)."""
    if bound == "product":
        return np.prod(p_each, axis=0)
    return 1.0 - np.sum(1.0 - p_each, axis=0)


def combine(expected: np.ndarray, p_each: np.ndarray, allowed: np.ndarray, threshold: float,
            bound: str) -> tuple[int, np.ndarray, np.ndarray]:
    """The joint choice: ``(candidate, joint P(safe), feasible)``; the candidate is the
    feasible one (``allowed`` and the joint P(safe) above ``threshold``) with the highest
    ``expected``, the first on ties, or -1 when none is feasible."""
    p_safe = joint_p_safe(p_each, bound)
    feasible = allowed & (p_safe > threshold)
    if not feasible.any():
        return -1, p_safe, feasible
    return int(np.argmax(np.where(feasible, expected, -np.inf))), p_safe, feasible


def av_planner(config: Config, spec, seed: int) -> ExternalPlanner:
    """The junction AV's planner of ``spec.av_plan`` (``persuasive.config.JunctionSpec``):
    ``pairwise``, the part-1 adapter-style AV; ``joint``, :class:`JointPlanner` with
    ``spec.joint_bound``. The ``lfg-rule`` AV plans by its own rule whatever the plan
    (``persuasive.many.rule.RulePlanner``: Li et al.'s worst pair)."""
    if config.av.kind == "lfg-rule":
        from .rule import RulePlanner

        return RulePlanner(config, seed)
    if spec.av_plan == "joint":
        return JointPlanner(config, seed, bound=spec.joint_bound)
    return ExternalPlanner(config, seed)


__all__ = ["JointChoice", "JointPlanner", "av_planner", "combine", "joint_expectation",
           "joint_p_safe"]
