"""Baselines for "who passes first", from the state of a pair at its prediction moment
(docs/guide/fit.md, "Held-out evaluation on recorded pairs").

Every baseline reads the :class:`Features` of a pair, what is seen up to the prediction moment
(:mod:`persuasive.recordings.evaluate` states the moment): per vehicle ``i`` in 1, 2 its
distance to the conflict point ``d_i = -s_i`` [m], speed ``v_i`` [m/s], acceleration ``a_i``
[m/s^2], direction of travel and occupancy interval. Anything a baseline needs to be scaled
or capped with is fitted on the training files only (:meth:`Baselines.fit`), and each
predicts ``P(vehicle 1 passes first)``:

- ``majority``: the training share of "vehicle 1 first", ``(n_1 + 1) / (n + 2)``;
- ``arrive_cv``, ``arrive_ca``: first to arrive at the conflict point, at constant speed or
  at constant acceleration: arrival times ``t_i = d_i / max(v_i, 0.1 m/s)``, or the first
  root of ``d_i = v_i t + a_i t^2 / 2`` (``2 d / (v + sqrt(v^2 + 2 a d))``; never, when the
  vehicle stops first), each capped at ``cap``; ``P = sigmoid(w (t_2 - t_1))`` with the scale
  ``w >= 0`` and the cap (one of :data:`CAPS_S`) of the largest training likelihood;
- ``logistic_gap``: logistic regression (gap acceptance) on the differences of the
  constant-speed arrival times (capped at 30 s), of the speeds and of the distances,
  standardised by the training means and deviations, with a ridge penalty
  ``RIDGE / 2 |w|^2`` on the weights (not the intercept): a Normal(0, 1) prior on each
  standardised weight, which keeps them finite when the training pairs are separable;
- ``right_of_way``: the junction's rule. Where the pairs were found with a Lanelet2 map
  (``recordings pairs --map``, :mod:`persuasive.recordings.lanelet_map`), the map's: its
  right of way where it gives one; at an all-way stop, arrival order: the vehicle that reached
  its stop line (within :data:`ARRIVED_M` of it) first goes first, a vehicle not there yet
  arriving at constant speed from the moment (a stop line the map does not give is taken at
  the start of the vehicle's occupancy interval). Where there is no map, or the map has no
  rule for the two lanelets, the vehicle from the right goes first (the right-before-left
  rule of an unsigned junction): at a crossing vehicle 1 has the right of way when it comes
  from vehicle 2's right, ``cross(u_2, u_1) > 0`` for the directions of travel ``u`` (x east,
  y north); in a merge the vehicle already in the lane (vehicle 2) has it;
- ``sumo_rule``: SUMO's junction rule: the vehicle without the right of way goes first only
  if, at constant speed, it leaves its occupancy interval at least ``SUMO_GAP_S`` (1 s)
  before the other enters its own; otherwise the one with the right of way goes first.

The two rules give a yes or no; their probability is the training share of pairs where the
rule was right, ``(hits + 1) / (n + 2)``, given to the side the rule names (the same for a
forward rollout of the IDM, :mod:`persuasive.recordings.evaluate`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: The floor of a speed in an arrival time [m/s] (the IDM's own floor, persuasive.policies.idm).
V_FLOOR = 0.1
#: The caps of an arrival time the first-to-arrive baselines choose from [s].
CAPS_S = (3.0, 5.0, 10.0, 20.0, 30.0)
#: The cap of the arrival times the logistic gap acceptance reads [s].
LOGISTIC_CAP_S = 30.0
#: Ridge penalty on the logistic gap acceptance's standardised weights.
RIDGE = 1.0
#: SUMO's gap for the vehicle without the right of way [s] (jmTimegapMinor's default).
SUMO_GAP_S = 1.0
#: A vehicle within this of its stop line has arrived at it (all-way stops) [m].
ARRIVED_M = 2.0
#: The baselines, in the order reported.
BASELINES = ("majority", "arrive_cv", "arrive_ca", "logistic_gap", "right_of_way",
             "sumo_rule", "role_belief")
#: What each is, in a table.
BASELINE_NAMES = {
    "majority": "majority",
    "arrive_cv": "first to arrive, constant speed",
    "arrive_ca": "first to arrive, constant acceleration",
    "logistic_gap": "logistic gap acceptance",
    "right_of_way": "right of way (the map's, else from the right)",
    "sumo_rule": "SUMO's rule (1 s gap)",
    "role_belief": "role belief, online (Bayes, §5.5)",
}


@dataclass(frozen=True)
class Features:
    """What each pair shows at its prediction moment; arrays ``(n, 2)`` per vehicle 1, 2
    unless stated: ``s`` [m] (relative to the conflict point, negative before it), ``v``
    [m/s], ``a`` [m/s^2], ``direction`` [rad] (of travel, x east, y north), ``occ_lo``,
    ``occ_hi`` [m] (the occupancy interval), ``merge`` ``(n,)``; from a map (None: no map
    for any pair): ``priority`` ``(n,)`` (1, 2: the vehicle with the right of way, 0: none),
    ``all_way`` ``(n,)`` (an all-way stop), ``stop_arrival`` [s] (when each reached its stop
    line, relative to the moment: negative when it has, positive at constant speed when it has
    not)."""

    s: np.ndarray
    v: np.ndarray
    a: np.ndarray
    direction: np.ndarray
    occ_lo: np.ndarray
    occ_hi: np.ndarray
    merge: np.ndarray = field(repr=False)
    priority: np.ndarray | None = field(default=None, repr=False)
    all_way: np.ndarray | None = field(default=None, repr=False)
    stop_arrival: np.ndarray | None = field(default=None, repr=False)

    @property
    def n(self) -> int:
        return int(self.s.shape[0])

    def take(self, idx) -> Features:
        pick = (lambda x: None if x is None else x[idx])
        return Features(self.s[idx], self.v[idx], self.a[idx], self.direction[idx],
                        self.occ_lo[idx], self.occ_hi[idx], self.merge[idx],
                        pick(self.priority), pick(self.all_way), pick(self.stop_arrival))


def arrival_cv(f: Features) -> np.ndarray:
    """Arrival times at the conflict point at constant speed ``(n, 2)`` [s] (uncapped)."""
    return np.maximum(-f.s, 0.0) / np.maximum(f.v, V_FLOOR)


def arrival_ca(f: Features) -> np.ndarray:
    """Arrival times at constant acceleration ``(n, 2)`` [s]: the first root of ``d = v t +
    a t^2 / 2``; inf when the vehicle stops before it (uncapped)."""
    d = np.maximum(-f.s, 0.0)
    v = np.maximum(f.v, 0.0)
    disc = v * v + 2.0 * f.a * d
    den = v + np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where((disc >= 0.0) & (den > 0.0), 2.0 * d / den, np.inf)
    return np.where(d == 0.0, 0.0, t)


def right_of_way(f: Features) -> np.ndarray:
    """1 where vehicle 1 has the right of way, else 0 ``(n,)`` (module docstring)."""
    u1 = np.stack([np.cos(f.direction[:, 0]), np.sin(f.direction[:, 0])], axis=1)
    u2 = np.stack([np.cos(f.direction[:, 1]), np.sin(f.direction[:, 1])], axis=1)
    from_right = u2[:, 0] * u1[:, 1] - u2[:, 1] * u1[:, 0] > 0.0
    rule = np.where(f.merge, 0, from_right.astype(np.int64))
    if f.priority is not None:
        rule = np.where(f.priority == 1, 1, np.where(f.priority == 2, 0, rule))
    if f.all_way is not None:
        first = (f.stop_arrival[:, 0] <= f.stop_arrival[:, 1]).astype(np.int64)
        rule = np.where(f.all_way, first, rule)
    return rule


def sumo_rule(f: Features, gap_s: float = SUMO_GAP_S) -> np.ndarray:
    """1 where SUMO's rule lets vehicle 1 go first, else 0 ``(n,)`` (module docstring)."""
    major = right_of_way(f)  # 1: vehicle 1 has the right of way
    v = np.maximum(f.v, V_FLOOR)
    t_in = np.maximum(f.occ_lo - f.s, 0.0) / v
    t_out = np.maximum(f.occ_hi - f.s, 0.0) / v
    idx = np.arange(f.n)
    major_col, minor_col = 1 - major, major  # columns: 0 is vehicle 1
    minor_goes = t_in[idx, major_col] - t_out[idx, minor_col] >= gap_s
    # vehicle 1 first: it is the major and the minor does not go, or it is the minor and goes
    return np.where(major == 1, ~minor_goes, minor_goes).astype(np.int64)


