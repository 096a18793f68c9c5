"""Fitting the IDM driver with gap acceptance (docs/method.md §11.2, §13.3).

The IDM human is deterministic given its parameters and the logged states: its waiting time
and its commitment follow the measured states, and its acceleration at each step is
``persuasive.policies.idm.idm_step``'s (the kernel the simulation runs). The emission is
``N(x_k; a_idm,k, sigma^2)``, so for given IDM parameters the log-likelihood is maximised over
``sigma`` in closed form, ``sigma^2 = max(SSE / n, sigma_min^2)``.

Fitted: the desired speed ``v0``, the time gap ``T``, the maximum acceleration ``a``, the
comfortable deceleration ``b`` (on log scales) and the gap acceptance: the critical gap
``critical_gap_s`` and its shrinking with waiting ``impatience_per_s``. ``delta`` and the jam
distance ``s0`` stay at the log's configuration (they shape the approach to a standstill, which
the logs rarely show). The gap parameters enter through a threshold (go or yield), so the
likelihood is piecewise constant in them: the maximisation alternates Nelder-Mead over all six
with fine scans of the two gap parameters.

Intervals: ``sigma`` by its exact profile likelihood (the best IDM parameters do not depend on
``sigma``); the four smooth parameters by the observed information on their log scale (Wald);
the two gap parameters by the likelihood ratio along their scan, the others held at their
estimates (the likelihood is a step function in them, so no curvature exists).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq, minimize

from .estimate import DROP_ONE_SIDED, DROP_TWO_SIDED, SIGMA_MIN, Estimate, ModelFit
from .evidence import Evidence
from .estimate import PARALLEL_WORK
from .models import IDM_NAMES, idm_sse, idm_sse_serial

#: The fitted IDM parameters: (name, lower bound, upper bound, log scale).
FITTED = (("desired_speed_mps", 1.0, 30.0, True), ("time_gap_s", 0.05, 5.0, True),
          ("max_accel_mps2", 0.1, 5.0, True), ("comfort_decel_mps2", 0.1, 8.0, True),
          ("critical_gap_s", 0.0, 10.0, False), ("impatience_per_s", 0.0, 2.0, False))
_SLOTS = [IDM_NAMES.index(name) for name, *_ in FITTED]
_LOG = np.array([log for *_, log in FITTED])
_LO = np.array([math.log(lo) if log else lo for _, lo, _, log in FITTED])
_HI = np.array([math.log(hi) if log else hi for _, _, hi, log in FITTED])
GAP_GRID = np.round(np.arange(0.0, 6.0001, 0.05), 10)
IMPATIENCE_GRID = np.round(np.arange(0.0, 1.0001, 0.01), 10)


class IDMObjective:
    """The IDM's sum of squared residuals and log-likelihood for batches of parameter rows."""

    def __init__(self, ev: Evidence, base: np.ndarray, sigma_min: float):
        self.ev, self.base, self.sigma_min = ev, base, sigma_min
        self.evaluations = 0

    def params(self, Y: np.ndarray) -> np.ndarray:
        """Full IDM parameter rows ``(M, 8)`` from fitted coordinates ``Y`` ``(M, 6)``."""
        Y = np.atleast_2d(Y)
        prm = np.tile(self.base, (len(Y), 1))
        prm[:, _SLOTS] = np.where(_LOG, np.exp(Y), Y)
        return prm

    def sse(self, Y: np.ndarray) -> np.ndarray:
        ev = self.ev
        prm = self.params(Y)
        out = np.empty((ev.n_runs, len(prm)))
        work = ev.n_steps * len(prm)
        kernel = idm_sse if work >= PARALLEL_WORK and ev.n_runs > 1 else idm_sse_serial
        kernel(ev.starts, ev.states, ev.accel, ev.P_hv, ev.P_av, ev.dt, prm, out)
        self.evaluations += len(prm)
        return out

    def loglik(self, Y: np.ndarray) -> np.ndarray:
        return loglik_of_sse(self.sse(Y).sum(axis=0), self.ev.n_steps, self.sigma_min)[0]


