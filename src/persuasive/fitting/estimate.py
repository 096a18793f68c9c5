"""Maximum-likelihood fits of the human models, their intervals and their comparison
(docs/method.md §13.4-13.6).

Parameters and their coordinates (the fits work on these):

======== ================================ ===================================
name      meaning                          coordinate
======== ================================ ===================================
``p_a``   willingness to change role       ``p_a`` in [0, 1]
``pi0``   ``P(initial role = leader)``     maximised exactly (concave, §13.5)
``sigma`` acceleration noise [m/s^2]       ``log sigma``, ``sigma >= sigma_min``
``beta``  rationality (``noisy``)          ``log beta`` in [log 1e-3, log 1e3], or inf
IDM       the IDM's and its gap's          ``persuasive.fitting.idm``
======== ================================ ===================================

**Exact data.** Simulated runs without noise reproduce the LFG's accelerations to the last bit,
so the likelihood grows without bound as ``sigma -> 0``. ``sigma`` is bounded below by
``sigma_min`` (default 0.001 m/s^2: two accelerations closer than that count as the same;
allowed: [1e-9, 1] m/s^2, :func:`check_sigma_min`); when the fit ends on that bound the data
are *exact*: each emission is then, in effect, an indicator of "this role reproduces the logged
acceleration", the likelihood in ``p_a`` is the probability of the role sequences that explain
the actions, and the log-likelihoods of all models that reproduce the data share the constant
``n log(1 / (sigma_min sqrt(2 pi)))``, so comparisons stay meaningful.

**Intervals** (95 %): profile likelihood, the other parameters maximised at every point, never
past the parameter's bounds. An interior estimate's interval is where twice the drop of the
profile log-likelihood stays below the chi-square(1) quantile 3.84; an estimate on a bound
(``p_a = 1``, ``p_a = 0``, ``pi0`` in {0, 1}, ``sigma = sigma_min``, ``beta = inf``) gets the
boundary-corrected cutoff 2.71 and an interval from that bound inwards
(:func:`profile_interval` states the rule).

**Comparison**: ``AIC = 2 k - 2 l``, ``BIC = k log n - 2 l`` (``n``: logged steps, ``k``: fitted
parameters; ``pi0`` counts). The selected model has the smallest BIC.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

import numpy as np

from ..config import ConfigError
from .evidence import Evidence
from .models import (EMIT_LFG, EMIT_NOISY, best_initial_role, hmm_loglik, hmm_loglik_serial,
                     path_loglik, path_loglik_serial)
from .optimize import hessian_at, maximise_rows

#: Default lower bound of the noise's standard deviation [m/s^2] (exact data end on it).
SIGMA_MIN = 1e-3
#: The values ``sigma_min`` may take [m/s^2] (:func:`check_sigma_min` says why).
SIGMA_MIN_RANGE = (1e-9, 1.0)
#: Upper bound of the noise's standard deviation [m/s^2].
SIGMA_MAX = 10.0
#: Bounds of the noisy human's rationality [1/reward]; beta = inf is the LFG.
BETA_MIN, BETA_MAX = 1e-3, 1e3
#: Drop of the log-likelihood at a two-sided 95 % limit: chi2(1) quantile / 2.
DROP_TWO_SIDED = 3.841458820694124 / 2.0
#: Drop at the limit of an estimate on a bound: the 95 % quantile of 1/2 chi2(0) + 1/2 chi2(1)
#: (the chi2(1) quantile at 90 %, 2.71 = 1.645^2), halved (:func:`profile_interval`).
DROP_ONE_SIDED = 2.705543454095404 / 2.0
#: An estimate this close to a bound, in the coordinate the fit moves, is on it.
AT_BOUND_TOL = 1e-9
#: A profile interval's bracket is narrowed (by 5 each round) at least twice, and further, up
#: to NARROW_MAX rounds, while its ends' log-likelihoods differ by more than NARROW_SPAN.
NARROW_MAX, NARROW_SPAN = 4, 0.25
#: Human kinds a fit knows, in the order they are reported.
MODELS = ("lfg", "stubborn", "noisy", "idm")
#: Below this many step-rows a kernel call runs on one thread.
PARALLEL_WORK = 200_000
#: The ``p_a`` grid of the profile (step 0.04).
P_GRID = np.linspace(0.0, 1.0, 26)
#: A profile point's nuisance coordinates stop moving below this step (in units of their
#: trust-region scale: 5e-5 in log sigma, where the log-likelihood's curvature is about 2 n,
#: costs at most n 5e-9 of log-likelihood)
PROFILE_TOL = 1e-4


@dataclass(frozen=True)
class Estimate:
    """One parameter's estimate and its 95 % interval (``None`` where it has none)."""

    value: float
    low: float | None
    high: float | None
    method: str  #: "profile", "profile, one-sided", "fixed", ...
    note: str = ""

    def to_dict(self) -> dict:
        out = {"estimate": _num(self.value), "ci95": [_num(self.low), _num(self.high)],
               "method": self.method}
        if self.note:
            out["note"] = self.note
        return out


