"""The forward filter over the human's hidden role, as the fit uses it.

The filter itself lives in :mod:`persuasive.role_filter` (docs/method.md §13.2), below the
policies, so that the planner's online posterior over ``p_a`` (:mod:`persuasive.online`) runs
the same compiled functions without importing the fitting package; this module keeps the
fit's names.
"""

from __future__ import annotations

from ..role_filter import (emission_lik, filter_loglik, filter_posterior, filter_predict,
                           filter_start, filter_step, filter_update, filter_update_lik,
                           role_transition, smooth_roles)

__all__ = ["emission_lik", "filter_loglik", "filter_posterior", "filter_predict",
           "filter_start", "filter_step", "filter_update", "filter_update_lik",
           "role_transition", "smooth_roles"]
