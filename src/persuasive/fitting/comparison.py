"""Fitting several human models to the same runs, comparing them, and the human's smoothed
role per step (docs/method.md §13.6).

:func:`fit_models` fits each model of ``models`` (maximum likelihood, one parameter set shared
by every run), ranks them by BIC (AIC beside it), and smooths the role of every run under the
role model (the selected one if it has a role, else the ``lfg``): ``P(role_k = L | the whole
run)`` by forward-backward at the estimate (``persuasive fit --per-participant`` calls it
once per participant of a ``drive`` study).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .estimate import MODELS, SIGMA_MIN, ModelFit, _num, check_sigma_min, fit_role_model
from .evidence import Evidence
from .models import EMIT_LFG, EMIT_NOISY, smooth_runs

#: The models with a hidden role.
ROLE_MODELS = ("lfg", "stubborn", "noisy")


@dataclass
class FitReport:
    """The fits of one set of runs, their comparison and the smoothed roles."""

    evidence: Evidence = field(repr=False)
    fits: dict[str, ModelFit]
    selected: str  #: the model with the smallest BIC
    role_model: str | None  #: the model the roles are smoothed under
    p_leader: np.ndarray | None = field(repr=False)  #: (n,) smoothed P(role = L) per step
    group: str | None = None  #: the participant, for a per-participant fit
    sigma_min: float = SIGMA_MIN

    def comparison(self) -> list[dict]:
        """One row per model, by increasing BIC: log-likelihood, parameters, AIC, BIC and
        their differences to the best."""
        rows = sorted(self.fits.values(), key=lambda f: (f.bic, MODELS.index(f.model)))
        best_aic = min(f.aic for f in rows)
        best_bic = rows[0].bic
        return [{"model": f.model, "loglik": f.loglik, "n_params": f.n_params,
                 "n_obs": f.n_obs, "aic": f.aic, "bic": f.bic, "delta_aic": f.aic - best_aic,
                 "delta_bic": f.bic - best_bic, "exact": f.exact} for f in rows]

    def runs(self) -> list[dict]:
        """Per run: the source, its steps, its initial-role posterior and its log-likelihood
        under each model."""
        ev = self.evidence
        out = []
        for i, log in enumerate(ev.runs):
            a, b = ev.starts[i], ev.starts[i + 1]
            row = {"source": log.source, "seed": log.seed, "steps": int(b - a),
                   "hv_kind": log.config.hv.kind}
            if log.participant is not None:
                row["participant"] = log.participant
            if self.p_leader is not None:
                row["p_initial_leader"] = _num(self.p_leader[a])
                row["p_final_leader"] = _num(self.p_leader[b - 1])
            row["loglik"] = {m: _num(f.run_loglik[i]) for m, f in self.fits.items()}
            out.append(row)
        return out

    def to_dict(self, runs: bool = True) -> dict:
        ev = self.evidence
        out = {"runs": ev.n_runs, "steps": ev.n_steps, "sigma_min": self.sigma_min,
               "selected": self.selected, "selection": "smallest BIC",
               "role_model": self.role_model,
               "models": {m: f.to_dict() for m, f in self.fits.items()},
               "comparison": [{k: (_num(v) if isinstance(v, float) else v)
                               for k, v in row.items()} for row in self.comparison()]}
        if self.group is not None:
            out = {"participant": self.group, **out}
        if runs:
            out["run_details"] = self.runs()
        return out


def smooth(ev: Evidence, fit: ModelFit) -> np.ndarray:
    """``P(role_k = L | the whole run)`` at every step under a fitted role model ``(n,)``."""
    t = fit.theta
    out = np.empty(ev.n_steps)
    run_ll = np.empty(ev.n_runs)
    kind = EMIT_NOISY if fit.model == "noisy" else EMIT_LFG
    smooth_runs(kind, ev.starts, ev.accel, ev.a_role, ev.pl, ev.q, ev.a_first,
                float(t["p_a"]), float(t["pi0"]), float(t["sigma"]), float(t["beta"]), out,
                run_ll)
    return out


def fit_models(ev: Evidence, models: Sequence[str] = MODELS, sigma_min: float = SIGMA_MIN,
               intervals: bool | Sequence[str] = True, group: str | None = None) -> FitReport:
    """Fit every model of ``models`` to the evidence; see the module docstring.

    ``sigma_min``: the floor of the noise's standard deviation [m/s^2], in [1e-9, 1]
    (:func:`persuasive.fitting.estimate.check_sigma_min` says why; another value raises
    :class:`persuasive.config.ConfigError` naming it and the range). ``intervals``: True
    (every model), False (none: point estimates, for model selection in bulk), or the names of
    the models that get them.
    """
    from .idm import fit_idm

    unknown = [m for m in models if m not in MODELS]
    if unknown or not models:
        raise ValueError(f"unknown models {unknown}; allowed: {', '.join(MODELS)}")
    sigma_min = check_sigma_min(sigma_min)

    def wants(m: str) -> bool:
        return intervals if isinstance(intervals, bool) else m in intervals

    fits: dict[str, ModelFit] = {}
    order = [m for m in MODELS if m in models]
    lfg_fit = None
    for m in order:
        if m == "idm":
            fits[m] = fit_idm(ev, sigma_min, wants(m))
        else:
            start = None
            if m == "noisy":
                lfg_fit = fits.get("lfg") or lfg_fit
                if lfg_fit is None:
                    lfg_fit = fit_role_model(ev, "lfg", sigma_min, intervals=False)
                start = lfg_fit.theta
            fits[m] = fit_role_model(ev, m, sigma_min, wants(m), start)
    selected = min(fits.values(), key=lambda f: (f.bic, MODELS.index(f.model))).model
    role_model = selected if selected in ROLE_MODELS else (
        "lfg" if "lfg" in fits else next((m for m in order if m in ROLE_MODELS), None))
    p_leader = smooth(ev, fits[role_model]) if role_model is not None else None
    return FitReport(ev, fits, selected, role_model, p_leader, group, sigma_min)


__all__ = ["FitReport", "ROLE_MODELS", "fit_models", "smooth"]
