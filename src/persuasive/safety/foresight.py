"""Foresight: the AV picks its yield line by predicting the run (docs/method.md §12.12).

A yield line before the human's 7.5 m circle ends the standoffs of the shield (§12.8) and
costs persuasion: the AV must decide earlier whether it stops there. Which of the two a run
needs depends on the run: with perfect foresight of the paper's human, picking the line per run
among a few keeps both (``benchmarks/oracle_ceiling.py``, results §15.15). This module gives
the AV that foresight from its *own* model of the human, not from the human.

With ``av.yield_line_choices_m = [y_1, ..., y_n]`` the AV, before the run, for each line
``y_i`` and each model human ``h`` of :data:`MODELS`, simulates the whole run
(``simulation.n_steps``) with

- itself as configured (kind, planner, shield with the line ``y_i``, its own random stream),
- ``h`` in the human's seat: the LFG player with ``roles.p_a = p_a_hat`` (the persuasive
  planner's own model of the human, §6) starting as leader, and starting as follower (its
  prior, ``roles.prior_leader`` in (0, 1), allows both), and the LFG player that keeps the
  leader's role (``stubborn``, ``p_a = 0``): a human that goes when the way is free, which the
  issue's liveness asks never to block, and which the adaptive model does not foresee (with
  the adaptive model alone, runs against ``stubborn`` at the paper's intersection still ended
  in standoffs where the line at the interval was picked); and the Boltzmann-rational LFG
  (``noisy``, with the configuration's ``hv.noisy.beta`` and ``p_a = p_a_hat``) starting as
  leader and as follower: a human that now and then takes a worse option, whose one sampled
  run (from the predictions' own random stream) shows a line on which such a choice ends in
  a standoff (with the first three models alone, seed 304 against the ``noisy`` human at the
  paper's intersection did, results §15.15);
- from the initial state as it measures it (the loop's own step-0 measurement,
  ``persuasive.streams.measure_states``),
  with no noise (it cannot know the run's noise), and with random numbers of its own: the
  predictions run with the seed :func:`prediction_seed` (the run's seed XOR a constant), so
  the model human's role draws are not the run's human's (an AV that draws, the ``lfg`` AV,
  draws differently in its predictions too),

and values each line by, in this order, (1) how many of the model humans' runs end with both
vehicles through and no standoff (``both_cleared`` and not ``deadlock``), (2) in how many the
AV passes the conflict point first, (3) the AV's time to clear in the slowest of them (the
run's length where it never cleared), shorter better; it picks the line of the highest value,
ties to the earlier line of the list. Liveness first and under every model: a line on which any
model human ends in a standoff loses to one on which none does; then persuasion, counted over
the models (a line that persuades the model human in either role beats one that persuades
none, even where the stubborn one cannot be persuaded on any line). The run then drives with that line, exactly as a run configured with
``av.yield_line_m = y`` does, and its summary carries ``yield_line_m``.

The choice only sets where the shield's line stands: every step is still filtered by the
shield, so every guarantee of §12 holds whichever line is picked. What foresight does not
know is a human unlike its models: a human that waits for the AV to commit (a follower that
never takes the lead) may still keep it waiting, as the issue allows. It costs at most ``5 n``
model runs once per run (about 6 ms each at the paper's intersection), before the first step,
not in the per-step budget.

**Cost, with the same pick** (issue 42; :func:`choose_line_reference` is the plain
computation, and ``tests/test_replay_speed.py`` holds the two equal on random states):

- *a line that cannot win is not finished*: after ``j`` of a line's ``m`` model runs, its
  value can at most reach (live so far ``+ (m - j)``, AV first so far ``+ (m - j)``, the
  slowest clear so far), each model run adding at most one to the counts and the slowest
  clear only falling; where that bound is not above the best value so far (a tie goes to the
  earlier line), the line's other runs are skipped;
- *a predicted run ends once it is decided*: with the compiled loop's predictions
  (``persuasive.world.predicted_summary``, what both loops hand in, scored by its ``score``,
  ``persuasive.world.predicted_score``) the run stops at the first state at which both
  vehicles are past their clearing position and the conflict point
  (``persuasive.world.predicted_states``). Positions never fall (speeds are at least
  ``v_min >= 0``), so from there on both stay cleared, who reached the conflict point first is
  settled, the AV's time to clear is known, and no standoff can start (a standoff needs both
  vehicles short of clearing): the score (``persuasive.world.score_states``) is the whole
  run's. Only the
  four fields the score reads are computed, not the run's record.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import Config

#: The model humans of the prediction: (``hv.kind``, its initial ``hv.role``).
MODELS = (("lfg", "leader"), ("lfg", "follower"), ("stubborn", "leader"), ("noisy", "leader"),
          ("noisy", "follower"))


def model_config(config: Config, line: float, kind: str, role: str) -> Config:
    """The configuration of the AV's prediction with ``line`` and the model human ``kind``
    starting in ``role`` (module docstring): the run's, with ``roles.p_a = p_a_hat`` (so that
    the AV's own estimate is unchanged), no noise."""
    return config.with_overrides({
        "av.yield_line_choices_m": None, "av.yield_line_m": line, "hv.kind": kind,
        "hv.role": role, "roles.p_a": config.p_a_hat,
        "simulation.measurement_noise": "none", "simulation.accel_noise_mps2": 0.0})


