"""Parameter recovery and model selection of ``persuasive fit`` (docs/method.md §13.7).

    python benchmarks/fit_recovery.py [--datasets 100] [--runs 50] [--workers 2]
                                      [--out results/fit-recovery] [--only KIND[:P_A]]
                                      [--smoke] [--timing] [--drive results/drive]

**Recovery.** Datasets of ``--runs`` runs are simulated with a known human and fitted:

- ``lfg`` with ``p_a`` in {0.3, 0.5, 0.7, 0.9, 1.0}, both initial roles, without and with
  acceleration noise (``simulation.accel_noise_mps2`` = 0.1 m/s^2, uniform): 20 settings; each
  dataset is fitted with the ``lfg`` model, 95 % profile interval of ``p_a``;
- for model selection also ``stubborn`` and ``noisy`` (``p_a = 0.7``, ``beta = 0.1``) with
  both initial roles, and ``idm`` (critical gap 1.5 s, time gap 1.2 s, desired speed 9 m/s, not
  the fit's start values), each without and with noise: 10 settings.

Every dataset is fitted with all four models (point estimates) and the smallest BIC names the kind.
The design of a dataset: corrected mode, the paper's intersection, run ``j`` against the persuasive
AV when ``j`` is even and the passive AV when odd (the two planners of the built-in ``drive``
study), both AVs assuming ``p_a_hat = 1`` (Table 2's rows and the drive study) and unshielded (the
shield, on by default in corrected mode, came later; it changes what the AV does, not the human,
and the recovery figures were measured without it); seeds ``1 + runs * d + j`` for dataset ``d``.
The persuasive AV gives a human who starts as leader its chances to change role (it tries to lead),
the passive AV one who starts as follower (it yields).

Per dataset one JSON line goes to ``OUT/results.jsonl`` as soon as it is done: run the same
command again to resume. ``OUT/meta.json`` records a digest of the code of the fitting
modules and of the design (docstrings and comments aside); results of other code are refused
(start a new ``--out``). The summary (coverage, mean absolute error, interval width, the
informative steps per dataset, selection accuracy) is printed and written to
``OUT/summary.md`` and ``OUT/summary.json``. An *informative step* is one where the human
could change role (its role is not its plausible role) and the two roles act differently.
Counting ``m`` such steps as observed Bernoulli(``p_a``) trials would estimate ``p_a`` with
standard error ``sqrt(p_a (1 - p_a) / m)``, a mean absolute error of ``sqrt(2 / pi)`` times
that: the summary prints this reference beside the error (the fit also learns from the
steps around them, and does a little better). ``--only KIND[:P_A]`` runs the settings of one
kind (e.g. ``lfg:0.7`` with ``--runs 200``: the error shrinks with the information).

**Timing** (``--timing``): 1000 runs of 61 steps are written as Parquet logs, then fitted with
the ``lfg`` model: the command end to end (``persuasive fit DIR/*.parquet --model lfg``) and
the fit in memory (evidence and estimation), 5 times each, medians.

**Drive trials** (``--drive DIR``): when recorded trials of the built-in study exist there,
they are fitted per participant (``persuasive fit DIR/*.parquet --per-participant``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

import numpy as np

P_VALUES = (0.3, 0.5, 0.7, 0.9, 1.0)
ROLES = ("leader", "follower")
NOISES = (0.0, 0.1)
IDM_TRUE = {"hv.idm.critical_gap_s": 1.5, "hv.idm.time_gap_s": 1.2,
            "hv.idm.desired_speed_mps": 9.0}


def settings() -> list[dict]:
    out = []
    for p in P_VALUES:
        for role in ROLES:
            for noise in NOISES:
                out.append({"kind": "lfg", "p_a": p, "role": role, "noise": noise})
    for kind, p in (("stubborn", 0.0), ("noisy", 0.7)):
        for role in ROLES:
            for noise in NOISES:
                out.append({"kind": kind, "p_a": p, "role": role, "noise": noise})
    for noise in NOISES:
        out.append({"kind": "idm", "p_a": None, "role": None, "noise": noise})
    return out


def key(setting: dict, d: int) -> str:
    return f"{setting['kind']}|{setting['p_a']}|{setting['role']}|{setting['noise']}|{d}"


def configs(setting: dict):
    from persuasive import Config

    base = {"hv.kind": setting["kind"], "simulation.accel_noise_mps2": setting["noise"],
            "mpc.p_a_hat": 1.0, "av.shield": "off"}
    if setting["kind"] in ("lfg", "noisy"):
        base["roles.p_a"] = setting["p_a"]
    if setting["role"] is not None:
        base["hv.role"] = setting["role"]
    if setting["kind"] == "idm":
        base.update(IDM_TRUE)
    return [Config(mode="corrected").with_overrides({**base, "av.kind": av})
            for av in ("persuasive", "passive")]


def informative_steps(records, ev) -> int:
    """Steps where the human could change role (its role is not its plausible role) and the two
    roles act differently: what identifies ``p_a``."""
    total = 0
    for i, rec in enumerate(records):
        if "hv_role" not in rec.log:
            return 0
        role = (rec.log["hv_role"] != "leader").astype(int)
        a, b = ev.starts[i], ev.starts[i + 1]
        own_pl = ev.pl[a:b][np.arange(b - a), role]
        chance = own_pl != (1 - role)
        differ = ev.a_role[a:b, 0] != ev.a_role[a:b, 1]
        total += int(np.sum(chance & differ))
    return total


def run_task(setting: dict, d: int, runs: int) -> dict:
    from persuasive import simulate
    from persuasive.fitting import evidence_of, fit_models
    from persuasive.fitting.evidence import run_log_of

    cs = configs(setting)
    t0 = time.perf_counter()
    records = [simulate(cs[j % 2], 1 + runs * d + j) for j in range(runs)]
    t_sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    ev = evidence_of([run_log_of(r) for r in records])
    wanted = ["lfg"] if setting["kind"] == "lfg" else False
    report = fit_models(ev, intervals=wanted)
    t_fit = time.perf_counter() - t0
    cmp = report.comparison()
    out = {"key": key(setting, d), **setting, "dataset": d, "runs": runs,
           "steps": ev.n_steps, "selected_bic": report.selected,
           "selected_aic": min(cmp, key=lambda r: r["aic"])["model"],
           "loglik": {r["model"]: r["loglik"] for r in cmp},
           "informative_steps": informative_steps(records, ev),
           "role_changes": int(sum(r.outcome.hv_role_changes for r in records)),
           "seconds_simulate": round(t_sim, 3), "seconds_fit": round(t_fit, 3)}
    lfg = report.fits["lfg"]
    if setting["kind"] == "lfg":
        e = lfg.params["p_a"]
        out.update({"p_hat": e.value, "low": e.low, "high": e.high, "method": e.method,
                    "sigma_hat": lfg.theta["sigma"], "pi0_hat": lfg.theta["pi0"],
                    "exact": lfg.exact})
    return out


def _code_of(source: str) -> str:
    """The syntax tree of Python source without docstrings (comments are not in it): what
    runs, whatever the documentation says."""
    import ast

    tree = ast.parse(source)
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                              ast.AsyncFunctionDef)) and body
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree)


def code_digest() -> str:
    """A hash of the code of the fitting modules that make the results and of the study's
    design (docstrings and comments left out)."""
    import inspect
    import textwrap

    import persuasive

    root = Path(persuasive.__file__).parent
    h = hashlib.sha256()
    for name in ("filter", "evidence", "models", "optimize", "estimate", "idm", "comparison"):
        path = root / "fitting" / f"{name}.py"
        h.update(name.encode() + b"\0" + _code_of(path.read_text()).encode())
    for func in (settings, key, configs, informative_steps, run_task):  # the design
        h.update(_code_of(textwrap.dedent(inspect.getsource(func))).encode())
    h.update(repr((P_VALUES, ROLES, NOISES, IDM_TRUE)).encode())
    return h.hexdigest()[:16]


def summarise(rows: list[dict], n_datasets: int) -> tuple[dict, str]:
    """Coverage, error and selection tables (markdown) from the result lines."""
    rec_lines = ["| p_a | initial role | accel. noise | datasets | coverage of 95 % CI | "
                 "MAE | binomial reference MAE | mean CI width | one-sided CIs | "
                 "informative steps per dataset | p_a estimate mean |",
                 "|---|---|---|---|---|---|---|---|---|---|---|"]
    summary = {"recovery": [], "selection": []}
    for s in settings():
        if s["kind"] != "lfg":
            continue
        rs = [r for r in rows if r["key"].rsplit("|", 1)[0] == key(s, 0).rsplit("|", 1)[0]]
        if not rs:
            continue
        cover = np.mean([r["low"] - 1e-9 <= s["p_a"] <= r["high"] + 1e-9 for r in rs])
        mae = np.mean([abs(r["p_hat"] - s["p_a"]) for r in rs])
        width = np.mean([r["high"] - r["low"] for r in rs])
        one = np.mean(["one-sided" in r["method"] for r in rs])
        info = np.mean([r["informative_steps"] for r in rs])
        mean = np.mean([r["p_hat"] for r in rs])
        # the error of counting: m observed Bernoulli(p_a) trials of a role change estimate
        # p_a with standard error sqrt(p (1 - p) / m), a mean absolute error of sqrt(2 / pi)
        # times that (the fit also learns from steps where the roles act alike, and can do
        # better)
        bound = math.sqrt(2 / math.pi * s["p_a"] * (1 - s["p_a"]) / info) if info else math.nan
        summary["recovery"].append({**s, "datasets": len(rs), "coverage": cover, "mae": mae,
                                    "mae_binomial": bound, "mean_width": width, "one_sided": one,
                                    "informative_steps": info, "mean_estimate": mean})
        rec_lines.append(f"| {s['p_a']:.1f} | {s['role']} | {s['noise']:g} | {len(rs)} | "
                         f"{100 * cover:.0f} % | {mae:.3f} | {bound:.3f} | {width:.3f} | "
                         f"{100 * one:.0f} % | {info:.0f} | {mean:.3f} |")
    sel_lines = ["| generating kind | initial role | accel. noise | datasets | selected by BIC "
                 "| by AIC | BIC picks |", "|---|---|---|---|---|---|---|"]
    by_kind: dict[str, list] = {}
    for s in settings():
        prefix = key(s, 0).rsplit("|", 1)[0]
        rs = [r for r in rows if r["key"].rsplit("|", 1)[0] == prefix]
        if not rs:
            continue
        ok_bic = np.mean([r["selected_bic"] == s["kind"] for r in rs])
        ok_aic = np.mean([r["selected_aic"] == s["kind"] for r in rs])
        picks: dict[str, int] = {}
        for r in rs:
            picks[r["selected_bic"]] = picks.get(r["selected_bic"], 0) + 1
        by_kind.setdefault(s["kind"], []).extend(r["selected_bic"] == s["kind"] for r in rs)
        label = s["kind"] + (f" (p_a {s['p_a']:g})" if s["kind"] in ("lfg", "noisy") else "")
        summary["selection"].append({**s, "datasets": len(rs), "bic_correct": ok_bic,
                                     "aic_correct": ok_aic, "picks": picks})
        sel_lines.append(f"| {label} | {s['role'] or '-'} | {s['noise']:g} | {len(rs)} | "
                         f"{100 * ok_bic:.0f} % | {100 * ok_aic:.0f} % | "
                         + ", ".join(f"{k} {v}" for k, v in sorted(picks.items())) + " |")
    kind_lines = ["| generating kind | datasets | selected by BIC |", "|---|---|---|"]
    for kind, oks in by_kind.items():
        kind_lines.append(f"| {kind} | {len(oks)} | {100 * np.mean(oks):.1f} % |")
        summary.setdefault("selection_by_kind", {})[kind] = {"datasets": len(oks),
                                                             "bic_correct": float(np.mean(oks))}
    fit_s = [r["seconds_fit"] for r in rows]
    text = "\n".join(["**Recovery of p_a** (lfg fits, 95 % profile-likelihood intervals)", "",
                      *rec_lines, "", "**Model selection** (all four kinds fitted, smallest "
                      "BIC)", "", *sel_lines, "", *kind_lines, "",
                      f"{len(rows)} datasets; fit time per dataset (all four models): median "
                      f"{np.median(fit_s):.2f} s" if fit_s else ""])
    return summary, text


def recovery(args) -> None:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    digest = code_digest()
    meta_path = out / "meta.json"
    meta = {"code": digest, "runs": args.runs}
    if meta_path.exists():
        old = json.loads(meta_path.read_text())
        if old != meta:
            sys.exit(f"error: {out} holds results of other code or settings ({old}); use "
                     "another --out")
    else:
        meta_path.write_text(json.dumps(meta) + "\n")
    results = out / "results.jsonl"
    done = {}
    if results.exists():
        for line in results.read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                done[row["key"]] = row
    chosen = [s for s in settings() if _matches(s, args.only)]
    tasks = [(s, d) for d in range(args.datasets) for s in chosen if key(s, d) not in done]
    print(f"{len(done)} datasets done, {len(tasks)} to go ({args.runs} runs each, "
          f"{args.workers} workers)", flush=True)
    t0 = time.perf_counter()
    if tasks:
        # spawned workers: they import this script (its run_task) afresh, never a fork of
        # this threaded process
        with ProcessPoolExecutor(args.workers, mp_context=get_context("spawn")) as pool, \
                open(results, "a") as fh:
            futures = [pool.submit(run_task, s, d, args.runs) for s, d in tasks]
            for i, fut in enumerate(as_completed(futures), 1):
                row = fut.result()
                fh.write(json.dumps(row) + "\n")
                fh.flush()
                done[row["key"]] = row
                if i % 20 == 0 or i == len(tasks):
                    el = time.perf_counter() - t0
                    print(f"  {i}/{len(tasks)} datasets in {el:.0f} s "
                          f"(about {el / i * (len(tasks) - i):.0f} s to go)", flush=True)
    rows = [done[key(s, d)] for d in range(args.datasets) for s in chosen
            if key(s, d) in done]
    summary, text = summarise(rows, args.datasets)
    summary.update({"datasets_per_setting": args.datasets, "runs_per_dataset": args.runs,
                    "code": digest})
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    (out / "summary.md").write_text(text + "\n")
    print(text)


def _matches(setting: dict, only: str | None) -> bool:
    """``--only KIND[:P_A]``: the settings of one kind (and one p_a)."""
    if not only:
        return True
    kind, _, p = only.partition(":")
    return setting["kind"] == kind and (not p or setting["p_a"] == float(p))


def timing(args) -> None:
    from persuasive import simulate
    from persuasive.fitting import evidence_of, fit_models, load_logs

    n = 1000
    cs = configs({"kind": "lfg", "p_a": 0.5, "role": "leader", "noise": 0.1})
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for j in range(n):
            path = Path(tmp) / f"run{j:04d}.parquet"
            simulate(cs[j % 2], 1 + j).save(path)
            paths.append(str(path))
        exe = Path(sys.executable).with_name("persuasive")
        wall, mem = [], []
        for _ in range(5):
            t0 = time.perf_counter()
            subprocess.run([str(exe), "fit", *paths, "--model", "lfg"], check=True,
                           stdout=subprocess.DEVNULL, env={**os.environ})
            wall.append(time.perf_counter() - t0)
            logs = load_logs(paths)
            t0 = time.perf_counter()
            rep = fit_models(evidence_of(logs), ["lfg"])
            mem.append(time.perf_counter() - t0)
        e = rep.fits["lfg"].params["p_a"]
        print(f"fit of {n} runs ({rep.evidence.n_steps} steps), lfg with 95 % intervals: "
              f"command end to end median {np.median(wall):.2f} s "
              f"(runs: {', '.join(f'{w:.2f}' for w in wall)}); in memory (evidence + fit) "
              f"median {np.median(mem):.2f} s ({', '.join(f'{m:.2f}' for m in mem)}); "
              f"p_a = {e.value:.3f} [{e.low:.3f}, {e.high:.3f}] (true 0.5); "
              f"{os.environ['NUMBA_NUM_THREADS']} threads")


def drive(args) -> None:
    files = sorted(Path(args.drive).glob("*.parquet"))
    if not files:
        print(f"no recorded trials in {args.drive}: nothing to fit")
        return
    exe = Path(sys.executable).with_name("persuasive")
    subprocess.run([str(exe), "fit", *map(str, files), "--per-participant"], check=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--datasets", type=int, default=100)
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="results/fit-recovery")
    ap.add_argument("--smoke", action="store_true", help="2 datasets of 10 runs per setting")
    ap.add_argument("--timing", action="store_true", help="only the 1000-run timing")
    ap.add_argument("--drive", default=None, help="fit the recorded trials in this folder")
    ap.add_argument("--only", default=None, metavar="KIND[:P_A]",
                    help="only the settings of one kind (and p_a), e.g. lfg:0.7")
    args = ap.parse_args()
    if args.smoke:
        args.datasets, args.runs = 2, 10
        args.out = args.out.rstrip("/") + "-smoke"
    if args.drive:
        drive(args)
        return
    if args.timing:
        os.environ["NUMBA_NUM_THREADS"] = "2"  # one fit may use both cores
        timing(args)
        return
    os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba loads: one thread per worker
    recovery(args)


if __name__ == "__main__":
    main()