def check_sigma_min(value, name: str = "sigma_min") -> float:
    """``value`` as a float if it is a valid ``sigma_min`` [m/s^2], else :class:`ConfigError`
    (one line naming ``name`` and the allowed range).

    Allowed: :data:`SIGMA_MIN_RANGE`, [1e-9, 1] m/s^2. Below, the floor stops being a property
    of the data: a game re-solved on another machine can differ from the logged acceleration
    by about 1e-15 m/s^2 (float64 rounding), and a floor within a few orders of magnitude of
    that would call the same data exact on one machine and not on another; the floor's own
    terms (``sigma_min^2`` in the IDM's closed form, ``((x - a) / sigma_min)^2`` for residuals
    up to the accelerations' range) stay normal, finite floats with many orders to spare (at
    1e-320 they are not: ``1 / sigma`` overflows and the log-likelihood is ``-inf``). Above,
    the floor would call every model exact: 1 m/s^2 is a third of a vehicle's whole
    acceleration range ([-2, 1] m/s^2 by default), and the fit's ``sigma`` must keep room
    below its upper bound :data:`SIGMA_MAX` (at 1e200 its interval ran backwards).
    """
    lo, hi = SIGMA_MIN_RANGE
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if ok:
        value = float(value)
        ok = math.isfinite(value) and lo <= value <= hi
    if not ok:
        raise ConfigError(f"{name} = {value!r} is out of range; allowed: [{lo:g}, {hi:g}] "
                          "m/s^2")
    return value


def bound_side(x: float, lo: float, hi: float, tol: float = AT_BOUND_TOL) -> str | None:
    """``"lower"`` or ``"upper"`` when ``x`` is on that bound of ``[lo, hi]`` (within
    ``tol``), else None (:func:`profile_interval` states the rule)."""
    if x - lo <= tol:
        return "lower"
    if hi - x <= tol:
        return "upper"
    return None


def interval_method(method: str, side: str | None) -> str:
    """An :class:`Estimate`'s ``method`` that says when the estimate is on a bound."""
    return method if side is None else f"{method}, one-sided: on the {side} bound"


def _num(x):
    if x is None:
        return None
    x = float(x)
    if math.isnan(x):
        return None
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return x


@dataclass
class ModelFit:
    """A fitted human model."""

    model: str
    params: dict[str, Estimate]
    loglik: float
    n_params: int
    n_obs: int
    exact: bool  #: sigma ended on sigma_min: the data are reproduced to within it
    theta: dict[str, float]  #: the point estimate as the likelihood reads it
    run_loglik: np.ndarray = field(repr=False)  #: per run, at the estimate
    profile: dict | None = field(default=None, repr=False)  #: the profile over p_a
    notes: list[str] = field(default_factory=list)

    @property
    def aic(self) -> float:
        return 2.0 * self.n_params - 2.0 * self.loglik

    @property
    def bic(self) -> float:
        return self.n_params * math.log(max(self.n_obs, 1)) - 2.0 * self.loglik

    def to_dict(self) -> dict:
        out = {"model": self.model, "loglik": _num(self.loglik), "n_params": self.n_params,
               "n_obs": self.n_obs, "aic": _num(self.aic), "bic": _num(self.bic),
               "exact": self.exact,
               "params": {k: v.to_dict() for k, v in self.params.items()}}
        if self.notes:
            out["notes"] = list(self.notes)
        if self.profile is not None:
            out["profile"] = {k: [_num(v) for v in vals] for k, vals in self.profile.items()}
        return out


