"""The paper's tables: Table 1 in full against the published numbers, Table 2 against pinned
per-seed outcomes of a validated full run, determinism across worker counts, the results store.

Table 2's full 14,000 runs are a command (``persuasive reproduce table2``), not a test; the
pinned seeds (``tests/data/table2_pinned.json``, written by ``benchmarks/pin_table2.py`` only
from a full run that equals the paper) include HV-first runs, runs with infeasible MPC steps
and runs that pass closer than the safe distance after the line, for every row.
"""

import json
from pathlib import Path

import pandas as pd
import pytest

from persuasive import experiments as ex
from persuasive.config import Config, ConfigError
from persuasive.simulation import simulate

PINNED = json.loads((Path(__file__).parent / "data" / "table2_pinned.json").read_text())


@pytest.mark.slow
def test_table1_reproduces_the_published_numbers_exactly():
    result = ex.reproduce("table1", seeds=1000, workers=2)
    summary = result.summaries["table1"]
    assert ex.matches_published(summary)
    for row in summary["rows"]:
        assert row["runs"] == 1000
        assert row["collisions"] == 0
        assert row["av_first"] + row["hv_first"] + row["same_step"] + row["neither"] == 1000
    # the published shares, spelled out: HV starts L -> HV always first; HV starts F -> 97.9 %
    assert [(r["av_first"], r["hv_first"]) for r in summary["rows"]] == [(0, 1000), (979, 21)]


@pytest.mark.parametrize("row", PINNED["rows"], ids=lambda r: f"row{r['row']}")
def test_table2_pinned_seeds(row):
    spec = ex.PUBLISHED["table2"][row["row"]]
    assert (spec.hv_role, spec.pa, spec.pa_hat) == (row["hv_role"], row["pa"], row["pa_hat"])
    config = spec.config(Config())
    assert spec.av == config.av.kind == "persuasive"
    for seed, expected in row["runs"].items():
        o = simulate(config, int(seed)).outcome
        got = {k: getattr(o, k) for k in expected}
        # integers and labels exactly; distances to 1e-9 m (libm may differ in the last bit)
        for key in ("min_distance_to_line_m", "min_distance_m"):
            assert got.pop(key) == pytest.approx(expected[key], abs=1e-9)
        assert got == {k: v for k, v in expected.items() if not k.startswith("min_")}, seed


def test_rows_name_their_agents():
    assert [r.av for r in ex.PUBLISHED["table1"]] == ["lfg", "lfg"]
    assert {r.av for r in ex.PUBLISHED["table2"]} == {"persuasive"}
    lfg = ex.PUBLISHED["table1"][1].config(Config(mode="corrected"))
    assert (lfg.mode, lfg.av.kind, lfg.hv.role, lfg.roles.p_a) == ("corrected", "lfg",
                                                                    "follower", 1.0)
    row = ex.PUBLISHED["table2"][2]
    mpc = row.config(Config())
    assert (mpc.av.kind, mpc.hv.role, mpc.roles.p_a, mpc.p_a_hat) == (
        "persuasive", row.hv_role, row.pa, row.pa_hat)


def test_pinned_seeds_cover_every_kind_of_run():
    runs = [r for row in PINNED["rows"] for r in row["runs"].values()]
    assert len(PINNED["rows"]) == 14
    assert any(r["first_at_line"] == 2 for r in runs)
    assert any(r["infeasible_steps"] > 0 for r in runs)
    assert any(r["min_distance_m"] < 7.5 <= r["min_distance_to_line_m"] for r in runs)


def test_worker_count_does_not_change_results():
    one = ex.run_tables(["table2"], seeds=4, workers=1)
    two = ex.run_tables(["table2"], seeds=4, workers=2)
    assert one == two
    assert [(r["row"], r["seed"]) for r in one] == [(i, s) for i in range(14) for s in range(1, 5)]


def test_reproduce_rows_equal_simulate_summaries():
    runs = ex.run_tables(["table1", "table2"], seeds=2, workers=1)
    for r in runs:
        spec = ex.PUBLISHED[r["table"]][r["row"]]
        s = simulate(spec.config(Config()), r["seed"]).summary()
        assert r["av"] == s["av"] == spec.av
        assert r["pa_hat"] == (None if spec.av == "lfg" else s["pa_hat"])
        for key in ("first_at_line", "first_at_conflict_point", "collision", "idx_end",
                    "min_distance_to_line_m", "min_distance_m", "infeasible_steps",
                    "hv_role_changes", "av_role_changes"):
            assert r[key] == s[key], key
        assert [r["hv_s0_m"], r["hv_v0_mps"]] == s["hv_initial_state"]


