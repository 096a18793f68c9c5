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
with fine scans of the two gap parameters. A scan is cheap: along the measured states the
driver's waiting time, its commitment and the accelerations of its two decisions do not depend
on the gap parameters, so :func:`persuasive.fitting.models.idm_sse` computes them once per scan
and each of its 201 rows only decides, step by step.

After Nelder-Mead and the scans, a lockstep trust-region Newton over the four smooth parameters
(:func:`persuasive.fitting.optimize.maximise_rows`, its steps projected onto the bounds) polishes
the estimate, so that a maximum on a bound ends exactly on it (Nelder-Mead stops near it: 29.99
m/s for the bound 30); a gap parameter whose plateau of equal likelihood reaches one of its
bounds is moved onto that bound (the same likelihood).

Intervals (95 %), every one within the parameter's range (:data:`FITTED`), with the rule of
:func:`persuasive.fitting.estimate.profile_interval` for an estimate on a bound (cutoff 2.71,
one-sided, the bound one of its ends): ``sigma`` by its exact profile likelihood (the best IDM
parameters do not depend on ``sigma``); the four smooth parameters by the profile likelihood
(the other three re-maximised at every point by the lockstep Newton, the gap parameters held),
or by the observed information on their log scale (Wald, the cheap one) where the estimate is
interior, that interval lies inside the range and the profile at its two ends has dropped by
what the quadratic approximation says (:data:`WALD_CHECK`: two profile points instead of about
twenty). The check is needed: the acceleration saturates and the gap decisions switch, so the
likelihood has kinks, and its curvature at an interior estimate can say +-5 % where the profile
says +-20 % (an IDM human with a desired speed of 45 m/s, driving at 10 m/s at most). The two
gap parameters get the likelihood ratio along a scan of their whole range, the others held at
their estimates (the likelihood is a step function in them, so no curvature exists). A profile
point likelier than the estimate (a lesser mode found first) moves the estimate there and the
intervals start again (at most :data:`RESTARTS` times; then a note says so).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq, minimize

from .estimate import (DROP_ONE_SIDED, DROP_TWO_SIDED, PARALLEL_WORK, PROFILE_TOL, SIGMA_MIN,
                       Estimate, ModelFit, bound_side, check_sigma_min, from_log,
                       interval_method, profile_interval)
from .evidence import Evidence
from .models import IDM_NAMES, idm_groups, idm_sse, idm_sse_serial
from .optimize import maximise_rows

#: The fitted IDM parameters: (name, lower bound, upper bound, log scale).
FITTED = (("desired_speed_mps", 1.0, 30.0, True), ("time_gap_s", 0.05, 5.0, True),
          ("max_accel_mps2", 0.1, 5.0, True), ("comfort_decel_mps2", 0.1, 8.0, True),
          ("critical_gap_s", 0.0, 10.0, False), ("impatience_per_s", 0.0, 2.0, False))
_SLOTS = [IDM_NAMES.index(name) for name, *_ in FITTED]
_LOG = np.array([log for *_, log in FITTED])
_LO = np.array([math.log(lo) if log else lo for _, lo, _, log in FITTED])
_HI = np.array([math.log(hi) if log else hi for _, _, hi, log in FITTED])
#: The four smooth parameters (log scale) and the two gap parameters, by index in FITTED.
SMOOTH, GAPS = [0, 1, 2, 3], [4, 5]
#: Finite-difference steps and trust-region scales of the fitted coordinates (Newton polish and
#: profiles; the gap parameters are never moved by it)
_H = np.full(len(FITTED), 1e-4)
_SCALE = np.array([0.5, 0.5, 0.5, 0.5, 1.0, 0.1])
#: The 97.5 % quantile of the standard normal: the quadratic approximation's half-width in
#: standard errors, a profile limit's first bracket.
_Z95 = 1.959963984540054
#: A profile point this much likelier than the estimate [log-likelihood] moves the estimate
#: there (at most RESTARTS times). Far below the drops that set an interval (1.35, 1.92): the
#: limits move by about 0.4 % of the half-width; smaller gains only chase the ripples of a flat
#: ridge, a whole pass of profiles each
BETTER_BY, RESTARTS = 0.01, 2
#: A Wald interval is kept where the profile at both its ends has dropped by 1.92 (the
#: two-sided cutoff) to within this factor either way: its limits then lie within about 12 %
#: of the profile's
WALD_CHECK = 1.25
#: Newton iterations per profile point, each started from the nearest point already
#: maximised: a limit then lies within 0.003 % of a Nelder-Mead profile's (the IDM human of
#: tests/test_fitting.py, on its bound); 6 miss it by 0.5 %, 12 cost a fifth more
PROFILE_ITERS = 8


