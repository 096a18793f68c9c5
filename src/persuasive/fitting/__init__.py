"""Fitting human models to recorded driving (docs/method.md §13).

- :mod:`.filter`: the forward filter over the human's hidden role, one step at a time (the
  same pass serves an offline fit over whole runs and an online posterior over ``p_a``);
- :mod:`.evidence`: reading logs and re-solving the human's game at every logged step;
- :mod:`.models`: the likelihood kernels of the human models (``lfg``, ``stubborn``,
  ``noisy``, ``idm``);
- :mod:`.optimize`, :mod:`.estimate`, :mod:`.idm`: maximum likelihood, profile-likelihood
  intervals;
- :mod:`.comparison`: several models on the same runs, AIC/BIC, smoothed roles;
- :mod:`.output`: the report (JSON) and the runs with their smoothed roles (Parquet).

From Python::

    from persuasive.fitting import evidence_of, fit_models, load_logs

    report = fit_models(evidence_of(load_logs(["run1.parquet", "run2.parquet"])))
    report.selected, report.fits["lfg"].params["p_a"]
"""

from .comparison import FitReport, fit_models, smooth
from .estimate import MODELS, SIGMA_MIN, SIGMA_MIN_RANGE, Estimate, ModelFit, check_sigma_min
from .evidence import Evidence, RunLog, evidence_of, load_logs, read_log
from .output import (FIT_METADATA, OUT_EXTENSIONS, is_fit_file, load_fitted_run, report_dict,
                     write_fit_parquet, write_json)

__all__ = ["Estimate", "Evidence", "FIT_METADATA", "FitReport", "MODELS", "ModelFit",
           "OUT_EXTENSIONS", "RunLog", "SIGMA_MIN", "SIGMA_MIN_RANGE", "check_sigma_min",
           "evidence_of", "fit_models", "is_fit_file", "load_fitted_run", "load_logs",
           "read_log", "report_dict", "smooth", "write_fit_parquet", "write_json"]
