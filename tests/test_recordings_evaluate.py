"""The held-out evaluation on recorded pairs (persuasive.recordings.evaluate, scores,
baselines) and ``persuasive fit PAIRS.parquet``: scores by hand, splits by file, the bootstrap
over files, no look at the future, the CLI and its bad input (one line, exit 2, nothing
written)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pyarrow.parquet as pq
import pytest

from _cli import run_cli as run
from persuasive import Config, simulate
from persuasive.recordings.baselines import arrival_ca, arrival_cv, right_of_way, sumo_rule
from persuasive.recordings.evaluate import (DECIDED, ENDS, KEPT, NEVER_NEAR, EvalParams,
                                            PairData, Split, ViewBuilder, combine, evaluate,
                                            features_of, fold_tests,
                                            prediction_moment, read_sites, role_posteriors,
                                            vehicle_limits)
from persuasive.recordings.export import export_runs
from persuasive.recordings.formats import RecordingError, read_tracks
from persuasive.recordings.pairs import find_pairs, write_pairs
from persuasive.recordings.scores import (accuracy, auc, bootstrap, brier, cluster_weights,
                                          ece, log_loss)
from persuasive.recordings.tracks import smooth_tracks

N_FILES = 6


@pytest.fixture(scope="module")
def pairs_file(tmp_path_factory):
    """Six simulated crossings (two LFG players, the roles swapped every other seed, so that
    either vehicle passes first), one INTERACTION file each, paired."""
    folder = tmp_path_factory.mktemp("pairs")
    runs = []
    for seed in range(1, N_FILES + 1):
        lead = seed % 2 == 1
        config = Config(mode="corrected").with_overrides({
            "scenario.kind": "crossing", "scenario.angle_deg": 90.0,
            "simulation.n_steps": 70, "av.kind": "lfg",
            "hv.role": "leader" if lead else "follower",
            "av.role": "follower" if lead else "leader"})
        path = folder / f"run{seed}.parquet"
        simulate(config, seed).save(path)
        runs.append(path)
    tracks = folder / "tracks"
    tracks.mkdir()
    export_runs(runs, tracks, noise_m=0.05, seed=0)
    result = find_pairs(smooth_tracks(read_tracks([tracks])))
    assert len(result.pairs) == N_FILES
    target = folder / "pairs.parquet"
    write_pairs(target, result, [str(tracks)])
    return target


@pytest.fixture(scope="module")
def evaluation(pairs_file):
    return evaluate(read_sites([pairs_file]), Split("folds", k=3),
                    params=EvalParams(n_boot=200))




# -- scores by hand (exact up to float rounding: 1e-12) ---------------------------------------

def test_scores_against_hand_computed_values():
    y = np.array([1, 0, 1, 0])
    p = np.array([0.9, 0.2, 0.4, 0.4])
    # AUC: positive-negative pairs 0.9>0.2, 0.9>0.4, 0.4>0.2, and a tie 0.4=0.4 (half)
    assert auc(y, p) == pytest.approx(3.5 / 4, abs=1e-12)
    assert brier(y, p) == pytest.approx((0.01 + 0.04 + 0.36 + 0.16) / 4, abs=1e-12)
    want = -(math.log(0.9) + math.log(0.8) + math.log(0.4) + math.log(0.6)) / 4
    assert log_loss(y, p) == pytest.approx(want, abs=1e-12)
    assert accuracy(y, p) == 0.75
    assert accuracy([1, 0], [0.5, 0.5]) == 0.5  # an even call counts half
    # calibration bins: 0.9 (|1 - 0.9|), 0.2 (|0 - 0.2|), the two 0.4 (|0.5 - 0.4|, twice)
    assert ece(y, p) == pytest.approx((0.1 + 0.2 + 2 * 0.1) / 4, abs=1e-12)
    assert math.isnan(auc([1, 1], [0.2, 0.7]))  # one class: undefined
    # the predictions are clipped at 1e-3 for the log-loss
    assert log_loss([1], [0.0]) == pytest.approx(-math.log(1e-3), abs=1e-12)
    # weights count a pair that many times (a bootstrap resample)
    w = np.array([2.0, 1.0, 0.0, 3.0])
    rep = np.repeat(np.arange(4), w.astype(int))
    for fn in (auc, brier, log_loss, accuracy, ece):
        assert fn(y, p, w) == pytest.approx(fn(y[rep], p[rep]), abs=1e-12)


def test_two_views_combine_into_one_order():
    # both sure of the same role: no information; one sure to lead, the other to follow
    np.testing.assert_allclose(combine([1.0, 1.0, 0.5, 0.8], [1.0, 0.0, 0.5, 0.2]),
                               [0.5, 1.0, 0.5, 0.64 / (0.64 + 0.04)], atol=1e-12)


# -- the bootstrap resamples files ------------------------------------------------------------

def test_bootstrap_resamples_whole_files_and_is_wider_than_over_pairs():
    files = np.repeat([f"f{i}" for i in range(10)], 20)  # 10 files of 20 pairs
    w = cluster_weights(files, 300, seed=0)
    assert w.shape == (300, 200)
    # every pair of a file is drawn as often as its file; a resample draws 10 files
    assert np.all(w.reshape(300, 10, 20) == w.reshape(300, 10, 20)[:, :, :1])
    np.testing.assert_array_equal(w.sum(axis=1), 200)
    assert np.array_equal(w, cluster_weights(files, 300, seed=0))  # seeded
    # pairs of one file share their outcome and their prediction (fully correlated)
    rng = np.random.default_rng(1)
    y_file, p_file = rng.integers(0, 2, 10), rng.uniform(0.2, 0.8, 10)
    y, p = np.repeat(y_file, 20), np.repeat(p_file, 20)
    by_file = bootstrap(lambda ww: brier(y, p, ww), w)
    by_pair = bootstrap(lambda ww: brier(y, p, ww), cluster_weights(np.arange(200), 300, 0))
    assert by_file.value == by_pair.value
    assert by_file.high - by_file.low > 2 * (by_pair.high - by_pair.low)


# -- splits by file ---------------------------------------------------------------------------

def test_splits_never_put_one_file_on_both_sides(evaluation):
    files = [f"r{i}" for i in range(7)]
    sites = {f: "a" for f in files}
    tests = fold_tests(files, Split("folds", k=3), sites, seed=4)
    assert sorted(f for t in tests for f in t) == files  # each file tested exactly once
    assert [len(t) for t in tests] == [3, 2, 2]
    assert fold_tests(files, Split("holdout", fraction=0.3), sites, 4)[0].__len__() == 2
    assert fold_tests(files, Split("holdout", fraction=0.01), sites, 4)[0].__len__() == 1
    assert fold_tests(files, Split("holdout", fraction=0.99), sites, 4)[0].__len__() == 6
    sites2 = {f: ("a" if i < 4 else "b") for i, f in enumerate(files)}
    assert fold_tests(files, Split("site", test_site="b"), sites2, 0) == [files[4:]]
    for split, words in ((Split("folds", k=8), "--folds = 8"),
                         (Split("site", test_site="c"), "not a site")):
        with pytest.raises(RecordingError, match=words):
            fold_tests(files, split, sites2, 0)
    with pytest.raises(RecordingError, match="at least 2"):
        fold_tests(files[:1], Split("folds", k=2), sites, 0)
    # the evaluation: each fold's predicted pairs come from its test files only
    pairs = evaluation.pairs
    tested = [f for fold in evaluation.folds for f in fold.test_files]
    assert sorted(tested) == sorted({p.file for p in pairs}) and len(tested) == N_FILES
    for fold in evaluation.folds:
        assert {pairs[i].file for i in fold.pair_index} <= set(fold.test_files)
        assert set(fold.run_files) == set(fold.test_files)


# -- the moment, and nothing seen after it ----------------------------------------------------

def _pair(s1, s2, first="1", occ=((-3.0, 3.0), (-3.0, 3.0))):
    n = len(s1)
    t = np.round(np.arange(n) * 0.1, 1)
    s = np.array([s1, s2], float)
    t_pass = tuple(float(np.interp(0.0, row, t)) if row[-1] >= 0 > row[0] else math.nan
                   for row in s)
    v = np.gradient(s, 0.1, axis=1)
    return PairData("site", "f", 0, "crossing", 90.0, ("car", "car"), (4.5, 4.5), (1.8, 1.8),
                    np.array(occ, float), first, 1.0, t_pass, t, s, v, np.zeros_like(s),
                    np.array([s1, np.zeros(n)]), np.array([np.zeros(n), s2]))


def test_the_prediction_moment_by_hand():
    params = EvalParams()
    # both within 40 m from step 10 (vehicle 2 at -40 m), the moment 1 s later, seen 0.5 s
    s1 = np.linspace(-30.0, 10.0, 81)  # 5 m/s
    s2 = np.linspace(-45.0, 3.0, 81)  # 6 m/s: -40 m at step 8.33 -> step 9
    status, k, seen = prediction_moment(_pair(s1, s2), params)
    assert (status, k, seen) == (KEPT, 19, 14)
    assert prediction_moment(_pair(s1, s2 - 100.0), params)[0] == NEVER_NEAR
    assert prediction_moment(_pair(s1[:19], s2[:19]), params)[0] == ENDS
    # vehicle 1 inside its occupancy interval at the moment: decided
    assert prediction_moment(_pair(s1 + 20.0, s2), params)[0] == DECIDED


def test_nothing_after_the_moment_is_seen(evaluation):
    pairs, status = evaluation.pairs, evaluation.status
    kept = [(p, st) for p, st in zip(pairs, status) if st[0] == KEPT]
    assert len(kept) == N_FILES
    for p, (_, k, seen) in kept:
        # the moment comes before both first arrivals, and what is seen before the moment
        assert p.t[k] < min(t for t in p.t_pass_s if math.isfinite(t))
        assert seen == k - 5
    # the baselines' features and the models' role posteriors read no step after `seen`
    p, (_, k, seen) = kept[0]
    late = replace(p, s=p.s.copy(), v=p.v.copy(), a=p.a.copy(), x=p.x.copy(), y=p.y.copy())
    for arr in (late.s, late.v, late.a, late.x, late.y):
        arr[:, seen + 1:] += 7.0
    f0, f1 = features_of([p], [seen]), features_of([late], [seen])
    for name in ("s", "v", "a", "direction"):
        np.testing.assert_array_equal(getattr(f0, name), getattr(f1, name))
    from persuasive.fitting import evidence_of

    builder = ViewBuilder("corrected", vehicle_limits([p], 0.01), 12.0)
    ev = evidence_of([builder.view(q, h) for q in (p, late) for h in (1, 2)])
    fit = SimpleNamespace(model="lfg", theta={"p_a": 0.3, "pi0": 0.6, "sigma": 0.4,
                                              "beta": math.inf})
    post = role_posteriors(ev, fit, np.array([seen] * 4))
    np.testing.assert_array_equal(post[:2], post[2:])


def test_the_baselines_by_hand():
    from persuasive.recordings.baselines import Features

    f = Features(s=np.array([[-20.0, -10.0], [-10.0, -20.0]]), v=np.array([[10.0, 2.0],
                                                                          [5.0, 10.0]]),
                 a=np.array([[0.0, -1.0], [2.0, 0.0]]),
                 direction=np.array([[math.pi, math.pi / 2], [0.0, math.pi / 2]]),
                 occ_lo=np.full((2, 2), -3.0), occ_hi=np.full((2, 2), 3.0),
                 merge=np.array([False, False]))
    np.testing.assert_allclose(arrival_cv(f), [[2.0, 5.0], [2.0, 2.0]])
    # 2 m/s braking at 1 m/s^2 stops after 2 m: never arrives; 5 m/s at 2 m/s^2: 10 = 5t + t^2
    ca = arrival_ca(f)
    assert ca[0, 0] == 2.0 and math.isinf(ca[0, 1])
    assert ca[1, 0] == pytest.approx((-5 + math.sqrt(65)) / 2, abs=1e-12)
    # pair 0: vehicle 1 heads west, vehicle 2 north: 1 comes from 2's right; pair 1: east
    np.testing.assert_array_equal(right_of_way(f), [1, 0])
    # pair 1: vehicle 1 is the minor one; it leaves (13 / 5 = 2.6 s) less than 1 s before
    # vehicle 2 enters (17 / 10 = 1.7 s): vehicle 2 goes first. Pair 0: the major goes first.
    np.testing.assert_array_equal(sumo_rule(f), [1, 0])


# -- the evaluation and the CLI ---------------------------------------------------------------

def test_the_evaluation_reports_every_model_and_baseline(evaluation):
    d = evaluation.to_dict()
    names = [r["name"] for r in d["rows"]]
    assert names == ["lfg", "stubborn", "noisy", "idm", "majority", "arrive_cv", "arrive_ca",
                     "logistic_gap", "right_of_way", "sumo_rule", "role_belief"]
    assert d["pairs"] == {"total": N_FILES, "kept": N_FILES,
                          "left_out": {NEVER_NEAR: 0, ENDS: 0, DECIDED: 0,
                                       "no first passer (neither, same time)": 0}}
    for r in d["rows"]:
        assert 0.0 <= r["brier"]["value"] <= 1.0
        lo, hi = r["log_loss"]["ci95"]
        assert lo <= r["log_loss"]["value"] <= hi
        assert ("loglik_per_step" in r) == (r["kind"] == "model"
                                           or r["name"] in ("arrive_cv", "arrive_ca"))
        assert (r.get("strongest_baseline") == d["strongest_baseline"]) == (r["kind"] == "model")
    assert d["strongest_baseline"] in names[4:]
    lim = d["limits"]
    assert len(lim["per_fold"]) == 3 and 0.0 <= lim["share_beyond_fitted"] <= 0.05
    car = lim["per_fold"][0]["accel_mps2"]["car"]
    assert car[0] < 0 < car[1]
    json.dumps(d, allow_nan=False)


def test_fit_evaluates_a_pairs_file_held_out(capsys, pairs_file, tmp_path):
    code, out, err = run(capsys, "fit", pairs_file, "--holdout", "0.34", "--model", "lfg",
                         "--quiet")
    assert code == 0 and err == ""
    assert "0.34 of the recording files held out (seed 0); 6 recording files, 6 pairs" in out
    assert "| predictor | log-lik/step | accuracy | AUC | Brier | log-loss | ECE | vs " in out
    assert "| lfg | " in out and "| logistic_gap (baseline) | " in out
    assert "strongest baseline (smallest log-loss): " in out
    report = tmp_path / "report.json"
    code, out, err = run(capsys, "fit", pairs_file, "--folds", "2", "--model", "stubborn",
                         "--json", "--out", report, "--seed", "3", "--quiet")
    assert code == 0 and err == ""
    payload = json.loads(out)
    assert json.loads(report.read_text()) == {**payload, "seconds": payload["seconds"]}
    assert payload["split"]["k"] == 2 and payload["split"]["seed"] == 3
    assert [r["name"] for r in payload["rows"]][0] == "stubborn"
    # the folds on two worker processes: the same report, a progress bar over the folds
    code, out, err = run(capsys, "fit", pairs_file, "--folds", "2", "--model", "stubborn",
                         "--json", "--seed", "3", "--workers", "2")
    assert code == 0 and "2/2" in err and "fold" in err, err
    two = json.loads(out)
    assert {**two, "seconds": 0} == {**payload, "seconds": 0}
    code, _, err = run(capsys, "fit", pairs_file, "--workers", "0")
    assert code == 2 and "--workers" in err


def test_bad_input_ends_in_one_line_and_exit_2_writing_nothing(capsys, pairs_file, tmp_path):
    one = tmp_path / "one.parquet"  # the pairs of a single recording file
    table = pq.read_table(pairs_file)
    keep = np.asarray(table.column("recording").to_pylist()) == "vehicle_tracks_000"
    pq.write_table(table.filter(keep), one)
    log = tmp_path / "run.parquet"
    simulate(Config(mode="corrected").with_overrides({"simulation.n_steps": 5}), 1).save(log)
    target = tmp_path / "r.json"
    cases = [
        (("--holdout", "0"), "--holdout = 0 is out of range"),
        (("--holdout", "1.5"), "--holdout = 1.5 is out of range"),
        (("--folds", "1"), "--folds = 1 is out of range"),
        (("--folds", "9"), "--folds = 9 is out of range"),
        (("--folds", "2", "--holdout", "0.5"), "give one"),
        (("--test-site", "x"), "needs several pairs files"),
        (("--per-participant",), "--per-participant does not apply"),
        (("--intervals", "none"), "--intervals does not apply"),
    ]
    for extra, words in cases:
        code, out, err = run(capsys, "fit", pairs_file, *extra, "--out", target)
        assert code == 2 and out == "" and err.count("\n") == 1, (extra, err)
        assert err.startswith("error: ") and words in err, (extra, err)
    for args, words in (((one,), "1 recording file"),
                        ((pairs_file, log), "is not a pairs file"),
                        ((log, "--holdout", "0.3"), "--holdout applies to pairs files"),
                        ((pairs_file, pairs_file), "is the same file"),
                        ((pairs_file, "--out", tmp_path / "r.parquet"), "unsupported extension")):
        code, out, err = run(capsys, "fit", *args, *(() if "--out" in args else
                                                      ("--out", target)))
        assert code == 2 and out == "" and err.count("\n") == 1, (args, err)
        assert words in err, (args, err)
    assert not target.exists() and not (tmp_path / "r.parquet").exists()


# -- reading, selecting and splitting the work (issue 42: a site's pairs in minutes) ----------

def _pairs_of_by_groups(frame, site, prefix):
    """The reading of a pairs frame before it was vectorised (a groupby, one pair at a time):
    the reference the fast :func:`pairs_of` must equal field for field."""
    out = []
    for pair_id, rows in frame.groupby("pair", sort=True):
        rows = rows.sort_values("step", kind="stable")
        r0 = rows.iloc[0]

        def both(q, unit):
            return np.stack([rows[f"{q}_1_{unit}"].to_numpy(float),
                             rows[f"{q}_2_{unit}"].to_numpy(float)])

        rec = str(r0["recording"]).split("/case", 1)[0]
        out.append(PairData(
            site=site, file=f"{site}/{rec}" if prefix else rec, pair=int(pair_id),
            kind=str(r0["kind"]), angle_deg=float(r0["angle_deg"]),
            classes=(str(r0["class_1"]), str(r0["class_2"])),
            lengths_m=(float(r0["length_1_m"]), float(r0["length_2_m"])),
            widths_m=(float(r0["width_1_m"]), float(r0["width_2_m"])),
            occupancy=np.array([[r0["occupancy_1_lo_m"], r0["occupancy_1_hi_m"]],
                                [r0["occupancy_2_lo_m"], r0["occupancy_2_hi_m"]]], float),
            first=str(r0["first"]), pet_s=float(r0["pet_s"]),
            pet_area_s=float(r0["pet_area_s"]) if "pet_area_s" in rows else math.nan,
            t_pass_s=(float(r0["t_pass_1_s"]), float(r0["t_pass_2_s"])),
            t=rows["t_s"].to_numpy(float), s=both("s", "m"), v=both("v", "mps"),
            a=both("a", "mps2"), x=both("x", "m"), y=both("y", "m"),
            **({"control": str(r0["control"]), "priority": int(r0["priority"]),
                "stop_s": (float(r0["stop_1_m"]), float(r0["stop_2_m"]))}
               if "control" in rows else {})))
    return out


def _same_pairs(a, b):
    from dataclasses import fields

    assert len(a) == len(b)
    for p, q in zip(a, b):
        for f in fields(p):
            u, v = getattr(p, f.name), getattr(q, f.name)
            assert type(u) is type(v), f.name
            if isinstance(u, np.ndarray):
                assert u.shape == v.shape and np.array_equal(u, v, equal_nan=True), f.name
            else:  # NaN equals NaN here (a pair with no stop line, no PET)
                assert np.array_equal(np.asarray(u, object), np.asarray(v, object)) or \
                    np.array_equal(u, v, equal_nan=True), (f.name, u, v)


def test_pairs_are_read_as_the_groupby_read_them(pairs_file):
    """The vectorised reading equals the pair-by-pair one on every field, whatever the order of
    the rows in the file, and the columns read are read_pairs' own values."""
    from persuasive.recordings.evaluate import pairs_of, read_pair_data
    from persuasive.recordings.pairs import read_pairs

    whole, _ = read_pairs(pairs_file)
    want = _pairs_of_by_groups(whole, "s", False)
    _same_pairs(pairs_of(whole, "s", False), want)
    ((name, frame),) = read_sites([pairs_file])
    _same_pairs(pairs_of(frame, "s", False), want)
    shuffled = whole.sample(frac=1.0, random_state=np.random.default_rng(1).integers(1 << 30))
    _same_pairs(pairs_of(shuffled, "s", False), want)
    _same_pairs(pairs_of(frame, "site", True), _pairs_of_by_groups(whole, "site", True))
    _same_pairs(read_pair_data([pairs_file]), _pairs_of_by_groups(whole, name, False))
    assert pairs_of(whole.iloc[:0], "s", False) == []