def loglik_of_sse(sse: np.ndarray, n: int, sigma_min: float):
    """``(loglik, sigma)`` with ``sigma`` maximising the Gaussian likelihood, floored."""
    sigma = np.sqrt(np.maximum(np.asarray(sse, float) / n, sigma_min ** 2))
    ll = -n * np.log(sigma) - 0.5 * n * math.log(2.0 * math.pi) - sse / (2.0 * sigma ** 2)
    return ll, sigma


def fit_idm(ev: Evidence, sigma_min: float = SIGMA_MIN, intervals: bool = True) -> ModelFit:
    """Fit the IDM with gap acceptance (see the module docstring)."""
    p = ev.runs[0].config.hv.idm
    base = np.array([getattr(p, name) for name in IDM_NAMES], float)
    obj = IDMObjective(ev, base, sigma_min)
    with np.errstate(divide="ignore"):
        y_default = np.where(_LOG, np.log(base[_SLOTS]), base[_SLOTS])
    y_default = np.clip(y_default, _LO, _HI)
    # starts: the configured IDM and a few gap acceptances
    starts = [y_default]
    for gap in (0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0):
        for imp in (0.0, 0.2):
            y = y_default.copy()
            y[4], y[5] = gap, imp
            starts.append(y)
    starts = np.array(starts)
    ll = obj.loglik(starts)
    order = np.argsort(-ll)[:2]
    best_y, best_ll = starts[order[0]], float(ll[order[0]])

    def neg(y):
        return -float(obj.loglik(np.clip(y, _LO, _HI)[None])[0])

    for j in order:  # the best two starts: Nelder-Mead, gap scans, Nelder-Mead again
        y = starts[j]
        for maxfev in (400, 300):
            res = minimize(neg, y, method="Nelder-Mead", bounds=list(zip(_LO, _HI)),
                           options={"xatol": 1e-5, "fatol": 1e-9, "maxfev": maxfev,
                                    "adaptive": True})
            y = _scan_gaps(obj, np.clip(res.x, _LO, _HI))
        v = -neg(y)
        if v > best_ll:
            best_y, best_ll = y, v
    y_hat = best_y
    sse = float(obj.sse(y_hat[None]).sum())
    ll_hat, sigma = loglik_of_sse(np.array([sse]), ev.n_steps, sigma_min)
    ll_hat, sigma_hat = float(ll_hat[0]), float(sigma[0])
    exact = sigma_hat <= sigma_min * (1 + 1e-12)
    prm = obj.params(y_hat[None])[0]
    theta = {name: float(prm[IDM_NAMES.index(name)]) for name in IDM_NAMES}
    theta["sigma"] = sigma_hat
    run_sse = obj.sse(y_hat[None])[:, 0]
    lengths = np.diff(ev.starts)
    run_ll = (-lengths * math.log(sigma_hat) - 0.5 * lengths * math.log(2 * math.pi)
              - run_sse / (2 * sigma_hat ** 2))
    params: dict[str, Estimate] = {}
    notes = [f"delta = {base[IDM_NAMES.index('delta')]:g} and jam_gap_m = "
             f"{base[IDM_NAMES.index('jam_gap_m')]:g} are held at the log's configuration"]
    if exact:
        notes.append(f"sigma ended on its floor sigma_min = {sigma_min:g} m/s^2: the IDM "
                     "reproduces the logged accelerations to within it (exact data)")
    if not intervals:
        for name, *_ in FITTED:
            params[name] = Estimate(theta[name], None, None, "point")
        params["sigma"] = Estimate(sigma_hat, None, None, "point")
    else:
        params.update(_wald(obj, y_hat, theta))
        params.update(_gap_intervals(obj, y_hat, ll_hat, theta))
        params["sigma"] = _sigma_interval(sse, ev.n_steps, sigma_min, sigma_hat, ll_hat)
    return ModelFit("idm", params, ll_hat, len(FITTED) + 1, ev.n_steps, exact, theta, run_ll,
                    None, notes)


def _scan_gaps(obj: IDMObjective, y: np.ndarray) -> np.ndarray:
    """Coordinate scans of the two gap parameters (one batch each)."""
    for j, grid in ((4, GAP_GRID), (5, IMPATIENCE_GRID)):
        rows = np.tile(y, (len(grid), 1))
        rows[:, j] = grid
        ll = obj.loglik(rows)
        cur = obj.loglik(y[None])[0]
        k = int(np.argmax(ll))
        if ll[k] > cur:
            y = rows[k].copy()
    return y


