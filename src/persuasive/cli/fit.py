"""``persuasive fit``: fit human models to recorded driving (docs/method.md §13).

Reads per-step Parquet logs (``simulate --out``, ``drive`` trials, the files ``replay``
reads), re-solves the human's game at every logged step, fits each human model by maximum
likelihood (one parameter set for all runs, or one per participant), prints the estimates with
95 % intervals and the comparison (log-likelihood, AIC, BIC), and optionally writes the report
(``.json``) or the runs with the human's smoothed role per step (``.parquet``, drawn by
``persuasive plot profile --from FILE --run K``). Every input is checked before anything is
written; a bad log, a log given twice (also as another spelling of its path or a link) or a
``--sigma-min`` outside [1e-9, 1] m/s^2 ends the command with one line naming it and exit
status 2.

Given pairs files (``persuasive recordings pairs --out PAIRS.parquet``, told apart by their
Parquet metadata), it evaluates the models held out instead
(:mod:`persuasive.recordings.evaluate`): each pair from each driver's view, in memory; fits
on some recording files and scores the others (``--folds K``, ``--holdout FRACTION``,
``--test-site NAME``): the log-likelihood per step of the next accelerations, and who passes
first, beside the baselines, with bootstrap intervals over recording files.
"""

from __future__ import annotations

import json
import math

import click

from .._compile import StudyClock
from ..config import SCENARIO_KINDS
from ._common import (check_readable, check_workers, compile_report, lock_output,
                      progress_bar, workers_type)

MODEL_CHOICES = ("lfg", "stubborn", "noisy", "idm", "all")


def _fmt(x, digits: int = 3) -> str:
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.{digits}g}" if abs(x) < 1e-3 and x != 0 else f"{x:.{digits}f}"


def _estimate_text(name: str, est) -> str:
    if est.low is None and est.high is None:
        return f"{name} = {_fmt(est.value)} ({est.method})"
    return f"{name} = {_fmt(est.value)} [{_fmt(est.low)}, {_fmt(est.high)}] ({est.method})"


def _print_report(report, header: str) -> None:
    ev = report.evidence
    click.echo(f"{header}{ev.n_runs} run{'s' * (ev.n_runs != 1)}, {ev.n_steps} steps; "
               f"sigma_min = {report.sigma_min:g} m/s^2")
    rows = report.comparison()
    click.echo("| model | parameters | log-likelihood | AIC | BIC | delta BIC | exact |")
    click.echo("|---|---|---|---|---|---|---|")
    for r in rows:
        click.echo(f"| {r['model']} | {r['n_params']} | {r['loglik']:.2f} | {r['aic']:.2f} | "
                   f"{r['bic']:.2f} | {r['delta_bic']:.2f} | {'yes' if r['exact'] else 'no'} |")
    click.echo(f"selected (smallest BIC): {report.selected}")
    for r in rows:
        fit = report.fits[r["model"]]
        click.echo(f"{fit.model}: " + "; ".join(_estimate_text(k, v)
                                                for k, v in fit.params.items()))
        for k, v in fit.params.items():
            if v.note:
                click.echo(f"  note: {k}: {v.note}")
        for note in fit.notes:
            click.echo(f"  note: {note}")
    if report.role_model is not None:
        click.echo(f"roles smoothed under {report.role_model}: mean P(leader) at the first "
                   f"step {_mean_first(report):.3f}, at the last {_mean_last(report):.3f}")


def _fit(ev, models, sigma_min: float, intervals: str, group: str | None = None):
    """One :class:`persuasive.fitting.FitReport`; ``intervals = "selected"``: every model
    without intervals, then the selected one again with them."""
    from ..fitting import FitReport, fit_models, smooth
    from ..fitting.comparison import ROLE_MODELS
    from ..fitting.estimate import MODELS

    if intervals != "selected":
        return fit_models(ev, models, sigma_min, intervals == "all", group)
    first = fit_models(ev, models, sigma_min, False, group)
    fits = dict(first.fits)
    fits[first.selected] = fit_models(ev, [first.selected], sigma_min, True).fits[
        first.selected]
    selected = min(fits.values(), key=lambda f: (f.bic, MODELS.index(f.model))).model
    role_model = selected if selected in ROLE_MODELS else first.role_model
    p_leader = smooth(ev, fits[role_model]) if role_model is not None else None
    return FitReport(ev, fits, selected, role_model, p_leader, group, sigma_min)