def test_each_runs_evidence_is_its_own(evaluation):
    """The folds solve the training and the test views apart: a run's evidence does not
    depend on the runs solved with it (every array, bit for bit)."""
    from persuasive.fitting import evidence_of

    builder = ViewBuilder("corrected", vehicle_limits(evaluation.pairs, 0.01), 12.0)
    views = [builder.view(p, h) for p in evaluation.pairs for h in (1, 2)]
    whole = evidence_of(views)
    for part in (range(0, 5), range(5, len(views))):
        alone, sub = evidence_of([views[i] for i in part]), whole.subset(part)
        for name in ("starts", "accel", "a_role", "pl", "belief", "q", "a_first", "states",
                     "P_hv", "P_av", "dt"):
            assert np.array_equal(getattr(alone, name), getattr(sub, name)), name


def test_pairs_are_selected_by_their_pet_at_the_conflict_area(evaluation):
    from persuasive.recordings.evaluate import NO_PET, PET_ABOVE, select_pairs

    pairs = [replace(p, pet_area_s=x) for p, x in
             zip(evaluation.pairs, [0.5, 5.0, 5.0001, math.nan, 30.0, 0.0])]
    kept, left = select_pairs(pairs, 5.0)
    assert [p.pet_area_s for p in kept] == [0.5, 5.0, 0.0]
    assert left == {PET_ABOVE: 2, NO_PET: 1}
    kept, left = select_pairs(pairs, math.inf)  # every pair, those without a PET too
    assert len(kept) == len(pairs) and left == {PET_ABOVE: 0, NO_PET: 0}
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(RecordingError, match="pet_max_s"):
            EvalParams(pet_max_s=bad)


