"""Maximising many log-likelihoods at once: a lockstep trust-region Newton over rows.

A fit needs the same small maximisation many times: over ``log sigma`` for every ``p_a`` of a
profile grid, over the nuisance parameters at each point of a profile interval search. The
kernels score a whole batch of parameter vectors in one call (:func:`persuasive.fitting.models
.hmm_loglik` is parallel over runs and vectorised over rows), so :func:`maximise_rows` advances
every row together: one call per iteration evaluates, for every row, the proposed point and a
finite-difference stencil around it (gradient and Hessian over the free coordinates), and
each row takes its own trust-region step (``d <= 3`` free coordinates; the step solves
``(-H + lambda I) s = g`` with ``lambda`` chosen so that ``|s| <= radius``). A coordinate on
its bound and pushed out of it leaves that row's Newton system (the others solve their own
part), and every step is projected into the bounds.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

#: A row stops when its next step is predicted to gain at most this share of its value (at
#: least 1e-12 in absolute terms): below it, the gain is within the rounding of a sum of many
#: steps' log-likelihoods (about 4e-8 for 500,000 steps, where the bound is about 1e-6), and a
#: step's actual gain is noise, so the trust region would only shrink to ``tol`` one
#: rejected step after another.
GAIN_TOL = 1e-12


def _stencil(x: np.ndarray, free: list[int], lo: np.ndarray, hi: np.ndarray,
             h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(G, P, D)`` per row: ``x``, the centre ``c`` (``x`` moved ``h`` inside the
    bounds), ``c +- h_i e_i``, ``c + h_i e_i + h_j e_j`` (i < j)."""
    c = x.copy()
    for j in free:
        c[:, j] = np.clip(c[:, j], lo[j] + h[j], hi[j] - h[j])
    pts = [x, c]
    for i in free:
        for sign in (1.0, -1.0):
            p = c.copy()
            p[:, i] += sign * h[i]
            pts.append(p)
    for a, i in enumerate(free):
        for j in free[a + 1:]:
            p = c.copy()
            p[:, i] += h[i]
            p[:, j] += h[j]
            pts.append(p)
    return np.stack(pts, axis=1), c


def _evaluate(f: Callable[[np.ndarray], np.ndarray], pts: np.ndarray) -> np.ndarray:
    """``f`` at the stencil points ``(G, P, D)`` in one call; the point ``x`` (column 0) is
    scored only in rows where it is not the centre (column 1)."""
    G, P, D = pts.shape
    apart = np.any(pts[:, 0] != pts[:, 1], axis=1)
    flat = np.concatenate([pts[:, 1:].reshape(-1, D), pts[apart, 0]])
    v = f(flat)
    vals = np.empty((G, P))
    vals[:, 1:] = v[:G * (P - 1)].reshape(G, P - 1)
    vals[:, 0] = vals[:, 1]
    vals[apart, 0] = v[G * (P - 1):]
    return vals


def _evaluate_lazy(f: Callable[[np.ndarray], np.ndarray], pts: np.ndarray,
                   f_old: np.ndarray) -> np.ndarray:
    """:func:`_evaluate` in two calls: first the proposals ``x`` (column 0) alone, then the
    stencils of only the rows whose proposal scored at least ``f_old`` (the others are
    rejected whatever their stencil says; their stencil values are NaN). For an ``f`` that
    scores a row the same whatever batch it is in, the values kept are :func:`_evaluate`'s to
    the last bit."""
    G, P, D = pts.shape
    f0 = np.asarray(f(pts[:, 0]), float)
    vals = np.full((G, P), np.nan)
    vals[:, 0] = f0
    want = f0 >= f_old
    k = int(want.sum())
    if k:
        sub = pts[want]
        apart = np.any(sub[:, 0] != sub[:, 1], axis=1)
        v = f(np.concatenate([sub[:, 2:].reshape(-1, D), sub[apart, 1]]))
        got = np.empty((k, P))
        got[:, 0] = got[:, 1] = f0[want]
        got[:, 2:] = v[:k * (P - 2)].reshape(k, P - 2)
        got[apart, 1] = v[k * (P - 2):]
        vals[want] = got
    return vals