def _notice_compile() -> None:
    """The compile notice (its usual line) when the closed loop's or the fit's kernels are not
    cached yet, and then the fit's kernels compiled at once
    (:func:`persuasive.fitting.estimate.warm_up`). Called once the inputs are read: a bad
    input is refused before any compile."""
    import os

    from ._common import compile_notice
    from ..fitting.estimate import warm_up
    from ..fitting.evidence import human_views
    from ..fitting.models import hmm_loglik, path_loglik

    # the fit's kernels live in two files; an edit to either recompiles that file's
    try:
        cached = all(os.path.getmtime(k._cache._cache_file._index_path)  # numba's layout
                     >= os.path.getmtime(k.py_func.__code__.co_filename)
                     for k in (hmm_loglik, path_loglik, human_views))
    except (AttributeError, OSError):
        cached = False
    if cached:
        compile_notice()
        return
    compile_notice(hmm_loglik, path_loglik, human_views)
    warm_up()


def _mean_first(report) -> float:
    ev = report.evidence
    return float(report.p_leader[ev.starts[:-1]].mean())


def _mean_last(report) -> float:
    ev = report.evidence
    return float(report.p_leader[ev.starts[1:] - 1].mean())


def _sigma_min(ctx, param, value):
    """``--sigma-min`` in its range (``check_sigma_min`` says why), checked as the command
    line is read, before anything is."""
    from ..fitting.estimate import check_sigma_min

    return check_sigma_min(value, "--sigma-min")


class _BadInput(click.ClickException):
    """Bad input: one line, exit status 2."""

    exit_code = 2


def _fmt_interval(d: dict, digits: int = 3) -> str:
    value, (lo, hi) = d["value"], d["ci95"]
    if value is None:
        return "-"
    if lo is None or hi is None:
        return f"{value:.{digits}f}"
    return f"{value:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def _print_evaluation(d: dict, elapsed: float, out: str | None) -> None:
    sp, pairs, lim, sel = d["split"], d["pairs"], d["limits"], d["selection"]
    dropped = ", ".join(f"{v} with {k}" for k, v in sel["left_out"].items() if v)
    pet = sel["pet_max_s"]
    click.echo(f"pairs evaluated: {sel['selected']} of {sel['read']}, "
               + ("every pair (--pet-max inf)" if pet == "inf" else
                  f"those with a PET at the conflict area (pet_area_s) of at most {pet:g} s "
                  f"(--pet-max)" + (f"; left out: {dropped}" if dropped else "")))
    left = ", ".join(f"{k} {v}" for k, v in pairs["left_out"].items() if v)
    click.echo(f"held-out evaluation: {sp['describe']} (seed {sp['seed']}); {sp['files']} "
               f"recording files, {pairs['total']} pairs, {pairs['kept']} predicted"
               + (f"; left out: {left}" if left else ""))
    mo = d["moment"]
    lead = mo["lead_time_s_quantiles"]
    click.echo(f"prediction moment: {mo['rule']}; seen up to {mo['seen_until_s_before']:g} s "
               "before it (no smoothed value seen uses a later sample)"
               + (f"; first arrival {lead['50%']:.2f} s after it (median)" if lead else ""))
    q = lim["quantiles"]
    click.echo(f"vehicle limits: the {q[0]:g} and {q[1]:g} quantiles of the "
               "training files' smoothed accelerations per class; test steps beyond them "
               f"{100 * lim['share_beyond_fitted']:.1f} %, beyond the paper's [-2, 1] m/s^2 "
               f"{100 * lim['share_beyond_paper']:.1f} %, above v_max "
               f"{100 * lim['share_above_v_max']:.1f} %")
    strongest = d["strongest_baseline"]
    click.echo("| predictor | log-lik/step | accuracy | AUC | Brier | log-loss | ECE | "
               f"vs {strongest} (log-loss) |")
    click.echo("|---|---|---|---|---|---|---|---|")
    for r in d["rows"]:
        ll = _fmt_interval(r["loglik_per_step"], 2) if "loglik_per_step" in r else "-"
        vs = _fmt_interval(r["delta_log_loss"]) if "delta_log_loss" in r else "-"
        name = r["name"] if r["kind"] == "model" else f"{r['name']} (baseline)"
        cells = [_fmt_interval(r[k]) for k in ("accuracy", "auc", "brier", "log_loss", "ece")]
        click.echo(f"| {name} | {ll} | " + " | ".join(cells) + f" | {vs} |")
    click.echo(f"strongest baseline (smallest log-loss): {strongest}; intervals: 95 % "
               f"percentile bootstrap over recording files, {d['bootstrap']['resamples']} "
               f"resamples (seed {d['bootstrap']['seed']})")
    click.echo(f"time: {elapsed:.2f} s" + (f"; written to {out}" if out else ""))