# -- the hidden-role models: lfg, stubborn, noisy ---------------------------------------------

#: Coordinates of a row: p_a, log sigma, log beta (its upper bound stands for beta = inf, the
#: LFG's own choice), pi0 (NaN: maximised exactly).
P_A, LOG_SIGMA, LOG_BETA, PI0 = 0, 1, 2, 3
#: Newton iterations of each start before the best three are maximised jointly.
START_ITERS = 3

#: Finite-difference steps and trust-region scales of the coordinates.
_H = np.array([1e-4, 1e-4, 1e-3, 1e-4])
_SCALE = np.array([0.1, 0.5, 1.0, 0.1])


class RoleObjective:
    """The log-likelihood of a hidden-role model for parameter rows ``(M, 4)`` =
    ``(p_a, log sigma, log beta, pi0)``; ``pi0 = NaN`` is maximised exactly."""

    def __init__(self, ev: Evidence, model: str, sigma_min: float):
        if model not in ("lfg", "stubborn", "noisy"):
            raise ValueError(f"not a hidden-role model: {model!r}")
        self.ev, self.model = ev, model
        self.emit = EMIT_NOISY if model == "noisy" else EMIT_LFG
        self.sigma_min = sigma_min = check_sigma_min(sigma_min)
        self.lo = np.array([0.0, math.log(sigma_min), math.log(BETA_MIN), 0.0])
        self.hi = np.array([1.0, math.log(SIGMA_MAX), math.log(BETA_MAX), 1.0])
        self.calls = 0  #: kernel calls
        self.rows = 0  #: parameter rows scored

    @property
    def free(self) -> list[int]:
        """The coordinates the Newton iterations move (``pi0`` is maximised exactly)."""
        return {"lfg": [P_A, LOG_SIGMA], "stubborn": [LOG_SIGMA],
                "noisy": [P_A, LOG_SIGMA, LOG_BETA]}[self.model]

    def beta(self, u: np.ndarray) -> np.ndarray:
        if self.model != "noisy":
            return np.full(len(u), np.inf)
        return np.where(u >= self.hi[LOG_BETA], np.inf, np.exp(u))

    def table(self, X: np.ndarray) -> np.ndarray:
        """Each run's log-likelihood per row and initial role ``(n_runs, M, 2)``."""
        ev = self.ev
        X = np.atleast_2d(X)
        p = X[:, P_A] if self.model != "stubborn" else np.zeros(len(X))
        out = np.empty((ev.n_runs, len(X), 2))
        work = ev.n_steps * len(X) * (12 if self.emit == EMIT_NOISY else 1)
        kernel = hmm_loglik if work >= PARALLEL_WORK and ev.n_runs > 1 else hmm_loglik_serial
        sigma = np.ascontiguousarray(np.exp(X[:, LOG_SIGMA]))
        paths_only = self.emit == EMIT_LFG and ev.filtered is not None and ev.filtered.all()
        if not paths_only:
            kernel(self.emit, ev.starts, ev.accel, ev.a_role, ev.pl, ev.q, ev.a_first,
                   np.ascontiguousarray(p), sigma,
                   np.ascontiguousarray(self.beta(X[:, LOG_BETA])), out)
        if self.emit == EMIT_LFG and ev.filtered is not None:
            # runs recorded through a filter: over role paths (models.path_loglik_run; every
            # run's row of out is written there when every run is filtered)
            runs = np.flatnonzero(ev.filtered).astype(np.int64)
            paths = path_loglik if len(runs) > 1 and work >= PARALLEL_WORK else \
                path_loglik_serial
            paths(runs, ev.starts, ev.accel, ev.a_raw, ev.pl, ev.band_off, ev.band_w,
                  np.ascontiguousarray(p), sigma, out)
        self.calls += 1
        self.rows += len(X)
        return out

    def evaluate(self, X: np.ndarray):
        """``(loglik (M,), pi0 (M,))``, ``pi0`` maximised where the row's is NaN."""
        X = np.atleast_2d(X)
        table = self.table(X)
        ell, pi0 = np.empty(len(X)), np.empty(len(X))
        best_initial_role(table, np.ascontiguousarray(X[:, PI0]), ell, pi0)
        return ell, pi0

    def __call__(self, X: np.ndarray) -> np.ndarray:
        return self.evaluate(X)[0]

    def maximise(self, rows: np.ndarray, free: list[int], iters: int = 40,
                 tol: float = 1e-7):
        """Maximise every row over ``free`` (:func:`persuasive.fitting.optimize
        .maximise_rows`, lazily: a row's value does not depend on its batch)."""
        return maximise_rows(self, rows, free, self.lo, self.hi, _H, _SCALE, iters=iters,
                             tol=tol, lazy=True)

    def run_loglik(self, x: np.ndarray) -> np.ndarray:
        """Each run's log-likelihood at the parameter vector ``x`` (its ``pi0`` given)."""
        table = self.table(x[None])
        a, b = table[:, 0, 0], table[:, 0, 1]
        pi0 = float(x[PI0])
        with np.errstate(divide="ignore"):
            return np.logaddexp(np.log(pi0) + a, np.log1p(-pi0) + b)