def _scan_grid(j: int, step: float) -> np.ndarray:
    """The grid of a gap parameter's scans: its whole range, in steps of ``step``."""
    _, lo, hi, _ = FITTED[j]
    return np.round(np.linspace(lo, hi, int(round((hi - lo) / step)) + 1), 10)


#: The scans of the gap parameters: 0..10 s in steps of 0.05 s, 0..2 1/s in steps of 0.01 1/s.
GAP_GRID = _scan_grid(4, 0.05)
IMPATIENCE_GRID = _scan_grid(5, 0.01)


class IDMObjective:
    """The IDM's sum of squared residuals and log-likelihood for batches of parameter rows."""

    def __init__(self, ev: Evidence, base: np.ndarray, sigma_min: float):
        self.ev, self.base, self.sigma_min = ev, base, check_sigma_min(sigma_min)
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
        kernel(ev.starts, ev.states, ev.accel, ev.P_hv, ev.P_av, ev.dt, prm, idm_groups(prm), out)
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
    """Fit the IDM with gap acceptance (see the module docstring).

    ``sigma_min``: the floor of ``sigma`` [m/s^2], in [1e-9, 1]
    (:func:`persuasive.fitting.estimate.check_sigma_min`; :class:`persuasive.config
    .ConfigError` otherwise).
    """
    sigma_min = check_sigma_min(sigma_min)
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
    y_hat = _gaps_onto_bounds(obj, _polish(obj, np.clip(best_y, _LO, _HI)))
    smooth, notes = None, []
    if intervals:
        # a profile point likelier than the estimate shows that the maximisation stopped on a
        # lesser mode: the estimate moves there and the intervals start again
        for attempt in range(RESTARTS + 1):
            ll_y = float(obj.loglik(y_hat[None])[0])
            smooth, better = _smooth_intervals(obj, y_hat, ll_y, _theta(obj, y_hat),
                                               last=attempt == RESTARTS)
            if better is None:
                break
            if attempt == RESTARTS:
                notes.append("a profile found parameters likelier than the estimate (by "
                             f"{better[1] - ll_y:.3g}): the likelihood has several modes")
            else:
                y_hat = _gaps_onto_bounds(obj, _polish(obj, _scan_gaps(obj, better[0])))
    sse = float(obj.sse(y_hat[None]).sum())
    ll_hat, sigma = loglik_of_sse(np.array([sse]), ev.n_steps, sigma_min)
    ll_hat, sigma_hat = float(ll_hat[0]), float(sigma[0])
    exact = sigma_hat <= sigma_min * (1 + 1e-12)
    if exact:  # sqrt(sigma_min^2) may miss sigma_min by a rounding step
        sigma_hat = sigma_min
    theta = _theta(obj, y_hat)
    theta["sigma"] = sigma_hat
    run_sse = obj.sse(y_hat[None])[:, 0]
    lengths = np.diff(ev.starts)
    run_ll = (-lengths * math.log(sigma_hat) - 0.5 * lengths * math.log(2 * math.pi)
              - run_sse / (2 * sigma_hat ** 2))
    params: dict[str, Estimate] = {}
    notes.insert(0, f"delta = {base[IDM_NAMES.index('delta')]:g} and jam_gap_m = "
                    f"{base[IDM_NAMES.index('jam_gap_m')]:g} are held at the log's configuration")
    if exact:
        notes.append(f"sigma ended on its floor sigma_min = {sigma_min:g} m/s^2: the IDM "
                     "reproduces the logged accelerations to within it (exact data)")
    if not intervals:
        for name, *_ in FITTED:
            params[name] = Estimate(theta[name], None, None, "point")
        params["sigma"] = Estimate(sigma_hat, None, None, "point")
    else:
        params.update(smooth)
        params.update(_gap_intervals(obj, y_hat, ll_hat, theta))
        params["sigma"] = _sigma_interval(sse, ev.n_steps, sigma_min, sigma_hat, ll_hat)
    return ModelFit("idm", params, ll_hat, len(FITTED) + 1, ev.n_steps, exact, theta, run_ll,
                    None, notes)