def _evaluate_pairs(paths, model, sigma_min, out, as_json, holdout, folds, test_site,
                    seed, workers=None, quiet=False, pet_max=None) -> None:
    """``fit PAIRS.parquet...``: the held-out evaluation (module docstring)."""
    from click.core import ParameterSource

    from .._files import check_output_file
    from ..fitting import write_json
    from ..fitting.estimate import MODELS
    from ..recordings.evaluate import (PET_MAX_S, EvalParams, Split, evaluate_pairs,
                                       read_pair_data)
    from ..recordings.formats import RecordingError

    ctx = click.get_current_context()
    for name, flag in (("per_participant", "--per-participant"), ("scenario", "--scenario"),
                       ("intervals", "--intervals")):
        if ctx.get_parameter_source(name) == ParameterSource.COMMANDLINE:
            raise _BadInput(f"{flag} does not apply to pairs files: the held-out evaluation "
                            "fits point estimates over every pair's own scenario")
    if sum(x is not None for x in (holdout, folds, test_site)) > 1:
        raise _BadInput("--holdout, --folds and --test-site are three ways to split: give one")
    if holdout is not None and not (math.isfinite(holdout) and 0.0 < holdout < 1.0):
        raise _BadInput(f"--holdout = {holdout:g} is out of range; allowed: (0, 1), the share "
                        "of recording files tested")
    if pet_max is not None and not (pet_max > 0.0):  # NaN too
        raise _BadInput(f"--pet-max = {pet_max:g} is out of range; allowed: (0, inf] s, the "
                        "largest PET at the conflict area (pet_area_s) of a pair evaluated "
                        "(inf: every pair)")
    if folds is not None and folds < 2:
        raise _BadInput(f"--folds = {folds} is out of range; allowed: 2 to the number of "
                        "recording files")
    if test_site is not None and len(paths) < 2:
        raise _BadInput("--test-site needs several pairs files (each a site) to train on the "
                        "others")
    if out:
        check_output_file(out, (".json",), "evaluation report")
        lock_output(out, "evaluation report")
    if holdout is not None:
        split = Split("holdout", fraction=holdout)
    elif test_site is not None:
        split = Split("site", test_site=test_site)
    else:
        split = Split("folds", k=folds)
    models = MODELS if model == "all" else (model,)
    params = EvalParams(seed=seed if seed is not None else 0, sigma_min=sigma_min,
                        pet_max_s=PET_MAX_S if pet_max is None else pet_max)
    clock = StudyClock()
    n_folds = 1 if split.kind != "folds" else (folds or 5)
    workers = check_workers(workers, n_folds)
    bar = prep = None
    try:
        pairs = read_pair_data(paths)
        _notice_compile()
        # the views' geometry, built once before the folds, then the folds
        prep = progress_bar(quiet, unit="view")
        bar = progress_bar(quiet, unit="fold")
        result = evaluate_pairs(pairs, split, models, params, workers=workers, progress=bar,
                                prepare=prep)
        del pairs
    except RecordingError as exc:
        raise _BadInput(str(exc)) from None
    finally:
        for b in (prep, bar):
            if b is not None:
                b.close()  # type: ignore[attr-defined]
    elapsed = clock.seconds
    payload = result.to_dict()
    payload["seconds"] = round(elapsed, 3)
    if out:
        write_json(out, payload)
    compile_report(clock)
    if as_json:
        click.echo(json.dumps(payload, allow_nan=False))
        return
    _print_evaluation(payload, elapsed, out)


@click.command()
@click.argument("logs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--model", "model", type=click.Choice(list(MODEL_CHOICES)), default="all",
              show_default=True, help="Human model to fit; all fits and compares them.")
@click.option("--per-participant", is_flag=True,
              help="One fit per participant of drive trials (the participant each trial "
                   "stores; trials older than that: their file name, <participant>-tNN-"
                   "<condition>.parquet) instead of one for all runs.")
@click.option("--scenario", type=click.Choice(list(SCENARIO_KINDS)), default=None,
              help="The model's scenario; logs of another are refused [the first log's].")
@click.option("--sigma-min", type=float, default=1e-3, show_default=True, metavar="M/S^2",
              callback=_sigma_min,
              help="Floor of the acceleration noise's standard deviation, in [1e-9, 1] m/s^2 "
                   "(exact data end on it).")
@click.option("--intervals", type=click.Choice(["all", "selected", "none"]), default="all",
              show_default=True, help="Which fitted models get 95 % intervals.")
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Write the report (.json) or the runs with their smoothed roles "
                   "(.parquet, for 'plot profile --from FILE --run K').")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option("--holdout", type=float, default=None, metavar="FRACTION",
              help="Pairs files: test on this share of the recording files, in (0, 1); train "
                   "on the rest.")
