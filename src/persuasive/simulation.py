"""One closed-loop run and its record (docs/method.md §7): :func:`simulate` and :class:`RunRecord`.

:func:`simulate` builds the scenario and both vehicles' parameter vectors from the
configuration, draws the run's random numbers (``persuasive.streams.draw_streams``), runs the
compiled loop (``persuasive.world.run_loop``) with the two policies the configuration names,
and returns a :class:`RunRecord`: the configuration, the seed, the states, the per-step log
and the outcome (:class:`RunOutcome`); the setup and the record are ``persuasive.record``'s.
:func:`persuasive.world.run_python` gives the same record for Python policies.

States are indexed ``x_0 .. x_N`` (``N = n_steps``): step ``k`` decides at ``x_k`` and advances
to ``x_{k+1}``; collision and arrival are tested on ``x_{k+1}``. ``idx_end`` is the first step
after which a vehicle is at its first-arrival line (the last step if none is), and the "up to
the line" minimum distance runs over ``x_0 .. x_{idx_end + 1}``. Measured speeds with noise are
clipped to the vehicle's ``[v_min, v_max]`` before a policy sees them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .config import Config, ConfigError
from .online import posterior_of, prior_view
from .policies import kinds as kd
from .policies import policy_params
from .record import ARRIVAL_LABELS, RunOutcome, RunRecord, check_seed, load_record, setup


def simulate(config: Config, seed: int, timed: bool = False, interaction: int = 0,
             p_a_prior: np.ndarray | None = None, *, x0: np.ndarray | None = None,
             hv_prm: np.ndarray | None = None) -> RunRecord:
    """Run one closed loop for ``seed``; bit-identical for equal inputs.

    ``timed``: also measure the AV's decision time per step (``RunRecord.av_decision_ms``).
    ``interaction``: the repeated interaction ``k`` with the seed's human (fresh initial state
    and draws from ``persuasive.streams.interaction_seed``; 0 is the seed's own run).
    ``p_a_prior`` ``(mpc.p_a_grid,)``: with ``mpc.p_a_hat = "online"``, the prior masses over
    the grid in place of the Beta prior's (:func:`simulate_interactions` hands each
    interaction the last one's posterior). ``x0`` ``(4,)``: the initial state ``(s_av, v_av,
    s_hv, v_hv)`` in place of the seed's draw (the rest of the seed's streams unchanged; a
    recorded start, ``persuasive.recordings.replay``); ``hv_prm``: the human's parameter
    vector in place of the configuration's (a replay given in memory).
    """
    from .policies.planners import ONLINE_STATE, PRM_ONLINE
    from .world import predicted_summary, run_compiled

    check_interaction(interaction)
    s = setup(config, seed, interaction=interaction, x0=x0, predict=predicted_summary)
    av_prm = policy_params(config, kd.AV, p_a_prior)
    record, av_st = run_compiled(s, av_prm, policy_params(config, kd.HV) if hv_prm is None
                                 else np.asarray(hv_prm, dtype=np.float64), timed)
    if av_st.shape[0] > kd.STATE_SIZE:  # an online posterior over p_a
        record = replace(record, interaction=interaction,
                         p_a_prior=prior_view(av_prm, PRM_ONLINE).copy(),
                         p_a_posterior=posterior_of(av_st, ONLINE_STATE,
                                                    int(av_prm[PRM_ONLINE])))
    elif interaction:
        record = replace(record, interaction=interaction)
    return record


def check_interaction(k) -> int:
    """``k`` as an int, or :class:`ConfigError` unless an integer in [0, 10^6]."""
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k <= 10**6:
        raise ConfigError(f"interaction = {k!r} is out of range; allowed: integer in "
                          "[0, 1000000]")
    return int(k)


def simulate_interactions(config: Config, seed: int, interactions: int | None = None,
                          p_a_prior: np.ndarray | None = None) -> list[RunRecord]:
    """``interactions`` runs of the AV with one human (docs/method.md §13.9): the same human
    kind, ``p_a`` and initial-role setting; interaction ``k`` draws its initial state and
    every random number from ``persuasive.streams.interaction_seed(seed, k)`` (interaction 0
    is ``simulate(config, seed)``). With ``mpc.p_a_hat = "online"`` the AV's posterior over
    ``p_a`` at the end of each interaction is the next one's prior (the first's is
    ``p_a_prior``, default the Beta prior); every other AV starts each interaction afresh, as
    the human does (its role belief and role start from the configuration).
    ``interactions``: default ``simulation.interactions`` (unset: 1)."""
    if interactions is None:
        interactions = config.simulation.interactions or 1
    if isinstance(interactions, bool) or not isinstance(interactions, (int, np.integer)) \
            or not 1 <= interactions <= 10**6:
        raise ConfigError(f"interactions = {interactions!r} is out of range; allowed: "
                          "integer in [1, 1000000]")
    out: list[RunRecord] = []
    prior = p_a_prior
    for k in range(int(interactions)):
        record = simulate(config, seed, interaction=k, p_a_prior=prior)
        if record.p_a_posterior is not None:
            prior = record.p_a_posterior
        out.append(record)
    return out


#: Per-interaction values of :func:`run_summary` (``by_interaction.<name>.<k>``).
BY_INTERACTION = ("first_at_line", "infeasible_steps", "collision", "hv_role_changes",
                  "pa_hat_final")


def run_summary(config: Config, seed: int) -> dict:
    """The summary of the run of ``seed`` (``RunRecord.summary``). With
    ``simulation.interactions = K > 1``: the last interaction's summary, plus
    ``interactions = K`` and ``by_interaction``, a list per :data:`BY_INTERACTION` value
    (``pa_hat_final`` only online) over the K interactions (what the sweeps and ``compare``
    store). With ``scenario.kind = "junction"``: the junction run's row
    (``persuasive.many.world.run_summary``)."""
    if config.scenario.kind == "junction":  # N vehicles: persuasive.many's row
        from .many.world import run_summary as junction_summary

        return junction_summary(config, seed)
    k = config.simulation.interactions or 1
    if k == 1:
        return simulate(config, seed).summary()
    summaries = [r.summary() for r in simulate_interactions(config, seed, k)]
    out = dict(summaries[-1])
    out["interactions"] = k
    out["by_interaction"] = {name: [s[name] for s in summaries] for name in BY_INTERACTION
                             if name in summaries[0]}
    return out


__all__ = ["ARRIVAL_LABELS", "BY_INTERACTION", "RunOutcome", "RunRecord", "check_interaction",
           "check_seed", "load_record", "run_summary", "simulate", "simulate_interactions"]