def _wald(obj: IDMObjective, y_hat: np.ndarray, theta: dict) -> dict[str, Estimate]:
    """Observed-information intervals of the four smooth parameters, on their log scale."""
    idx = [0, 1, 2, 3]
    h = 1e-3
    pts = [y_hat]
    for a in idx:
        for s in (1, -1):
            y = y_hat.copy()
            y[a] += s * h
            pts.append(y)
    for i, a in enumerate(idx):
        for b in idx[i + 1:]:
            for sa, sb in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                y = y_hat.copy()
                y[a] += sa * h
                y[b] += sb * h
                pts.append(y)
    vals = obj.loglik(np.array(pts))
    f0 = vals[0]
    d = len(idx)
    H = np.empty((d, d))
    for i in range(d):
        H[i, i] = (vals[1 + 2 * i] - 2 * f0 + vals[2 + 2 * i]) / h ** 2
    k = 1 + 2 * d
    for i in range(d):
        for j in range(i + 1, d):
            fpp, fpm, fmp, fmm = vals[k:k + 4]
            k += 4
            H[i, j] = H[j, i] = (fpp - fpm - fmp + fmm) / (4 * h * h)
    out = {}
    try:
        cov = np.linalg.inv(-H)
    except np.linalg.LinAlgError:
        cov = np.full((d, d), np.nan)
    for i, a in enumerate(idx):
        name = FITTED[a][0]
        var = cov[i, i]
        if np.isfinite(var) and var > 0:
            se = math.sqrt(var)
            lo_, hi_ = math.exp(y_hat[a] - 1.959963984540054 * se), math.exp(
                y_hat[a] + 1.959963984540054 * se)
            out[name] = Estimate(theta[name], lo_, hi_, "wald (log scale)")
        else:
            out[name] = Estimate(theta[name], None, None, "wald (log scale)",
                                 "no curvature: the data do not determine it")
    return out


def _gap_intervals(obj: IDMObjective, y_hat: np.ndarray, ll_hat: float,
                   theta: dict) -> dict[str, Estimate]:
    out = {}
    for j, grid in ((4, GAP_GRID), (5, IMPATIENCE_GRID)):
        name = FITTED[j][0]
        rows = np.tile(y_hat, (len(grid), 1))
        rows[:, j] = grid
        ll = obj.loglik(rows)
        keep = grid[ll >= ll_hat - DROP_TWO_SIDED]
        if keep.size == 0:
            out[name] = Estimate(theta[name], theta[name], theta[name], "likelihood ratio, "
                                 "others held")
        else:
            out[name] = Estimate(theta[name], float(min(keep.min(), theta[name])),
                                 float(max(keep.max(), theta[name])),
                                 "likelihood ratio, others held",
                                 f"scanned {grid[0]:g}..{grid[-1]:g}")
    return out


def _sigma_interval(sse: float, n: int, sigma_min: float, sigma_hat: float,
                    ll_hat: float) -> Estimate:
    def ll(s):
        return -n * math.log(s) - 0.5 * n * math.log(2 * math.pi) - sse / (2 * s * s)

    if sigma_hat <= sigma_min * (1 + 1e-12):
        target = ll_hat - DROP_ONE_SIDED
        hi = brentq(lambda s: ll(s) - target, sigma_min, max(1.0, 10 * sigma_min) * 10)
        return Estimate(sigma_hat, sigma_min, hi, "profile, one-sided")
    target = ll_hat - DROP_TWO_SIDED
    bottom = max(sigma_min, sigma_hat * 1e-3)
    lo = sigma_min if ll(bottom) >= target else brentq(lambda s: ll(s) - target, bottom,
                                                       sigma_hat)
    hi = brentq(lambda s: ll(s) - target, sigma_hat, sigma_hat * 1e3)
    return Estimate(sigma_hat, lo, hi, "profile")


__all__ = ["FITTED", "IDMObjective", "fit_idm", "loglik_of_sse"]
