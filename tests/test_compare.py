"""``persuasive compare`` (``persuasive.studies.compare``): every pair on the same runs, the
summary's statistics, the command and its figure."""

from __future__ import annotations

import json

import numpy as np
import pytest

from persuasive import Config, ConfigError, simulate
from persuasive.cli import main
from persuasive.studies import compare as cmp


def run(capsys, *args):
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def test_parse_kinds():
    assert cmp.parse_kinds("persuasive, yield", ("persuasive", "yield", "cv"), "--av",
                           ()) == ("persuasive", "yield")
    assert cmp.parse_kinds("mpc", ("persuasive",), "--av", ()) == ("persuasive",)
    assert cmp.parse_kinds("all", ("a", "b"), "--av", ("a", "b")) == ("a", "b")
    assert cmp.parse_kinds(None, ("a", "b"), "--hv", ("a",)) == ("a",)
    with pytest.raises(ConfigError, match="--av = 'x' is out of range"):
        cmp.parse_kinds("persuasive,x", ("persuasive",), "--av", ())
    with pytest.raises(ConfigError, match="given twice"):
        cmp.parse_kinds("a,a", ("a",), "--av", ())


@pytest.fixture(scope="module")
def comparison(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cmp") / "c"
    return cmp.run_comparison(Config(), ("persuasive", "yield", "cv"), ("lfg", "aggressive"),
                              seeds=6, out=folder, workers=2, timing_seeds=1)


def test_every_pair_meets_the_same_humans(comparison):
    runs = comparison.runs
    assert len(runs) == 3 * 2 * 6 and comparison.failures == 0
    assert set(runs["streams"]) == {"per-agent"}  # forced for a paired comparison
    for hv, mine in runs.groupby("hv.kind"):
        starts = mine.groupby("seed")[["hv_initial_state.0", "hv_initial_state.1",
                                       "av_initial_state.0"]].nunique()
        assert (starts == 1).all().all(), hv  # one initial state per seed, whatever the AV


def test_rows_equal_the_runs_they_summarise(comparison):
    runs = comparison.runs
    for row in comparison.summary["rows"]:
        mine = runs[(runs["av.kind"] == row["av"]) & (runs["hv.kind"] == row["hv"])]
        first = mine["first_at_line"].to_numpy()
        assert row["runs"] == len(mine) == 6
        assert row["av_first_pct"] == pytest.approx(100 * np.mean(first == 1))
        assert row["collisions"] == int(mine["collision"].sum())
        lo, hi = row["av_first_pct_ci"]
        assert lo <= row["av_first_pct"] <= hi
        assert row["av_decision_ms_median"] > 0
        assert row["av_not_cleared"] == int(mine["av_delay_s"].isna().sum())
        assert row["hv_not_cleared"] == int(mine["hv_delay_s"].isna().sum())
        (line,) = [x for x in cmp.to_markdown(comparison.summary).splitlines()
                   if x.startswith(f"| {row['av']} | {row['hv']} | 6 |")]
        assert line.split(" | ")[8] == f"{6 - row['av_not_cleared']} / {6 - row['hv_not_cleared']}"
        # each run is what simulate gives for its pair and seed
        seed = int(mine["seed"].iloc[0])
        config = cmp.comparison_base(Config()).with_overrides({"av.kind": row["av"],
                                                               "hv.kind": row["hv"]})
        assert simulate(config, seed).outcome.first_at_line == int(mine["first_at_line"].iloc[0])


def test_yield_never_goes_first_and_paired_differences_are_by_seed(comparison):
    rows = {(r["av"], r["hv"]): r for r in comparison.summary["rows"]}
    assert rows[("yield", "aggressive")]["av_first_pct"] == 0.0
    runs = comparison.runs
    for p in comparison.summary["paired"]:
        ref = runs[(runs["av.kind"] == "persuasive") & (runs["hv.kind"] == p["hv"])]
        other = runs[(runs["av.kind"] == p["av"]) & (runs["hv.kind"] == p["hv"])]
        a = ref.set_index("seed")["first_at_line"].eq(1).astype(float)
        b = other.set_index("seed")["first_at_line"].eq(1).astype(float)
        assert p["av_first_pct"]["mean"] == pytest.approx(100 * (b - a).mean())
        assert p["av_first_pct"]["seeds"] == 6


def test_summary_is_a_function_of_the_runs(comparison):
    again = cmp.summarize(comparison.runs, cmp.comparison_base(Config()),
                          ("persuasive", "yield", "cv"), ("lfg", "aggressive"), 6,
                          {(r["av"], r["shield"], r["hv"]): r["av_decision_ms_median"]
                           for r in comparison.summary["rows"]})
    saved = json.loads((comparison.folder / "summary.json").read_text())
    again["failures"] = saved["failures"]
    assert json.loads(json.dumps(again)) == saved  # bootstrap intervals included


def test_bootstrap_interval_by_construction():
    values = np.array([0.0] * 50 + [1.0] * 50)
    lo, hi = cmp._bootstrap_ci(values)
    assert 0.35 < lo < 0.5 < hi < 0.65  # about +-1.96 * 0.05
    assert cmp._bootstrap_ci(np.ones(7)) == [1.0, 1.0]
    assert cmp._bootstrap_ci(np.array([np.nan])) == [None, None]


def test_compare_command_json_and_figure(capsys, tmp_path):
    code, out, err = run(capsys, "compare", "--av", "persuasive,passive", "--hv", "stubborn",
                         "--seeds", "3", "--workers", "1", "--quiet", "--json",
                         "--out", str(tmp_path / "c"), "--timing-seeds", "1")
    assert code == 0, err
    rows = json.loads(out)
    assert [(r["av"], r["hv"]) for r in rows] == [("persuasive", "stubborn"),
                                                 ("passive", "stubborn")]
    assert all(set(r) == set(cmp.JSON_KEYS) for r in rows)
    code, out, err = run(capsys, "plot", "compare", "--from", str(tmp_path / "c"), "--out",
                         str(tmp_path / "c.png"))
    assert code == 0 and (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"
    # rerunning the same comparison resumes (nothing to run) and gives the same summary
    before = (tmp_path / "c" / "summary.json").read_text()
    code, _, _ = run(capsys, "compare", "--av", "persuasive,passive", "--hv", "stubborn",
                     "--seeds", "3", "--workers", "1", "--quiet", "--json",
                     "--out", str(tmp_path / "c"), "--timing-seeds", "1")
    after = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert code == 0
    for a, b in zip(json.loads(before)["rows"], after["rows"]):
        a.pop("av_decision_ms_median"), b.pop("av_decision_ms_median")  # timing varies
        assert a == b


@pytest.mark.parametrize("args, message", [
    (["--av", "persuasive,teleport"], "--av = 'teleport' is out of range"),
    (["--hv", "lfg,lfg"], "given twice"),
    (["--seeds", "0"], "--seeds"),
])
def test_compare_bad_input(capsys, tmp_path, args, message):
    code, out, err = run(capsys, "compare", *args, "--out", str(tmp_path / "c"), "--quiet")
    assert code == 2 and out == "" and message in err and err.count("\n") == 1


# -- the size of a comparison counts every interaction; the bar counts runs --------------------

#: The pairs of a default comparison: every planner x every human but replay (the registries).
N_PAIRS = len(cmp.AV_KINDS) * len(cmp.DEFAULT_HV_KINDS)
#: The most seeds 1,000,000 runs allow for them with 3 shield settings and 4 interactions.
MOST_SHIELDS = 1_000_000 // (3 * N_PAIRS * 4)


@pytest.mark.parametrize("args, message", [
    (["--interactions", "1000", "--seeds", "2000"],
     f"--seeds = 2000 is out of range; allowed: 1..{1_000_000 // (N_PAIRS * 1000)} for "
     f"{N_PAIRS} pairs x 1000 interactions (at most 1000000 runs, every interaction counted, "
     "summarised in memory; 'persuasive sweep' streams more to disk)"),
    # the interactions from --set count as well as --interactions
    (["--set", "simulation.interactions=10", "--av", "cv", "--hv", "idm,lfg", "--seeds",
      "50001"],
     "--seeds = 50001 is out of range; allowed: 1..50000 for 2 pairs x 10 interactions (at "
     "most 1000000 runs, every interaction counted, summarised in memory; 'persuasive sweep' "
     "streams more to disk)"),
    # shield settings are pairs too
    (["--shield", "off,worst-case,responsive", "--interactions", "4", "--seeds",
      str(MOST_SHIELDS + 1)],
     f"--seeds = {MOST_SHIELDS + 1} is out of range; allowed: 1..{MOST_SHIELDS} for "
     f"{3 * N_PAIRS} pairs x 4 interactions (at most 1000000 runs, every interaction counted, "
     "summarised in memory; 'persuasive sweep' streams more to disk)"),
], ids=["interactions", "set-interactions", "shields"])
def test_the_run_cap_counts_interactions(capsys, tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)  # the default folder would go here

    def never(*args, **kwargs):
        raise AssertionError("a comparison over the cap started")

    monkeypatch.setattr(cmp, "run_comparison", never)
    code, out, err = run(capsys, "compare", *args, "--quiet")
    assert (code, out, err) == (2, "", f"error: {message}\n")
    assert list(tmp_path.iterdir()) == []


def test_check_size_bounds():
    assert cmp.check_size(25, 40, 1000) == 25  # exactly 1,000,000 runs
    with pytest.raises(ConfigError, match=r"^seeds = 26 is out of range; allowed: 1\.\.25 "):
        cmp.check_size(26, 40, 1000)
    assert cmp.check_size(25000, 40) == 25000
    with pytest.raises(ConfigError, match=r"^seeds = 25001 is out of range; allowed: 1\.\.25000 "
                                          r"for 40 pairs \(at most"):
        cmp.check_size(25001, 40)
    most = 1_000_000 // (N_PAIRS * 1000)
    with pytest.raises(ConfigError, match=rf"allowed: 1\.\.{most} for {N_PAIRS} pairs x 1000 "
                                          "interactions"):
        cmp.comparison_grid(Config().with_overrides({"simulation.interactions": 1000}),
                            cmp.AV_KINDS, cmp.DEFAULT_HV_KINDS, most + 1)


@pytest.mark.slow  # a local cluster starts
def test_the_progress_counts_runs_with_their_interactions(tmp_path):
    calls = []
    base = Config().with_overrides({"simulation.interactions": 3})
    cmp.run_comparison(base, ("cv",), ("idm",), seeds=2, out=tmp_path / "c", workers=1,
                       timing_seeds=1, progress=lambda done, total: calls.append((done, total)))
    assert calls[0] == (0, 6) and calls[-1] == (6, 6)  # 2 seeds x 3 interactions
    assert all(total == 6 and done % 3 == 0 for done, total in calls)


def test_hv_role_is_refused_when_no_compared_kind_reads_it(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(cmp, "run_comparison", None)  # never reached
    code, out, err = run(capsys, "compare", "--av", "persuasive,cv", "--hv", "idm,adversary",
                         "--hv-role", "follower", "--out", str(tmp_path / "c"), "--quiet")
    assert (code, out) == (2, "")
    assert err == ("error: --hv-role = follower is not used by the idm, adversary HVs with the "
                   "persuasive, cv AVs; it is read only by the lfg, stubborn, noisy humans and "
                   "the lfg AV (the lfg AV starts in the other role)\n")
    assert list(tmp_path.iterdir()) == []
    from persuasive.cli.compare import check_hv_role

    # one kind that reads it is enough: the pairs with it start from it
    check_hv_role("follower", Config(), ("persuasive", "lfg"), ("idm",))
    check_hv_role("follower", Config(), ("cv",), ("idm", "noisy"))
    check_hv_role(None, Config(), ("cv",), ("idm",))