def score(summary: dict, run_s: float) -> tuple[bool, bool, float]:
    """A predicted run's score: (live, AV first through, -AV clear time)."""
    live = bool(summary["both_cleared"]) and not bool(summary["deadlock"])
    clear = summary["av_time_to_clear_s"]
    clear = run_s if clear is None or not math.isfinite(clear) else min(clear, run_s)
    return live, bool(summary["av_first_through"]), -clear


def line_value(scores) -> tuple[int, int, float]:
    """A line's value from the :func:`score` of each of its predicted runs, larger is
    better: (runs live, runs with the AV first through, -the slowest AV clear time)."""
    return (sum(s[0] for s in scores), sum(s[1] for s in scores), min(s[2] for s in scores))


#: What the predictions' seed differs from the run's by (XOR): any constant would do, one
#: that changes many bits.
PREDICTION_SEED_XOR = 0x5DEECE6


def prediction_seed(seed: int) -> int:
    """The seed of the predictions of the run of ``seed``: a random stream the run's human
    never draws from (the run's streams come from ``seed`` itself)."""
    return int(seed) ^ PREDICTION_SEED_XOR


def choose_line(config: Config, seed: int, x0_measured: np.ndarray, predict,
                interaction: int = 0) -> float:
    """The yield line the AV picks for the run (module docstring). ``predict(config, seed,
    interaction, x0) -> summary``: a predicted run's summary (the loops hand in
    ``persuasive.world.predicted_summary``, the compiled loop's). A ``predict`` with a
    ``score(config, seed, interaction, x0, run_s)`` attribute (``predicted_summary``'s:
    ``persuasive.world.predicted_score``, the run stopped once decided) is scored by it. The
    same line as :func:`choose_line_reference`, with fewer and shorter model runs (module
    docstring, "Cost")."""
    run_s = config.simulation.n_steps * config.simulation.dt_s
    p_seed = prediction_seed(seed)
    fast = getattr(predict, "score", None)  # the compiled loop's: a run stopped once decided
    if fast is not None:
        def score_of(model: Config):
            return fast(model, p_seed, interaction, x0_measured, run_s)
    else:
        def score_of(model: Config):
            return score(predict(model, p_seed, interaction, x0_measured), run_s)
    best, pick = None, None
    for line in config.yield_line_choices:
        value = bounded_line_value((score_of(model_config(config, line, kind, role))
                                    for kind, role in MODELS), len(MODELS), best)
        if value is not None and (best is None or value > best):
            best, pick = value, line
    return pick


def bounded_line_value(scores, m: int, best) -> tuple[int, int, float] | None:
    """:func:`line_value` of the ``m`` :func:`score` that ``scores`` yields, drawn one at a
    time, or None as soon as the line cannot beat ``best`` (None: nothing to beat): its
    value after ``j`` of them can at most reach (live ``+ (m - j)``, first ``+ (m - j)``, the
    slowest clear so far), and a line wins only with a value above the best so far."""
    live = first = 0
    slowest = math.inf
    left = m
    for s in scores:
        left -= 1
        live += s[0]
        first += s[1]
        slowest = min(slowest, s[2])
        if best is not None and (live + left, first + left, slowest) <= best:
            return None
    return live, first, slowest


def choose_line_reference(config: Config, seed: int, x0_measured: np.ndarray, predict,
                          interaction: int = 0) -> float:
    """:func:`choose_line` computed plainly: every model run of every line, whole, through
    ``predict``'s summaries (what the tests hold the fast path to)."""
    run_s = config.simulation.n_steps * config.simulation.dt_s
    best, pick = None, None
    for line in config.yield_line_choices:
        value = line_value([score(predict(model_config(config, line, kind, role),
                                          prediction_seed(seed), interaction, x0_measured),
                                  run_s)
                            for kind, role in MODELS])
        if best is None or value > best:
            best, pick = value, line
    return pick


__all__ = ["MODELS", "PREDICTION_SEED_XOR", "bounded_line_value", "choose_line",
           "choose_line_reference", "line_value", "model_config", "prediction_seed", "score"]