def _derivatives(vals: np.ndarray, x: np.ndarray, c: np.ndarray, free: list[int],
                 h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient at ``x`` and Hessian ``(G, d)``, ``(G, d, d)`` from stencil values."""
    d = len(free)
    fc = vals[:, 1]
    g = np.empty((vals.shape[0], d))
    H = np.empty((vals.shape[0], d, d))
    for a, i in enumerate(free):
        fp, fm = vals[:, 2 + 2 * a], vals[:, 3 + 2 * a]
        g[:, a] = (fp - fm) / (2.0 * h[i])
        H[:, a, a] = (fp - 2.0 * fc + fm) / (h[i] * h[i])
    k = 2 + 2 * d
    for a, i in enumerate(free):
        for b in range(a + 1, d):
            j = free[b]
            fij = vals[:, k]
            k += 1
            H[:, a, b] = H[:, b, a] = (fij - vals[:, 2 + 2 * a] - vals[:, 2 + 2 * b] + fc) / (
                h[i] * h[j])
    # the gradient at x from the one at the centre (they differ only next to a bound)
    dx = (x - c)[:, free]
    g = g + np.einsum("gab,gb->ga", H, dx)
    return g, H


def _trust_step(g: np.ndarray, H: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Maximiser of ``g.s + s.H.s / 2`` subject to ``|s| <= radius``, per row."""
    w, V = np.linalg.eigh(-H)  # -H = V diag(w) V^T
    gv = np.einsum("gda,gd->ga", V, g)
    lam_min = np.maximum(0.0, -w.min(axis=1)) + 1e-12 * (1.0 + np.abs(w).max(axis=1))

    def step_len(lam):
        return np.sqrt(np.sum((gv / (w + lam[:, None])) ** 2, axis=1))

    newton_ok = (w.min(axis=1) > 0) & (step_len(np.maximum(lam_min, 0.0)) <= radius)
    lam = np.where(newton_ok, np.maximum(lam_min, 0.0), 0.0)
    todo = ~newton_ok
    if todo.any():
        lo = lam_min.copy()
        hi = lo + np.linalg.norm(g, axis=1) / np.maximum(radius, 1e-300) + 1.0
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            long = step_len(mid) > radius
            lo = np.where(long, mid, lo)
            hi = np.where(long, hi, mid)
        lam = np.where(todo, hi, lam)
    s = np.einsum("gda,ga->gd", V, gv / (w + lam[:, None]))
    return s


def maximise_rows(f: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, free: list[int],
                  lo: np.ndarray, hi: np.ndarray, h: np.ndarray, scale: np.ndarray,
                  iters: int = 40, tol: float = 1e-7, radius0: float = 1.0,
                  lazy: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Maximise ``f`` over the coordinates ``free`` of every row of ``x0`` ``(G, D)``.

    ``f`` maps points ``(M, D)`` to values ``(M,)`` (``-inf`` where impossible) in one call.
    ``lo, hi, h, scale`` ``(D,)``: bounds, finite-difference steps and the scale of each
    coordinate (the trust region is a ball in ``x / scale``). Returns the maximisers and the
    maxima. A row stops when its step, in scaled units, is below ``tol`` (or its trust region
    has shrunk below it), or when the step is predicted to gain at most :data:`GAIN_TOL` of
    the row's value and moves no coordinate onto its bound.

    ``lazy``: after the first iteration, score each row's proposal first and its stencil only
    where the proposal is not worse than the row's accepted point (a rejected step needs no
    derivatives). The same iterates and results, bit for bit, where ``f`` scores a row the
    same in any batch (the hidden-role kernels do); fewer rows scored where steps are often
    rejected (near a maximum, the trust region shrinking to ``tol``), one call more per
    accepted step.
    """
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        return _maximise_rows(f, x0, free, lo, hi, h, scale, iters, tol, radius0, lazy)


def _maximise_rows(f, x0, free, lo, hi, h, scale, iters, tol, radius0, lazy):
    x = np.array(x0, dtype=np.float64, copy=True)
    G, D = x.shape
    if not free:
        return x, f(x)
    for j in free:
        x[:, j] = np.clip(x[:, j], lo[j], hi[j])
    fx = np.full(G, -np.inf)
    grad = np.zeros((G, len(free)))
    hess = np.zeros((G, len(free), len(free)))
    radius = np.full(G, float(radius0))
    active = np.ones(G, bool)
    prop = x.copy()
    predicted = np.zeros(G)
    sc = scale[free]
    first = True
    for _ in range(iters):
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        pts, c = _stencil(prop[rows], free, lo, hi, h)
        vals = _evaluate_lazy(f, pts, fx[rows]) if lazy and not first else _evaluate(f, pts)
        f_new = vals[:, 0]
        g_new, H_new = _derivatives(vals, prop[rows], c, free, h)
        ok = np.isfinite(vals).all(axis=1)
        better = ok & (f_new >= fx[rows]) if not first else ok
        if first:
            bad = rows[~ok]
            fx[bad] = f_new[~ok]  # the start itself may be impossible: nothing to improve
        gain = f_new - fx[rows]
        acc = rows[better]
        fx[acc] = f_new[better]
        x[acc] = prop[acc]
        grad[acc] = g_new[better]
        hess[acc] = H_new[better]
        if not first:
            ratio = np.where(predicted[rows] > 0, gain / np.maximum(predicted[rows], 1e-300), 1.0)
            grow = better & (ratio > 0.75)
            shrink = ~better | (ratio < 0.25)
            radius[rows[grow]] *= 2.0
            radius[rows[shrink & ~grow]] *= 0.25
        first = False
        # the next step of every active row, from its accepted point
        rows = np.flatnonzero(active)
        if not np.isfinite(fx[rows]).any():
            active[rows[~np.isfinite(fx[rows])]] = False
        rows = rows[np.isfinite(fx[rows])]
        if rows.size == 0:
            break
        gs, Hs = grad[rows] * sc, hess[rows] * np.outer(sc, sc)[None]
        # coordinates held by a bound (on it, pushed out of it) leave the Newton system, so
        # that the others solve their own part (a projected full step would stall there)
        xr = x[rows][:, free]
        held = (((xr <= lo[free]) & (gs < 0)) | ((xr >= hi[free]) & (gs > 0)))
        if held.any():
            gs = np.where(held, 0.0, gs)
            keep = ~held
            Hs = Hs * (keep[:, :, None] & keep[:, None, :])
            big = np.abs(Hs).max(axis=(1, 2)) + 1.0
            Hs = Hs - np.einsum("ga,ab->gab", held * big[:, None], np.eye(len(free)))
        s = _trust_step(gs, Hs, radius[rows]) * sc
        new = x[rows].copy()
        new[:, free] += s
        for j in free:
            new[:, j] = np.clip(new[:, j], lo[j], hi[j])
        s_eff = (new - x[rows])[:, free] / sc
        predicted[rows] = (np.einsum("ga,ga->g", s_eff, gs)
                           + 0.5 * np.einsum("ga,gab,gb->g", s_eff, Hs, s_eff))
        size = np.sqrt(np.sum(s_eff ** 2, axis=1))
        # a step onto a bound is still tried, however small its gain: a maximum on a bound
        # ends exactly on it
        moved = new[:, free] != x[rows][:, free]
        onto = np.any(moved & ((new[:, free] <= lo[free]) | (new[:, free] >= hi[free])), axis=1)
        tiny = (predicted[rows] <= GAIN_TOL * np.maximum(1.0, np.abs(fx[rows]))) & ~onto
        done = (size < tol) | (radius[rows] < tol) | tiny
        active[rows[done]] = False
        prop[rows] = new
    return x, fx


def hessian_at(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, free: list[int],
               lo: np.ndarray, hi: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient ``(d,)`` and Hessian ``(d, d)`` of ``f`` over ``free`` at the point ``x``
    ``(D,)`` (finite differences, one call)."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        pts, c = _stencil(x[None], free, lo, hi, h)
        vals = _evaluate(f, pts)
        g, H = _derivatives(vals, x[None], c, free, h)
    return g[0], H[0]


__all__ = ["hessian_at", "maximise_rows"]
