"""The policy kinds: ids, which side may use them, and their shapes (docs/method.md §11).

A policy drives one vehicle. Its compiled side is a kind id, a parameter vector, a state vector
(``STATE_SIZE`` slots, kind-specific layout) and a log row (``LOG_SIZE`` slots, the kind's
columns first); :func:`persuasive.policies.step.policy_step` dispatches on the id. This module
is the registry: adding a kind means a module with its step function, one branch in the
dispatcher and one :class:`KindSpec` here.
"""

from __future__ import annotations

from dataclasses import dataclass

# Kind ids (compile-time constants in the dispatcher).
(LFG, STUBBORN, NOISY, IDM, AGGRESSIVE, REPLAY, PERSUASIVE, PASSIVE, CV, YIELD, ADVERSARY,
 DECEPTIVE, RANDOM, LEVEL1, LEVEL2, LFG_RULE) = range(16)

#: The vehicle a policy drives.
AV, HV = 0, 1

#: Size of every policy's state vector and log row.
STATE_SIZE = 16
LOG_SIZE = 20

LFG_LOG = ("role", "next_role", "trajectory", "plausible_leader", "pi_ll", "pi_lf", "pi_fl",
           "pi_ff", "draw", "belief_other_leader", "belief_other_follower")
NOISY_LOG = LFG_LOG + ("choice_draw", "choice_probability")
MPC_LOG = ("trajectory", "feasible", "n_feasible", "p_safe_min", "p_safe_max",
           "expected_reward", "belief_hv_leader_used", "belief_hv_leader",
           "belief_hv_follower", "tie_role", "human_belief_av_leader",
           "human_plausible_leader", "branch_p_ll", "branch_p_lf", "branch_p_fl", "branch_p_ff",
           "model_confidence", "n_allowed", "p_a_hat")
CV_LOG = ("trajectory", "feasible", "n_feasible", "p_safe_min", "expected_reward", "n_allowed")
YIELD_LOG = ("trajectory", "released", "n_admissible")
LEVELK_LOG = ("trajectory", "predicted_hv_trajectory", "expected_reward", "n_allowed")
IDM_LOG = ("go", "committed", "waiting_s", "gap_s", "time_to_conflict_s",
           "other_time_to_conflict_s")
ADVERSARY_LOG = ("target_time_s", "lurking")
DECEPTIVE_LOG = ("committed",)
RANDOM_LOG = ("hold_left_s",)
NO_LOG: tuple[str, ...] = ()


@dataclass(frozen=True)
class KindSpec:
    """What the loop needs to know of a kind."""

    name: str
    kind: int
    sides: tuple[int, ...]  #: AV and/or HV
    draws: int  #: uniforms drawn per step (the role draw first)
    needs_game: bool  #: reads the full prediction of the joint state (the human's view)
    needs_av_library: bool  #: reads the AV's library (built by the loop when no game is)
    log: tuple[str, ...]  #: its log columns
    has_role: bool = False  #: holds a leader/follower role (state slot 0)


KINDS: dict[str, KindSpec] = {s.name: s for s in (
    KindSpec("lfg", LFG, (AV, HV), 1, True, False, LFG_LOG, True),
    KindSpec("stubborn", STUBBORN, (HV,), 1, True, False, LFG_LOG, True),
    KindSpec("noisy", NOISY, (HV,), 2, True, False, NOISY_LOG, True),
    KindSpec("idm", IDM, (HV,), 0, False, False, IDM_LOG),
    KindSpec("aggressive", AGGRESSIVE, (HV,), 0, False, False, NO_LOG),
    KindSpec("replay", REPLAY, (HV,), 0, False, False, NO_LOG),
    KindSpec("adversary", ADVERSARY, (HV,), 0, False, False, ADVERSARY_LOG),
    KindSpec("deceptive", DECEPTIVE, (HV,), 0, False, False, DECEPTIVE_LOG),
    KindSpec("random", RANDOM, (HV,), 2, False, False, RANDOM_LOG),
    KindSpec("persuasive", PERSUASIVE, (AV,), 0, True, True, MPC_LOG),
    KindSpec("passive", PASSIVE, (AV,), 0, True, True, MPC_LOG),
    KindSpec("cv", CV, (AV,), 0, False, True, CV_LOG),
    KindSpec("yield", YIELD, (AV,), 0, False, True, YIELD_LOG),
    # the level-k AV reads the game cache's two libraries (not its solve)
    KindSpec("level1", LEVEL1, (AV,), 0, True, True, LEVELK_LOG),
    KindSpec("level2", LEVEL2, (AV,), 0, True, True, LEVELK_LOG),
    # Li et al.'s pairwise LFG AV: the LFG player whose role the traffic rule fixes (no draw)
    KindSpec("lfg-rule", LFG_RULE, (AV,), 0, True, False, LFG_LOG, True),
)}

#: Specs by kind id.
BY_ID: dict[int, KindSpec] = {s.kind: s for s in KINDS.values()}
#: Log columns whose values are roles (written as "leader"/"follower").
ROLE_COLUMNS = ("role", "next_role", "tie_role")
#: Log columns whose values are integers or flags.
INT_COLUMNS = ("trajectory", "n_feasible", "n_admissible", "n_allowed",
               "predicted_hv_trajectory")
BOOL_COLUMNS = ("feasible", "released", "go", "committed", "lurking")


def spec(name: str) -> KindSpec:
    """The :class:`KindSpec` of a kind name."""
    return KINDS[name]
