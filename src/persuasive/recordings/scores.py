"""Scores of probabilistic predictions of a binary outcome, and their bootstrap over
clusters (docs/guide/fit.md, "Held-out evaluation on recorded pairs").

The outcome is ``y`` in {0, 1} (1: vehicle 1 passed the conflict point first), a prediction
is ``p = P(y = 1)``; arrays ``(n,)``, one entry per pair.

- **accuracy**: the share of pairs whose outcome is the likelier one under ``p``; a
  prediction of exactly 0.5 counts half;
- **AUC**: the area under the ROC curve by ranks (Mann-Whitney): ``(R_1 - n_1 (n_1 + 1) / 2)
  / (n_1 n_0)``, ``R_1`` the sum of the positives' ranks among all predictions, ties given
  their average rank; NaN when one class is absent;
- **Brier score**: ``mean((p - y)^2)``;
- **log-loss**: ``-mean(y log p + (1 - y) log(1 - p))``, with ``p`` clipped to ``[eps, 1 -
  eps]`` (:data:`CLIP_P`: one pair never costs more than ``log(1000) = 6.9`` nats);
- **calibration**: the predictions in :data:`N_BINS` bins of width 0.1 (the last closed),
  per bin the count, the mean prediction and the observed share of ``y = 1``; the expected
  calibration error (ECE) is the count-weighted mean of ``|observed - mean prediction|``.

**Bootstrap over clusters.** Pairs of one recording file share their traffic, site and
hour, so they are not independent; an interval that resampled pairs would be too narrow.
:func:`bootstrap` resamples whole clusters (recording files) with replacement, ``B`` times
from ``numpy.random.default_rng(seed)``, recomputes a statistic on the pairs (or steps) of the
drawn clusters, a cluster drawn twice counting twice, and gives the 2.5 % and 97.5 %
percentiles of the statistics that are defined (a resample with one class has no AUC; the
count of those is reported). Every score takes the resamples as a weight matrix ``(B, n)``
(how often each pair is drawn), so all resamples are scored in a few array operations.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

#: Predictions are clipped to [CLIP_P, 1 - CLIP_P] for the log-loss.
CLIP_P = 1e-3
#: Calibration bins of width 1 / N_BINS.
N_BINS = 10


def _weights(y: np.ndarray, w) -> tuple[np.ndarray, bool]:
    """``w`` as ``(B, n)`` (ones for None) and whether it was one row."""
    if w is None:
        return np.ones((1, y.size)), True
    w = np.asarray(w, float)
    return (w[None], True) if w.ndim == 1 else (w, False)


def _out(values: np.ndarray, single: bool):
    return float(values[0]) if single else values


def _mean(values: np.ndarray, w: np.ndarray) -> np.ndarray:
    total = w.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, (w @ values) / np.where(total > 0, total, 1.0), np.nan)


def accuracy(y: np.ndarray, p: np.ndarray, w=None):
    """Share of correct calls (module docstring); NaN for no pair. ``w``: weights ``(n,)``, or
    one row per resample ``(B, n)`` (then one value per row)."""
    y, p = np.asarray(y, float), np.asarray(p, float)
    w, single = _weights(y, w)
    hit = np.where(p > 0.5, y == 1, np.where(p < 0.5, y == 0, 0.5)).astype(float)
    return _out(_mean(hit, w), single)


def auc(y: np.ndarray, p: np.ndarray, w=None):
    """The ROC area by ranks, ties at their average rank (with weights: each pair counted
    ``w`` times); NaN when one class is absent."""
    y, p = np.asarray(y, float), np.asarray(p, float)
    w, single = _weights(y, w)
    if y.size == 0:
        return _out(np.full(w.shape[0], np.nan), single)
    order = np.argsort(p, kind="stable")
    ps, ys, ws = p[order], y[order], w[:, order]
    starts = np.flatnonzero(np.concatenate([[True], ps[1:] != ps[:-1]]))
    pos = np.add.reduceat(ws * (ys == 1), starts, axis=1)  # (B, groups): weight of positives
    neg = np.add.reduceat(ws * (ys == 0), starts, axis=1)
    below = np.cumsum(neg, axis=1) - neg  # negatives strictly below each group's value
    n1, n0 = pos.sum(axis=1), neg.sum(axis=1)
    num = np.sum(pos * (below + 0.5 * neg), axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where((n1 > 0) & (n0 > 0), num / np.where(n1 * n0 > 0, n1 * n0, 1.0), np.nan)
    return _out(out, single)


def brier(y: np.ndarray, p: np.ndarray, w=None):
    """``mean((p - y)^2)``."""
    y, p = np.asarray(y, float), np.asarray(p, float)
    w, single = _weights(y, w)
    return _out(_mean((p - y) ** 2, w), single)


def log_loss(y: np.ndarray, p: np.ndarray, w=None, eps: float = CLIP_P):
    """Mean negative log-likelihood [nats per pair], ``p`` clipped to ``[eps, 1 - eps]``."""
    y = np.asarray(y, float)
    p = np.clip(np.asarray(p, float), eps, 1.0 - eps)
    w, single = _weights(y, w)
    return _out(_mean(-(y * np.log(p) + (1.0 - y) * np.log1p(-p)), w), single)


def _bins(p: np.ndarray, n_bins: int) -> np.ndarray:
    return np.minimum((np.asarray(p, float) * n_bins).astype(np.int64), n_bins - 1)


def calibration(y: np.ndarray, p: np.ndarray, n_bins: int = N_BINS) -> list[dict]:
    """Per bin of ``p`` (width ``1 / n_bins``, the last closed): ``lo``, ``hi``, ``n``,
    ``mean_p``, ``observed`` (None in an empty bin)."""
    y, p = np.asarray(y, float), np.asarray(p, float)
    k = _bins(p, n_bins)
    out = []
    for b in range(n_bins):
        sel = k == b
        n = int(sel.sum())
        out.append({"lo": b / n_bins, "hi": (b + 1) / n_bins, "n": n,
                    "mean_p": float(p[sel].mean()) if n else None,
                    "observed": float(y[sel].mean()) if n else None})
    return out


def ece(y: np.ndarray, p: np.ndarray, w=None, n_bins: int = N_BINS):
    """Expected calibration error: the count-weighted mean over the bins of ``|observed -
    mean p|``."""
    y, p = np.asarray(y, float), np.asarray(p, float)
    w, single = _weights(y, w)
    onehot = _bins(p, n_bins)[:, None] == np.arange(n_bins)[None, :]  # (n, bins)
    count = w @ onehot
    gap = np.abs(w @ (onehot * y[:, None]) - w @ (onehot * p[:, None]))  # per bin, summed
    total = count.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(total > 0, gap.sum(axis=1) / np.where(total > 0, total, 1.0), np.nan)
    return _out(out, single)


#: The pair scores, by name, in the order reported.
PAIR_SCORES: dict[str, Callable] = {
    "accuracy": accuracy, "auc": auc, "brier": brier, "log_loss": log_loss, "ece": ece}


@dataclass(frozen=True)
class Interval:
    """A statistic on the whole sample and its bootstrap percentile interval."""

    value: float
    low: float
    high: float
    resamples: int  #: resamples where the statistic was defined

    def to_dict(self) -> dict:
        def num(x):
            return None if x is None or not np.isfinite(x) else float(x)

        return {"value": num(self.value), "ci95": [num(self.low), num(self.high)],
                "resamples": self.resamples}


def cluster_weights(clusters: Sequence, n_boot: int, seed: int,
                    names: Sequence | None = None) -> np.ndarray:
    """``(n_boot, n)``: how often each unit (labelled by its cluster in ``clusters``, ``(n,)``)
    is drawn in each bootstrap resample. A resample draws as many clusters as ``names`` holds
    (default: the labels present, sorted), with replacement from
    ``numpy.random.default_rng(seed)``, and takes every unit of a drawn cluster as often as
    the cluster was drawn. Two calls with the same ``names``, ``n_boot`` and ``seed`` draw the
    same clusters, whatever their units."""
    clusters = np.asarray(clusters, dtype=object)
    names = sorted(set(clusters.tolist())) if names is None else list(names)
    where = {c: i for i, c in enumerate(names)}
    code = np.array([where[c] for c in clusters], np.int64)
    rng = np.random.default_rng(seed)
    drawn = rng.integers(0, max(len(names), 1), (n_boot, len(names)))
    counts = np.zeros((n_boot, max(len(names), 1)))
    np.add.at(counts, (np.repeat(np.arange(n_boot), len(names)), drawn.ravel()), 1.0)
    return counts[:, code] if code.size else np.zeros((n_boot, 0))


def bootstrap(stat: Callable, weights: np.ndarray) -> Interval:
    """``stat(w)`` with unit weights ``w`` (ones: the whole sample; ``(B, n)``: one value per
    resample, :func:`cluster_weights`); the 95 % percentile interval of the defined values."""
    value = float(stat(np.ones(weights.shape[1])))
    vals = np.asarray(stat(weights), float)
    vals = vals[np.isfinite(vals)]
    if vals.size == 0:
        return Interval(value, float("nan"), float("nan"), 0)
    lo, hi = np.percentile(vals, [2.5, 97.5])
    return Interval(value, float(lo), float(hi), int(vals.size))


__all__ = ["CLIP_P", "Interval", "N_BINS", "PAIR_SCORES", "accuracy", "auc", "bootstrap",
           "brier", "calibration", "cluster_weights", "ece", "log_loss"]