def test_the_evaluation_is_that_of_the_pairs_read_one_by_one(pairs_file, evaluation):
    """The whole evaluation (every fold, score, interval and fitted parameter) from the
    reference reading of the pairs equals the one from the fast reading, and every pair of
    the fixture is evaluated under the default --pet-max."""
    from persuasive.recordings.evaluate import PET_MAX_S, evaluate_pairs
    from persuasive.recordings.pairs import read_pairs

    whole, _ = read_pairs(pairs_file)
    ref = evaluate_pairs(_pairs_of_by_groups(whole, "pairs", False), Split("folds", k=3),
                         params=EvalParams(n_boot=200))
    assert ref.to_dict() == evaluation.to_dict()
    sel = evaluation.to_dict()["selection"]
    assert sel["pet_max_s"] == PET_MAX_S and sel["read"] == sel["selected"] == N_FILES
    every = evaluate_pairs(evaluation.pairs, Split("folds", k=3),
                           params=EvalParams(n_boot=200, pet_max_s=math.inf)).to_dict()
    assert every["selection"]["pet_max_s"] == "inf"
    assert {**every, "selection": None} == {**evaluation.to_dict(), "selection": None}


def test_fit_names_the_pairs_it_leaves_out(capsys, pairs_file, tmp_path):
    from persuasive.recordings.evaluate import PET_MAX_S

    pets = sorted(p.pet_area_s for p in read_pair_data_of(pairs_file))
    cut = 0.5 * (pets[1] + pets[2])  # two of the six pairs at most
    code, out, err = run(capsys, "fit", pairs_file, "--folds", "2", "--model", "stubborn",
                         "--quiet", "--pet-max", f"{cut!r}", "--json")
    if code == 0:
        d = json.loads(out)
        assert d["selection"]["selected"] == 2 and d["pairs"]["total"] == 2
        assert d["selection"]["left_out"] == {"PET at the conflict area above pet_max_s": 4,
                                              "no PET at the conflict area": 0}
    else:  # the two pairs in one file: a split needs two
        assert code == 2 and "recording file" in err
    code, out, err = run(capsys, "fit", pairs_file, "--holdout", "0.34", "--model", "lfg",
                         "--quiet")
    assert code == 0 and f"pairs evaluated: 6 of 6, those with a PET at the conflict area " \
        f"(pet_area_s) of at most {PET_MAX_S:g} s (--pet-max)" in out
    code, out, err = run(capsys, "fit", "--help")
    assert f"[{PET_MAX_S:g}]" in " ".join(out.split())
    for bad in ("0", "-2", "nan"):
        code, out, err = run(capsys, "fit", pairs_file, "--pet-max", bad)
        assert code == 2 and out == "" and err.count("\n") == 1, (bad, err)
        assert f"--pet-max = {float(bad):g} is out of range; allowed: (0, inf] s" in err
    code, out, err = run(capsys, "fit", pairs_file, "--pet-max", "1e-6", "--quiet")
    assert code == 2 and err.count("\n") == 1 and "--pet-max" in err, err