def _clamp(x: float, lo: float, hi: float) -> float:
    return float(min(max(x, lo), hi))


def from_log(u: float, lo: float, hi: float) -> float:
    """``exp(u)`` for a parameter in ``[lo, hi]`` fitted as ``u = log x``: on a bound the bound
    itself (``exp(log 8)`` is 7.999999999999998), and never outside the range."""
    if u <= math.log(lo):
        return float(lo)
    if u >= math.log(hi):
        return float(hi)
    return _clamp(math.exp(u), lo, hi)


def initial_sigma(ev: Evidence, sigma_min: float) -> float:
    """A start for ``sigma``: the RMS of the smaller of the two roles' residuals per step."""
    r = np.min(np.abs(ev.accel[:, None] - ev.a_role), axis=1)
    return float(max(sigma_min, math.sqrt(float(np.mean(r * r)))))


def profile_interval(prof, x_hat: float, ell_hat: float, lo_bound: float, hi_bound: float,
                     width: float | None = None, grid: np.ndarray | None = None,
                     grid_vals: np.ndarray | None = None,
                     at_bound_tol: float = AT_BOUND_TOL) -> tuple[float, float, bool]:
    """A 95 % profile-likelihood interval of one coordinate, within ``[lo_bound, hi_bound]``.

    **The rule.** The estimate ``x_hat`` is *on a bound* when it lies within ``at_bound_tol``
    of it, in the coordinate the fit moves (``p_a``, ``pi0``, ``log sigma``, ``log beta``,
    the log of the IDM's smooth parameters); the fits land exactly on a bound when their
    maximum is there (their Newton steps are projected onto the bounds; an IDM gap parameter,
    a step function, is moved onto a bound its plateau of equal likelihood reaches, and its
    scan follows this rule too). An interior estimate's
    interval is ``{x : 2 (ell_hat - prof(x)) <= 3.84}``, the chi-square(1) 95 % quantile. On
    a bound the likelihood-ratio statistic of the true value is asymptotically
    ``1/2 chi2(0) + 1/2 chi2(1)`` (Self and Liang 1987), whose 95 % quantile is 2.71
    (``1.645^2``, :data:`DROP_ONE_SIDED`): the interval is ``{x : 2 (ell_hat - prof(x)) <=
    2.71}``, from that bound inwards, so the bound is one of its ends (one-sided). Either way
    the profile is searched up to the bounds and never past them: a limit it does not reach
    before a bound is that bound, and every interval lies within ``[lo_bound, hi_bound]`` and
    holds ``x_hat``.

    ``prof(values (m,)) -> (m,)``: the profile log-likelihood at several values, in one
    batch. Each limit is bracketed (from ``grid``/``grid_vals``, profile values already known;
    else around ``x_hat +- width``, the limits of the quadratic approximation; else walking out
    to the bound), the bracket narrowed by rounds of 4 points (two, and up to
    :data:`NARROW_MAX` while its ends differ by more than :data:`NARROW_SPAN` of
    log-likelihood), and the limit interpolated linearly in the signed root of the likelihood
    ratio. Both limits share each batch. Returns ``(low, high, on_bound)``.
    """
    side = bound_side(x_hat, lo_bound, hi_bound, at_bound_tol)
    on = (side == "lower", side == "upper")
    one_sided = side is not None
    target = ell_hat - (DROP_ONE_SIDED if one_sided else DROP_TWO_SIDED)
    ends = (lo_bound, hi_bound)

    class Side:
        def __init__(self, k):
            self.k, self.inner, self.f_in = k, x_hat, ell_hat
            self.outer = self.f_out = None
            self.result = ends[k] if on[k] else None
            self.narrowed = 0
            self.tries = 0

    sides = [Side(0), Side(1)]
    for sd in sides:
        if sd.result is None and grid is not None:
            sel = (grid < x_hat) if sd.k == 0 else (grid > x_hat)
            cand, vals = grid[sel], grid_vals[sel]
            order = np.argsort(-cand) if sd.k == 0 else np.argsort(cand)
            for xg, vg in zip(cand[order], vals[order]):
                if not vg >= target:
                    sd.outer, sd.f_out = xg, vg
                    break
                sd.inner, sd.f_in = xg, vg
            if sd.outer is None and abs(sd.inner - ends[sd.k]) <= at_bound_tol:
                sd.result = ends[sd.k]
    while True:
        # two rounds; more while a bracket still spans much of the drop (a wide first bracket
        # where the quadratic approximation was poor), at most NARROW_MAX
        todo = [sd for sd in sides if sd.result is None and (
            sd.narrowed < 2 or (sd.narrowed < NARROW_MAX and sd.f_out is not None
                                and sd.f_in - sd.f_out > NARROW_SPAN))]
        if not todo:
            break
        batch = []
        for sd in todo:
            sign = -1.0 if sd.k == 0 else 1.0
            if sd.outer is not None:
                xs = np.linspace(sd.inner, sd.outer, 6)[1:-1]
            elif sd.tries == 0 and width is not None and math.isfinite(width) and width > 0:
                xs = np.clip(x_hat + sign * width * np.array([0.8, 1.0, 1.25, 1.8]),
                             lo_bound, hi_bound)
            else:
                xs = np.linspace(sd.inner, ends[sd.k], 5)[1:]
            batch.append(xs)
        vals = prof(np.concatenate(batch))
        k = 0
        for sd, xs in zip(todo, batch):
            vs = vals[k:k + len(xs)]
            k += len(xs)
            bracketed = sd.outer is not None
            below = np.flatnonzero(~(vs >= target))
            if below.size == 0:
                sd.inner, sd.f_in = xs[-1], vs[-1]
                if not bracketed and abs(xs[-1] - ends[sd.k]) <= at_bound_tol:
                    sd.result = ends[sd.k]
            else:
                j = below[0]
                if j > 0:
                    sd.inner, sd.f_in = xs[j - 1], vs[j - 1]
                sd.outer, sd.f_out = xs[j], vs[j]
            sd.narrowed += 1 if bracketed else 0
            sd.tries += 1
            if sd.tries > 12 and sd.outer is None:
                sd.result = ends[sd.k]
    out = []
    for sd in sides:
        if sd.result is not None:
            out.append(float(sd.result))
            continue
        # linear in the signed root of the likelihood ratio, which is linear in x where the
        # profile is quadratic
        r_in, r_out = (math.sqrt(2.0 * max(ell_hat - f, 0.0)) for f in (sd.f_in, sd.f_out))
        r_t = math.sqrt(2.0 * (ell_hat - target))
        if not (math.isfinite(r_in) and math.isfinite(r_out)) or r_out <= r_in:
            out.append(float(0.5 * (sd.inner + sd.outer)))
        else:
            out.append(float(sd.inner + (r_t - r_in) * (sd.outer - sd.inner) / (r_out - r_in)))
    # the interpolation stays inside its bracket; the clamp only guards the rounding of x_hat
    low = min(max(out[0], lo_bound), x_hat)
    high = max(min(out[1], hi_bound), x_hat)
    return low, high, one_sided