def test_summary_counts_and_markdown():
    runs = ex.run_tables(["table2"], seeds=3, workers=1, mode="corrected")
    summary = ex.summarize(runs, "table2")
    assert summary["mode"] == "corrected" and summary["seeds"] == 3
    assert len(summary["rows"]) == 14
    for row, spec in zip(summary["rows"], ex.PUBLISHED["table2"]):
        assert row["runs"] == 3
        assert row["av_first"] + row["hv_first"] + row["same_step"] + row["neither"] == 3
        assert row["av_first_pct"] == pytest.approx(100 * row["av_first"] / 3)
        assert row["published_hv_first_pct"] == spec.published_hv_first_pct
    md = ex.to_markdown(summary)
    assert md.count("\n| ") == 15  # header + 14 rows
    assert "corrected mode" in md


def test_seeds_other_than_the_published_are_not_compared():
    runs = ex.run_tables(["table1"], seeds=3, workers=1)
    short = ex.summarize(runs, "table1")  # seeds 1..3
    assert short["seeds"] == 3
    assert [(r["diff_av_first_pct"], r["diff_hv_first_pct"]) for r in short["rows"]] == \
        [(None, None)] * 2
    assert [r["published_av_first_pct"] for r in short["rows"]] == [0.0, 97.9]
    md = ex.to_markdown(short)
    assert "published" not in md and "diff" not in md
    assert "| L | 1.00 | 0.0 | 100.0 | 0 | 0 |" in md
    assert "so they are not compared" in ex.verdict(short, Config())
    full = ex.summarize(runs, "table1", seeds=1000)  # as if they were seeds 1..1000
    assert "| AV first % | HV first % | published AV/HV % | diff AV/HV |" in \
        ex.to_markdown(full)
    row = full["rows"][1]
    assert row["diff_av_first_pct"] == pytest.approx(row["av_first_pct"] - 97.9, abs=1e-9)


def test_violations_use_each_runs_own_safety_distance():
    runs = ex.run_tables(["table1"], seeds=2, workers=1)
    assert {r["safety_distance_m"] for r in runs} == {7.5}
    closest = min(r["min_distance_m"] for r in runs)
    for r in runs:  # a run whose own safe distance is larger than its closest approach
        r["safety_distance_m"] = closest + 1.0 if r is runs[0] else r["safety_distance_m"]
    summary = ex.summarize(runs, "table1")
    assert sum(row["violations_whole_run"] for row in summary["rows"]) == \
        int(runs[0]["min_distance_m"] < closest + 1.0) + \
        sum(r["min_distance_m"] < 7.5 for r in runs[1:])


def test_each_run_carries_the_safety_distance_it_was_run_with():
    # the HV 4 m long: the scenario (and every kernel) uses 1.5 (5 + 4) / 2 = 6.75 m
    config = ex.PUBLISHED["table2"][0].config(Config().with_overrides(
        {"hv.vehicle.length_m": 4.0}))
    assert simulate(config, 1).scenario.min_dist_m == 6.75
    assert ex.run_record("table2", 0, config, 1)["safety_distance_m"] == 6.75