@click.option("--folds", type=int, default=None, metavar="K",
              help="Pairs files: K folds by recording file, each file tested once [5, or one "
                   "per file].")
@click.option("--test-site", default=None, metavar="NAME",
              help="Pairs files: train on the other pairs files (sites), test on this one "
                   "(its file name without .parquet).")
@click.option("--pet-max", "pet_max", type=float, default=None, metavar="SECONDS",
              help="Pairs files: evaluate the pairs whose PET at the conflict area "
                   "(pet_area_s) is at most this, in (0, inf] s; inf: every pair (a site's "
                   "waiting cars pair with every car that passes) [4].")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=None,
              help="Pairs files: seed of the split and of the bootstrap [0].")
@click.option("--workers", type=workers_type(), default=None,
              help="Pairs files: worker processes, one fold each at a time [all cores, at "
                   "most the folds]; the evaluation does not depend on it.")
@click.option("--quiet", is_flag=True, help="Pairs files: no progress bar over the folds.")
def fit(logs, model, per_participant, scenario, sigma_min, intervals, out, as_json, holdout,
        folds, test_site, pet_max, seed, workers, quiet) -> None:
    """Fit human models to recorded driving (simulate --out logs, drive trials), or evaluate
    them held out on recorded pairs (pairs files of 'persuasive recordings pairs').

    Each log counts once: a file given twice (./x and x, a link) is refused. --sigma-min
    [1e-9, 1] m/s^2: below, float rounding of a re-solved game would decide whether data are
    exact; above, the floor is a third of a vehicle's acceleration range.
    """
    from .._files import check_output_file
    from ..config import ConfigError
    from ..fitting import (OUT_EXTENSIONS, evidence_of, load_logs, report_dict,
                           write_fit_parquet, write_json)
    from ..fitting.estimate import MODELS
    from ..fitting.evidence import check_distinct
    from ..recordings.evaluate import is_pairs_file

    check_readable(logs, "log file")  # every input, before any is read or compiled for
    kinds = [is_pairs_file(p) for p in logs]
    if any(kinds):
        if not all(kinds):
            other = logs[kinds.index(False)]
            raise _BadInput(f"{other!r} is not a pairs file: give pairs files "
                            "('persuasive recordings pairs --out FILE.parquet') or logs, not "
                            "both")
        check_distinct(logs)
        _evaluate_pairs(logs, model, sigma_min, out, as_json, holdout, folds, test_site, seed,
                        workers, quiet, pet_max)
        return
    for value, flag in ((holdout, "--holdout"), (folds, "--folds"), (test_site, "--test-site"),
                        (pet_max, "--pet-max"), (seed, "--seed"), (workers, "--workers")):
        if value is not None:
            raise _BadInput(f"{flag} applies to pairs files ('persuasive recordings pairs --out "
                            "FILE.parquet'), not to logs")

    ext = check_output_file(out, OUT_EXTENSIONS, "fit") if out else None
    if out:
        lock_output(out, "fit")
    clock = StudyClock()
    runs = load_logs(logs, scenario)  # reads and checks every log, compiles nothing
    if per_participant:
        for log in runs:
            if log.participant is None:
                raise ConfigError(f"--per-participant: log file {log.source!r} is not a drive "
                                  "trial (it names no participant: 'persuasive drive' stores "
                                  "one in each trial it writes)")
    _notice_compile()
    models = MODELS if model == "all" else (model,)
    ev = evidence_of(runs)
    if per_participant:
        groups: dict[str, list[int]] = {}
        for i, log in enumerate(runs):
            groups.setdefault(log.participant, []).append(i)
        reports = [_fit(ev.subset(idx), models, sigma_min, intervals, name)
                   for name, idx in sorted(groups.items())]
    else:
        reports = [_fit(ev, models, sigma_min, intervals)]
    elapsed = clock.seconds
    payload = report_dict(reports)
    payload["seconds"] = round(elapsed, 3)
    if out:
        if ext == ".json":
            write_json(out, payload)
        else:
            write_fit_parquet(out, reports, payload)
    compile_report(clock)
    if as_json:
        click.echo(json.dumps(payload, allow_nan=False))
        return
    for report in reports:
        header = f"participant {report.group}: " if report.group is not None else "fit of "
        _print_report(report, header)
    click.echo(f"time: {elapsed:.2f} s" + (f"; written to {out}" if out else ""))