def read_pair_data_of(path):
    from persuasive.recordings.evaluate import read_pair_data

    return read_pair_data([path])


def test_the_rollout_reads_the_views_packed_parameters_as_built(evaluation):
    """The IDM rollout on the parameter vectors an evidence packed equals the one that builds
    them from the views' configurations."""
    from persuasive.config import Config
    from persuasive.fitting import evidence_of
    from persuasive.fitting.models import IDM_NAMES
    from persuasive.recordings.evaluate import idm_rollout

    idm = Config().hv.idm
    prm = np.array([getattr(idm, name) for name in IDM_NAMES], float)
    builder = ViewBuilder("corrected", vehicle_limits(evaluation.pairs, 0.01), 12.0)
    for p, st in zip(evaluation.pairs, evaluation.status):
        if st[0] != KEPT:
            continue
        views = [builder.view(p, 1), builder.view(p, 2)]
        ev = evidence_of(views)
        packed = (ev.P_av[0], ev.P_hv[0], ev.P_av[1], ev.P_hv[1])
        assert idm_rollout(p, st[2], *views, prm, packed) == idm_rollout(p, st[2], *views, prm)


def test_the_geometries_built_once_are_those_each_fold_builds(evaluation, monkeypatch):
    """Every view's scenario geometry is built once before the folds (``view_geometries``):
    under another fold's limits it gives the scenario a build gives, and the evaluation
    with every scenario built anew (no cache) is the same, key for key."""
    import persuasive.record as record
    from persuasive.recordings.evaluate import evaluate_pairs, view_geometries
    from persuasive.scenarios import build_scenario

    pairs = evaluation.pairs
    views = [(i, h) for i in range(len(pairs)) for h in (1, 2)]
    entries = dict(view_geometries(pairs, "corrected", views, vehicle_limits(pairs, 0.01),
                                   12.0))
    assert set(entries) == {record.geometry_key(ViewBuilder("corrected", vehicle_limits(
        pairs, 0.01), 12.0).config(pairs[i], h)) for i, h in views}
    other = ViewBuilder("corrected", vehicle_limits(pairs[:2], 0.05), 15.0)
    for i, h in views:
        config = other.config(pairs[i], h)
        kept = record.with_geometry(entries[record.geometry_key(config)], config)
        assert kept == build_scenario(config)
    monkeypatch.setattr(record, "scenario_of", lambda config, cache=None: build_scenario(
        config))
    record.static_setup.cache_clear()
    try:
        anew = evaluate_pairs(pairs, Split("folds", k=3), params=EvalParams(n_boot=200))
    finally:
        record.static_setup.cache_clear()
    assert anew.to_dict() == evaluation.to_dict()
