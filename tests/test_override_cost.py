"""What the shield's overrides cost (issue 25 item 6): ``override_share`` and ``override_mps2``
per run, by hand and from real runs, and their rows in ``compare`` and the sweep metrics."""

from __future__ import annotations

import numpy as np
import pytest

from persuasive import Config
from persuasive.safety import measures
from persuasive.safety import shield as sh
from persuasive.simulation import simulate
from persuasive.sweep.metrics import METRICS


def test_override_cost_by_hand():
    verdicts = np.array([sh.ADMITTED, sh.BRAKE, sh.GO, sh.ADMITTED, sh.UNCERTIFIED, sh.BRAKE])
    proposed = np.array([0.5, 1.0, -1.0, 0.2, 0.0, np.nan])
    applied = np.array([0.5, -2.0, 1.0, 0.2, -2.0, -2.0])
    got = measures.override_cost(verdicts, proposed, applied)
    assert got["override_share"] == pytest.approx(4 / 6)
    # 3 + 2 + 2 (+ nothing for the NaN proposal) over six steps
    assert got["override_mps2"] == pytest.approx(7 / 6)
    off = np.full(4, sh.OFF)
    assert measures.override_cost(off, np.zeros(4), np.ones(4)) == {
        "override_share": 0.0, "override_mps2": 0.0}
    assert measures.override_cost(None, None, np.ones(3))["override_share"] == 0.0


def test_a_shield_agnostic_planner_is_overridden_and_the_run_says_how_much():
    """The paper's human, seed 15: the planner that ignores the shield is overridden in a
    third of its steps; the outcome's figures are the log's. Without a shield both are 0."""
    cfg = Config(mode="corrected").with_overrides({"hv.kind": "lfg", "mpc.shield_aware": False})
    r = simulate(cfg, 15)
    v, p, a = (r.log["shield_verdict"], r.log["av_proposed_accel_mps2"],
               r.log["av_accel_mps2"])
    over = v > 0
    assert r.outcome.shield_interventions == over.sum() > 10
    assert r.outcome.override_share == pytest.approx(over.mean())
    assert r.outcome.override_mps2 == pytest.approx(np.abs(a - p)[over].sum() / len(v))
    assert r.outcome.override_mps2 > 0.1
    bare = simulate(cfg.with_overrides({"av.shield": "off"}), 15).outcome
    assert bare.override_share == 0.0 and bare.override_mps2 == 0.0


def test_compare_and_the_sweep_metrics_carry_it(tmp_path):
    from persuasive.studies.compare import JSON_KEYS, to_markdown, run_comparison

    assert {"override_pct", "override_mps2_mean"} <= set(JSON_KEYS)
    assert {"override_pct", "override_mps2"} <= set(METRICS)
    base = Config(mode="corrected").with_overrides({"mpc.shield_aware": False})
    summary = run_comparison(base, ("persuasive",), ("lfg",), 20, out=tmp_path / "c",
                             workers=1, timing_seeds=1).summary
    row = summary["rows"][0]
    runs = [simulate(base.with_overrides({"hv.kind": "lfg"}), s).outcome for s in range(1, 21)]
    assert row["override_pct"] == pytest.approx(100 * np.mean([o.override_share for o in runs]))
    assert row["override_mps2_mean"] == pytest.approx(np.mean([o.override_mps2 for o in runs]))
    assert row["override_pct"] > 0
    assert "overrides % of steps" in to_markdown(summary)