def fit_role_model(ev: Evidence, model: str, sigma_min: float = SIGMA_MIN,
                   intervals: bool = True, start: dict | None = None) -> ModelFit:
    """Fit ``lfg``, ``stubborn`` or ``noisy`` to the evidence (see the module docstring).

    ``sigma_min``: the floor of ``sigma`` [m/s^2], in [1e-9, 1] (:func:`check_sigma_min`
    raises :class:`persuasive.config.ConfigError` otherwise). ``start``: a parameter vector to
    try as a start as well (``noisy`` takes the ``lfg`` estimate, its ``beta = inf`` limit, so
    that it never fits worse than the LFG).
    """
    sigma_min = check_sigma_min(sigma_min)
    obj = RoleObjective(ev, model, sigma_min)
    lo, hi, free = obj.lo, obj.hi, obj.free
    t0 = math.log(initial_sigma(ev, sigma_min))
    notes: list[str] = []
    # 1. starts over p_a (and beta), each maximised a little over the rest; then Newton over
    #    every free coordinate from the best three
    us = [math.log(0.1), math.log(3.0)] if model == "noisy" else [hi[LOG_BETA]]
    ps = np.linspace(0.0, 1.0, 6) if P_A in free else np.zeros(1)
    starts = np.array([[p, t0, u, np.nan] for p in ps for u in us])
    if start is not None:
        starts = np.vstack([starts, [start["p_a"], math.log(start["sigma"]),
                                     hi[LOG_BETA], np.nan]])
    xs, fs = obj.maximise(starts, [c for c in free if c != P_A], iters=START_ITERS, tol=1e-4)
    best = np.argsort(-fs)[:3]
    xs, fs = obj.maximise(xs[best], free)
    j = int(np.argmax(fs))
    x_hat, ell_hat = xs[j], float(fs[j])
    profile = grid_vals = None
    # 2. the profile over p_a on its grid (each row maximised over the other coordinates):
    #    its intervals' brackets, and a search for another mode
    if P_A in free and intervals:
        nuis = [c for c in free if c != P_A]
        rows = np.tile(x_hat, (len(P_GRID), 1))
        rows[:, P_A] = P_GRID
        xs, grid_vals = obj.maximise(rows, nuis, tol=PROFILE_TOL)
        j = int(np.argmax(grid_vals))
        if grid_vals[j] > ell_hat + 1e-6:  # another mode: restart the joint maximisation there
            x2, f2 = obj.maximise(xs[j][None], free)
            if f2[0] > ell_hat:
                x_hat, ell_hat = x2[0], float(f2[0])
        profile = {"p_a": P_GRID.tolist(), "loglik": grid_vals.tolist()}
    # the point estimate, pi0 included
    _, pi0_hat = obj.evaluate(x_hat[None])
    x_hat = x_hat.copy()
    x_hat[PI0] = float(pi0_hat[0])
    run_ll = obj.run_loglik(x_hat)
    p_hat = float(x_hat[P_A]) if model != "stubborn" else 0.0
    sigma_hat = from_log(float(x_hat[LOG_SIGMA]), sigma_min, SIGMA_MAX)
    beta_hat = float(obj.beta(x_hat[LOG_BETA:LOG_BETA + 1])[0]) if model == "noisy" else math.inf
    exact = bool(x_hat[LOG_SIGMA] <= lo[LOG_SIGMA] + 1e-9)
    theta = {"p_a": p_hat, "pi0": float(x_hat[PI0]), "sigma": sigma_hat, "beta": beta_hat}
    if exact:
        notes.append(f"sigma ended on its floor sigma_min = {sigma_min:g} m/s^2: the model "
                     "reproduces the logged accelerations to within it (exact data)")
    if model == "noisy" and math.isinf(beta_hat):
        notes.append("beta = inf: the LFG's own choice explains the data at least as well as "
                     "any finite rationality")
    x_free = x_hat.copy()
    x_free[PI0] = np.nan  # pi0 maximised at every profile point
    # the Hessian at the estimate predicts the nuisance coordinates along each profile and
    # the interval's half-width (the quadratic approximation); Newton then corrects them
    if intervals:
        _, H = hessian_at(obj, x_free, free, lo, hi, _H)

    def profile_of(coord: int):
        nuis = [c for c in free if c != coord]
        base = x_free if coord != PI0 else x_hat
        slope = np.zeros(len(nuis))
        if coord in free and nuis:
            j = free.index(coord)
            idx = [free.index(c) for c in nuis]
            try:
                slope = -np.linalg.solve(H[np.ix_(idx, idx)], H[idx, j])
            except np.linalg.LinAlgError:
                pass

        def prof(values: np.ndarray) -> np.ndarray:
            rows = np.tile(base, (len(values), 1))
            rows[:, coord] = values
            if coord in free:
                rows[:, nuis] += np.outer(values - base[coord], slope)
                for c in nuis:
                    rows[:, c] = np.clip(rows[:, c], lo[c], hi[c])
            return obj.maximise(rows, nuis, tol=PROFILE_TOL)[1]
        return prof

    def half_width(coord: int) -> float | None:
        if coord not in free:
            return None
        try:
            var = -np.linalg.inv(H)[free.index(coord), free.index(coord)]
        except np.linalg.LinAlgError:
            return None
        return math.sqrt(2.0 * DROP_TWO_SIDED * var) if var > 0 else None

    params: dict[str, Estimate] = {}
    names = {P_A: "p_a", PI0: "pi0", LOG_SIGMA: "sigma", LOG_BETA: "beta"}
    coords = [c for c in (P_A, PI0, LOG_SIGMA, LOG_BETA) if c in free or c == PI0]
    for c in coords:
        name = names[c]
        value = theta[name]
        if not intervals:
            params[name] = Estimate(value, None, None, "point")
            continue
        a, b, one = profile_interval(profile_of(c), float(x_hat[c]), ell_hat, lo[c], hi[c],
                                     half_width(c), P_GRID if c == P_A else None,
                                     grid_vals if c == P_A else None)
        if c == LOG_SIGMA:
            a, b = (from_log(v, sigma_min, SIGMA_MAX) for v in (a, b))
        elif c == LOG_BETA:
            a = from_log(a, BETA_MIN, BETA_MAX)
            b = math.inf if b >= hi[LOG_BETA] else from_log(b, BETA_MIN, BETA_MAX)
        side = bound_side(float(x_hat[c]), lo[c], hi[c]) if one else None
        params[name] = Estimate(value, a, b, interval_method("profile", side))
    if model == "stubborn":
        params = {"p_a": Estimate(0.0, None, None, "fixed"), **params}
    k = {"lfg": 3, "stubborn": 2, "noisy": 4}[model]
    return ModelFit(model, params, ell_hat, k, ev.n_steps, exact, theta, run_ll, profile,
                    notes)