def _sigmoid(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * np.asarray(z, float)))


def _loglik(y: np.ndarray, p: np.ndarray) -> float:
    p = np.clip(p, 1e-12, 1.0 - 1e-12)
    return float(np.sum(y * np.log(p) + (1.0 - y) * np.log1p(-p)))


def fit_scale(dt: np.ndarray, y: np.ndarray) -> float:
    """The scale ``w >= 0`` [1/s] maximising ``sum log P(y | sigmoid(w dt))`` (bounded to
    [0, 100])."""
    from scipy.optimize import minimize_scalar

    if dt.size == 0:
        return 0.0
    res = minimize_scalar(lambda w: -_loglik(y, _sigmoid(w * dt)), bounds=(0.0, 100.0),
                          method="bounded", options={"xatol": 1e-6})
    return float(res.x)


def fit_logistic(X: np.ndarray, y: np.ndarray, ridge: float = RIDGE) -> np.ndarray:
    """Ridge logistic regression ``(k + 1,)``: the intercept, then the weights of ``X``
    ``(n, k)`` (the penalty ``ridge / 2 |w|^2`` leaves the intercept free)."""
    from scipy.optimize import minimize

    n, k = X.shape
    A = np.hstack([np.ones((n, 1)), X])

    def f(beta):
        z = A @ beta
        # -log-likelihood = sum log(1 + e^z) - y z, stably
        nll = float(np.sum(np.logaddexp(0.0, z) - y * z))
        grad = A.T @ (_sigmoid(z) - y)
        nll += 0.5 * ridge * float(beta[1:] @ beta[1:])
        grad[1:] += ridge * beta[1:]
        return nll, grad

    res = minimize(f, np.zeros(k + 1), jac=True, method="L-BFGS-B")
    return np.asarray(res.x, float)