def _theta(obj: IDMObjective, y: np.ndarray) -> dict[str, float]:
    """The IDM parameters of the fitted coordinates ``y``, each within its range (the
    likelihood reads exp(log 30) = 30.000000000000004; the report says 30)."""
    prm = obj.params(y[None])[0]
    theta = {name: float(prm[IDM_NAMES.index(name)]) for name in IDM_NAMES}
    for j, (name, lo, hi, log) in enumerate(FITTED):
        theta[name] = from_log(float(y[j]), lo, hi) if log else min(max(float(y[j]), lo), hi)
    return theta


def _polish(obj: IDMObjective, y: np.ndarray) -> np.ndarray:
    """The estimate after the projected Newton over the four smooth parameters (it only
    accepts steps that raise the likelihood, and lands exactly on a bound that holds the
    maximum)."""
    x, _ = maximise_rows(obj.loglik, y[None], SMOOTH, _LO, _HI, _H, _SCALE)
    return x[0]


def _gaps_onto_bounds(obj: IDMObjective, y: np.ndarray) -> np.ndarray:
    """``y`` with each gap parameter moved onto a bound its plateau reaches: the likelihood is
    a step function in them, so every value of the plateau is an estimate, and one that
    reaches a bound puts the estimate on it. A plateau that reaches both bounds (the data do
    not depend on the parameter) leaves it where it is."""
    y = y.copy()
    for j, grid in zip(GAPS, (GAP_GRID, IMPATIENCE_GRID)):
        rows = np.tile(y, (len(grid), 1))
        rows[:, j] = grid
        ll = obj.loglik(rows)
        cur = float(obj.loglik(y[None])[0])
        flat = ll >= cur - 1e-9 * max(1.0, abs(cur))
        down = bool(flat[grid <= y[j]].all())
        up = bool(flat[grid >= y[j]].all())
        if down != up:
            y[j] = grid[0] if down else grid[-1]
    return y


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


def _hessian(obj: IDMObjective, y_hat: np.ndarray) -> np.ndarray:
    """The log-likelihood's Hessian over the four smooth parameters (log scale) at ``y_hat``,
    by central differences (one call)."""
    idx = SMOOTH
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
    return H


def _smooth_intervals(obj: IDMObjective, y_hat: np.ndarray, ll_hat: float, theta: dict,
                      last: bool = False
                      ) -> tuple[dict[str, Estimate], tuple[np.ndarray, float] | None]:
    """Intervals of the four smooth parameters: Wald on the log scale where the estimate is
    interior, that interval inside the range and the profile at its ends where the quadratic
    approximation says (:data:`WALD_CHECK`), else the profile likelihood (the module
    docstring). Returns them and None; or, as soon as a profile meets a point that beats
    ``ll_hat`` by :data:`BETTER_BY`, that point and its log-likelihood (the intervals so far
    are then moot; with ``last`` every interval is still computed, and the likeliest point
    returned after them). The observed information (log scale) also brackets each profile
    limit and predicts the other three along the profile."""
    H = _hessian(obj, y_hat)
    try:
        cov = np.linalg.inv(-H)
    except np.linalg.LinAlgError:
        cov = np.full(H.shape, np.nan)
    out = {}
    best: list = [None, ll_hat + BETTER_BY]
    for i in SMOOTH:
        name, lo, hi, _ = FITTED[i]
        side = bound_side(float(y_hat[i]), _LO[i], _HI[i])
        var = cov[i, i]
        se = math.sqrt(var) if np.isfinite(var) and var > 0 else None
        prof = _profile(obj, y_hat, i, H, best)
        if side is None and se is not None:
            a, b = y_hat[i] - _Z95 * se, y_hat[i] + _Z95 * se
            if _LO[i] <= a and b <= _HI[i]:
                drop = ll_hat - prof(np.array([a, b]))
                if best[0] is not None and not last:
                    return out, (best[0], best[1])
                if np.all((drop >= DROP_TWO_SIDED / WALD_CHECK)
                          & (drop <= DROP_TWO_SIDED * WALD_CHECK)):
                    out[name] = Estimate(theta[name], math.exp(a), math.exp(b),
                                         "wald (log scale)")
                    continue
        a, b, _ = profile_interval(prof, float(y_hat[i]), ll_hat, float(_LO[i]), float(_HI[i]),
                                   _Z95 * se if se is not None else None)
        if best[0] is not None and not last:  # the estimate moves: the others start again
            return out, (best[0], best[1])
        a, b = (from_log(v, lo, hi) for v in (a, b))
        note = ""
        if a <= lo * (1 + 1e-12) and b >= hi * (1 - 1e-12):
            note = "the interval is the whole range: the data do not determine it"
        out[name] = Estimate(theta[name], a, b, interval_method("profile", side), note)
    return out, (None if best[0] is None else (best[0], best[1]))