def test_save_writes_the_folder_as_a_set(tmp_path, monkeypatch):
    target = tmp_path / "results"
    result = ex.reproduce("table1", seeds=3, workers=1)
    ex.save(result, "table1", target)
    runs = pd.read_parquet(target / "runs.parquet")
    assert list(runs.columns) == list(ex.RUN_COLUMNS) and len(runs) == 6
    assert json.loads((target / "summary.json").read_text()) == result.summaries["table1"]
    assert Config.from_toml(target / "config.toml") == Config()
    # a second run (with force, the default) replaces the folder
    ex.save(ex.reproduce("table1", seeds=5, workers=1), "table1", target)
    assert len(pd.read_parquet(target / "runs.parquet")) == 10
    ex.save(result, "table1", target)
    assert len(pd.read_parquet(target / "runs.parquet")) == 6

    # a write that fails half-way leaves the previous folder whole, every file of it, and no
    # temporary file or folder behind
    def broken(self, path, **kw):
        Path(path).write_bytes(b"partial")
        raise OSError(28, "No space left on device")

    before = {p.name: p.read_bytes() for p in target.iterdir()}
    monkeypatch.setattr(pd.DataFrame, "to_parquet", broken)
    with pytest.raises(ConfigError, match="cannot be written: no space left on device"):
        ex.save(result, "table1", target)
    assert {p.name: p.read_bytes() for p in target.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results"]


def test_save_without_force_refuses_only_other_settings(tmp_path):
    target = tmp_path / "results"
    result = ex.reproduce("table1", seeds=3, workers=1)
    ex.save(result, "table1", target)
    # the same settings again: accepted without force
    ex.save(ex.reproduce("table1", seeds=3, workers=1), "table1", target, force=False)
    # other settings are refused without force, and the folder is untouched
    bigger = ex.reproduce("table1", seeds=5, workers=1)
    with pytest.raises(ConfigError, match="other settings"):
        ex.save(bigger, "table1", target, force=False)
    assert len(pd.read_parquet(target / "runs.parquet")) == 6
    # ... and so is a reproduction's own sweep folder
    sweep_folder = tmp_path / "sweep"
    ex.reproduce("table1", seeds=3, workers=1, out=sweep_folder)
    with pytest.raises(ConfigError, match="other settings"):
        ex.save(bigger, "table1", sweep_folder, force=False)


def test_reproduce_into_a_folder_keeps_the_sweep_and_its_summary(tmp_path):
    # with ``out``, the folder is the table's sweep (resumable); save adds the summary beside
    from persuasive import sweep

    folder = tmp_path / "t1"
    result = ex.reproduce("table1", seeds=3, workers=1, out=folder)
    assert result.folders == {"table1": folder}
    ex.save(result, "table1", folder)
    assert {"manifest.json", "runs", "summary.json", "summary.md", "config.toml"} <= {
        p.name for p in folder.iterdir()}
    assert json.loads((folder / "summary.json").read_text()) == result.summaries["table1"]
    assert len(sweep.load(folder)) == 6
    # the runs equal a reproduction without a folder, row for row
    plain = ex.reproduce("table1", seeds=3, workers=1)
    pd.testing.assert_frame_equal(result.runs, plain.runs)
    # the same call again finds every run done and gives the same summary
    again = ex.reproduce("table1", seeds=3, workers=1, out=folder)
    assert again.summaries == result.summaries


def test_a_failing_run_is_reported_and_the_others_kept():
    # seeds whose initial state cannot be drawn in one try fail (in the workers, which share
    # nothing with this process but the configuration); the others are kept, the same ones
    # whatever the number of workers
    base = Config().with_overrides({"scenario.hv_s0_halfwidth_m": 12,
                                    "scenario.max_init_draws": 1})
    seen = []
    for workers in (1, 2):
        failures = []
        runs = ex.run_tables(["table1"], seeds=6, workers=workers, chunk=2, base=base,
                             failures=failures)
        assert 0 < len(failures) < 12 and len(runs) + len(failures) == 12
        assert all(f.error.startswith("InitialStateError: ") for f in failures)
        assert failures[0].config_hash == ex.PUBLISHED["table1"][0].config(base).digest()
        seen.append(([(r["row"], r["seed"]) for r in runs],
                     [(f.table, f.row, f.seed) for f in failures]))
    assert seen[0] == seen[1]
    result = ex.reproduce("table1", seeds=6, workers=2, base=base)
    assert [(f.table, f.row, f.seed) for f in result.failures] == seen[0][1]
    assert [(r["row"], r["seed"]) for r in result.runs.to_dict("records")] == seen[0][0]
    assert ([f["seed"] for f in result.summaries["table1"]["failures"]]
            == [seed for _, _, seed in seen[0][1]])


def test_cli_reports_failed_runs_and_exits_1(monkeypatch, capsys, tmp_path):
    from persuasive import sweep
    from persuasive.cli import main

    # seeds whose initial state cannot be drawn in one try fail; the others are kept
    code = main(["reproduce", "table1", "--seeds", "6", "--workers", "1", "--quiet",
                 "--set", "scenario.hv_s0_halfwidth_m=12", "--set", "scenario.max_init_draws=1",
                 "--out", str(tmp_path / "r")])
    out, err = capsys.readouterr()
    assert code == 1
    assert "error: run failed: table1 row 0 seed" in err and "InitialStateError" in err
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    n_failed = len(summary["failures"])
    assert 0 < n_failed < 12
    assert len(sweep.load(tmp_path / "r")) == 12 - n_failed
    assert sum(row["runs"] for row in summary["rows"]) == 12 - n_failed


@pytest.mark.parametrize("kwargs, name", [
    ({"seeds": 0}, "seeds"), ({"workers": 0}, "workers"), ({"seeds": 2.5}, "seeds"),
    ({"chunk": 0}, "chunk"), ({"chunk": -3}, "chunk"),
    ({"seeds": 2**32}, r"seeds = 4294967296 is out of range; allowed: integer in \[1, "),
    ({"seeds": 500_001}, r"seeds = 500001 is out of range; allowed: 1..500000 for 2 rows"),
])
def test_bad_arguments(kwargs, name):
    with pytest.raises(ConfigError, match=name):
        ex.run_tables(["table1"], **{"seeds": 2, **kwargs})
    with pytest.raises(ConfigError, match="table"):
        ex.run_tables(["table3"], seeds=2)


def test_the_library_refuses_studies_too_large_to_summarise(tmp_path):
    with pytest.raises(ConfigError, match=r"seeds = 62501 is out of range; allowed: 1..62500 "
                                          r"for 16 rows \(at most 1000000 runs"):
        ex.reproduce("all", seeds=62501, out=tmp_path / "r")
    with pytest.raises(ConfigError, match=r"seeds = 2 is out of range; allowed: 1..1 for "):
        ex.check_seeds(2, ex.MAX_RUNS)
    from persuasive.studies.compare import comparison_grid

    with pytest.raises(ConfigError, match=r"seeds = 500001 is out of range; allowed: "
                                          r"1..500000 for 2 pairs"):
        comparison_grid(Config(), ["persuasive", "cv"], ["lfg"], 500_001)
    assert list(tmp_path.iterdir()) == []