def rule_hit_rate(rule: np.ndarray, y: np.ndarray) -> float:
    """``(hits + 1) / (n + 2)``: how often a yes-or-no rule named the first passer."""
    return float((np.sum(rule == y) + 1.0) / (y.size + 2.0))


def rule_probability(rule: np.ndarray, hit: float) -> np.ndarray:
    """``P(vehicle 1 first)`` of a rule right with probability ``hit``."""
    return np.where(rule == 1, hit, 1.0 - hit)


def _gap_design(f: Features) -> np.ndarray:
    t = np.minimum(arrival_cv(f), LOGISTIC_CAP_S)
    d = -f.s
    return np.stack([t[:, 0] - t[:, 1], f.v[:, 0] - f.v[:, 1], d[:, 0] - d[:, 1]], axis=1)


@dataclass
class Baselines:
    """The fitted baselines (module docstring); :meth:`fit`, then :meth:`predict`."""

    share_1: float = 0.5  #: majority: training share of vehicle 1 first
    cv: tuple[float, float] = (0.0, CAPS_S[-1])  #: (scale [1/s], cap [s])
    ca: tuple[float, float] = (0.0, CAPS_S[-1])
    mean: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    beta: np.ndarray = field(default_factory=lambda: np.zeros(4))
    row_hit: float = 0.5  #: right of way's training hit rate
    sumo_hit: float = 0.5

    @classmethod
    def fit(cls, f: Features, y: np.ndarray) -> Baselines:
        """Fit every scale, cap and weight on the training pairs ``f``, outcomes ``y``."""
        y = np.asarray(y, float)
        out = cls()
        out.share_1 = float((y.sum() + 1.0) / (y.size + 2.0))
        for name, times in (("cv", arrival_cv(f)), ("ca", arrival_ca(f))):
            best = None
            for cap in CAPS_S:
                t = np.minimum(times, cap)
                dt = t[:, 1] - t[:, 0]
                w = fit_scale(dt, y)
                ll = _loglik(y, _sigmoid(w * dt))
                if best is None or ll > best[0] + 1e-12:
                    best = (ll, w, cap)
            setattr(out, name, (best[1], best[2]))
        X = _gap_design(f)
        if y.size:
            out.mean = X.mean(axis=0)
            sd = X.std(axis=0)
            out.scale = np.where(sd > 0, sd, 1.0)
        out.beta = fit_logistic((X - out.mean) / out.scale, y)
        out.row_hit = rule_hit_rate(right_of_way(f), y)
        out.sumo_hit = rule_hit_rate(sumo_rule(f), y)
        return out

    def predict(self, f: Features) -> dict[str, np.ndarray]:
        """``P(vehicle 1 first)`` ``(n,)`` of every baseline but ``role_belief`` (which needs
        the re-solved game: :mod:`persuasive.recordings.evaluate`)."""
        out = {"majority": np.full(f.n, self.share_1)}
        for name, times in (("arrive_cv", arrival_cv(f)), ("arrive_ca", arrival_ca(f))):
            w, cap = self.cv if name == "arrive_cv" else self.ca
            t = np.minimum(times, cap)
            out[name] = _sigmoid(w * (t[:, 1] - t[:, 0]))
        X = (_gap_design(f) - self.mean) / self.scale
        out["logistic_gap"] = _sigmoid(self.beta[0] + X @ self.beta[1:])
        out["right_of_way"] = rule_probability(right_of_way(f), self.row_hit)
        out["sumo_rule"] = rule_probability(sumo_rule(f), self.sumo_hit)
        return out

    def to_dict(self) -> dict:
        return {"majority_share_1": self.share_1,
                "arrive_cv": {"scale_per_s": self.cv[0], "cap_s": self.cv[1]},
                "arrive_ca": {"scale_per_s": self.ca[0], "cap_s": self.ca[1]},
                "logistic_gap": {"intercept": float(self.beta[0]),
                                 "weights_standardised": [float(b) for b in self.beta[1:]],
                                 "features": ["t_cv_1 - t_cv_2 [s]", "v_1 - v_2 [m/s]",
                                              "d_1 - d_2 [m]"],
                                 "mean": [float(m) for m in self.mean],
                                 "sd": [float(s) for s in self.scale]},
                "right_of_way_hit_rate": self.row_hit, "sumo_rule_hit_rate": self.sumo_hit}


__all__ = ["ARRIVED_M", "BASELINES", "BASELINE_NAMES", "Baselines", "CAPS_S", "Features",
           "LOGISTIC_CAP_S",
           "RIDGE", "SUMO_GAP_S", "V_FLOOR", "arrival_ca", "arrival_cv", "fit_logistic",
           "fit_scale", "right_of_way", "rule_hit_rate", "rule_probability", "sumo_rule"]