def _profile(obj: IDMObjective, y_hat: np.ndarray, i: int, H: np.ndarray, best: list):
    """The profile log-likelihood of smooth parameter ``i`` (log scale): at each value the
    other three are maximised by the lockstep Newton (:data:`PROFILE_ITERS` steps), from the
    nearest point already maximised (at first the estimate) moved along the quadratic
    approximation's ridge; the gap parameters are held at their estimates. Keeps the likeliest
    point it meets in ``best`` = ``[row, loglik]`` when it beats ``best[1]``."""
    nuis = [c for c in SMOOTH if c != i]
    try:
        slope = -np.linalg.solve(H[np.ix_(nuis, nuis)], H[nuis, i])
    except np.linalg.LinAlgError:
        slope = np.zeros(len(nuis))
    if not np.all(np.isfinite(slope)):
        slope = np.zeros(len(nuis))

    done = [y_hat.copy()]  # the estimate and every profile point so far

    def prof(values: np.ndarray) -> np.ndarray:
        # each point starts from the nearest one already maximised, moved along the ridge:
        # where the likelihood has kinks the ridge at the estimate soon stops predicting it
        known = np.array([x[i] for x in done])
        near = np.argmin(np.abs(values[:, None] - known[None, :]), axis=1)
        rows = np.array([done[k] for k in near])
        rows[:, nuis] += np.outer(values - rows[:, i], slope)
        rows[:, i] = values
        rows[:, nuis] = np.clip(rows[:, nuis], _LO[nuis], _HI[nuis])
        xs, fs = maximise_rows(obj.loglik, rows, nuis, _LO, _HI, _H, _SCALE, iters=PROFILE_ITERS,
                               tol=PROFILE_TOL)
        done.extend(x.copy() for x in xs)
        k = int(np.argmax(fs))
        if fs[k] > best[1]:
            best[0], best[1] = xs[k].copy(), float(fs[k])
        return fs
    return prof


def _gap_intervals(obj: IDMObjective, y_hat: np.ndarray, ll_hat: float,
                   theta: dict) -> dict[str, Estimate]:
    """The gap parameters' intervals: the likelihood ratio along a scan of the whole range,
    the others held (the cutoff of an estimate on a bound: 2.71, else 3.84)."""
    out = {}
    for j, grid in zip(GAPS, (GAP_GRID, IMPATIENCE_GRID)):
        name, lo, hi, _ = FITTED[j]
        side = bound_side(float(y_hat[j]), lo, hi)
        rows = np.tile(y_hat, (len(grid), 1))
        rows[:, j] = grid
        ll = obj.loglik(rows)
        keep = grid[ll >= ll_hat - (DROP_ONE_SIDED if side else DROP_TWO_SIDED)]
        low = min(float(keep.min()), theta[name]) if keep.size else theta[name]
        high = max(float(keep.max()), theta[name]) if keep.size else theta[name]
        flat = bool(np.all(ll >= ll_hat - 1e-9 * max(1.0, abs(ll_hat))))
        out[name] = Estimate(theta[name], low, high,
                             interval_method("likelihood ratio, others held", side),
                             "the likelihood is the same over the whole range: the data do "
                             "not determine it" if flat else "")
    return out


def _sigma_interval(sse: float, n: int, sigma_min: float, sigma_hat: float,
                    ll_hat: float) -> Estimate:
    def ll(s):
        return -n * math.log(s) - 0.5 * n * math.log(2 * math.pi) - sse / (2 * s * s)

    if sigma_hat <= sigma_min * (1 + 1e-12):
        target = ll_hat - DROP_ONE_SIDED
        hi = brentq(lambda s: ll(s) - target, sigma_min, max(1.0, 10 * sigma_min) * 10)
        return Estimate(sigma_hat, sigma_min, hi, interval_method("profile", "lower"))
    target = ll_hat - DROP_TWO_SIDED
    bottom = max(sigma_min, sigma_hat * 1e-3)
    lo = sigma_min if ll(bottom) >= target else brentq(lambda s: ll(s) - target, bottom,
                                                       sigma_hat)
    hi = brentq(lambda s: ll(s) - target, sigma_hat, sigma_hat * 1e3)
    return Estimate(sigma_hat, lo, hi, "profile")


__all__ = ["FITTED", "GAP_GRID", "IDMObjective", "IMPATIENCE_GRID", "fit_idm",
           "loglik_of_sse"]