def warm_up() -> None:
    """Load (compiling them once when they are not cached) every kernel a fit may call, the
    parallel ones too (chosen by the data's size, so a small fit would not reach them), on
    one step: a later, larger fit never compiles silently."""
    from .. import packing as slot
    from .models import idm_sse, idm_sse_serial

    starts = np.array([0, 1], np.int64)
    args = (starts, np.zeros(1), np.zeros((1, 2)), np.ones((1, 2)), np.zeros((1, 2, 3)),
            np.zeros((1, 3)), np.full(1, 0.5), np.ones(1), np.ones(1))
    for kernel in (hmm_loglik, hmm_loglik_serial):
        for kind in (EMIT_LFG, EMIT_NOISY):
            kernel(kind, *args, np.empty((1, 1, 2)))
    for kernel in (path_loglik, path_loglik_serial):  # recorded logs: over role paths
        kernel(np.zeros(1, np.int64), starts, np.zeros(1), np.zeros((1, 2)), np.ones((1, 2)),
               np.array([-1, 0, 1]), np.full((1, 3), 1.0 / 3.0), np.full(1, 0.5), np.ones(1),
               np.empty((1, 1, 2)))
    P = np.zeros((1, slot.N_SLOTS))
    P[:, slot.U_MIN], P[:, slot.U_MAX], P[:, slot.YIELD_S], P[:, slot.CLEAR_S] = -2, 1, -6, 7
    prm = np.array([[10.0, 1.5, 1.0, 1.5, 4.0, 2.0, 1.0, 0.0]])
    states = np.array([[-20.0, 4.0, -20.0, 4.0]])
    for kernel in (idm_sse, idm_sse_serial):
        kernel(starts, states, np.zeros(1), P, P, np.full(1, 0.1), prm, np.zeros(1, np.int64),
               np.empty((1, 1)))


__all__ = ["AT_BOUND_TOL", "BETA_MAX", "BETA_MIN", "Estimate", "MODELS", "ModelFit",
           "RoleObjective", "SIGMA_MIN", "SIGMA_MIN_RANGE", "bound_side", "check_sigma_min",
           "fit_role_model", "from_log", "initial_sigma", "interval_method",
           "profile_interval", "warm_up"]
