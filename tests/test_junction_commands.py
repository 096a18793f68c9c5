"""The junction of many vehicles through the configuration and the common commands (issue 40
item 7): ``scenario.kind = "junction"`` with its ``[junction]`` section, and ``simulate``,
``compare``, ``sweep``, ``plot profile``/``topview``, ``animate`` and ``bench`` taking
``--scenario junction --vehicles N``."""

from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pandas as pd
import pytest

from persuasive.config import Config, ConfigError
from persuasive.many.junction import JunctionSpec
from persuasive.many.measures import summary
from persuasive.many.study import run_seed
from persuasive.many.world import JunctionWorld
from persuasive.scenarios import build_scenario
from persuasive.simulation import run_summary

from _cli import run_cli

#: A small, short junction in corrected mode (the worst-case shield).
JUNCTION = Config(mode="corrected").with_overrides({"scenario.kind": "junction",
                                                    "junction.n_vehicles": 3,
                                                    "junction.duration_s": 8.0})
#: The options that give the same junction on the command line.
SHORT = ("--scenario", "junction", "--vehicles", 3, "--set", "junction.duration_s=8")


def _no_timing(row: dict) -> dict:
    return {k: v for k, v in row.items() if not k.startswith("step_ms")}


def _same(a: dict, b: dict) -> bool:
    return json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True,
                                                                    default=str)


# -- the configuration ------------------------------------------------------------------------


def test_two_vehicle_configurations_keep_their_text_and_digest():
    for config in (Config(), Config(mode="corrected"),
                   Config().with_overrides({"scenario.kind": "merge"})):
        assert "junction" not in config.to_dict()
        assert "[junction]" not in config.to_toml()
        assert config.junction_spec is None


def test_the_junction_section_round_trips_and_builds_its_spec():
    config = JUNCTION.with_overrides({"junction.variant": "left-heavy", "junction.av_arm": "east",
                                      "junction.av_movement": "left", "junction.lanes": 2,
                                      "junction.gap_m": [5, 9],
                                      "junction.hv_kinds": "lfg:0.5,idm:0.5"})
    back = Config.from_dict(tomllib.loads(config.to_toml()))
    assert back == config and back.digest() == config.digest()
    spec = config.junction_spec
    assert spec == JunctionSpec.of("left-heavy", n_vehicles=3, duration_s=8.0, av_arm=0,
                                   av_movement="left", lanes=2, gap_m=(5.0, 9.0),
                                   hv_kinds="lfg:0.5,idm:0.5")
    assert spec.priority == "first-come" and spec.mix == (0.6, 0.3, 0.1)
    assert config.digest() != JUNCTION.digest()


@pytest.mark.parametrize("overrides, message", [
    ({"junction.n_vehicles": 4}, '[junction] is read only with scenario.kind = "junction"'),
    ({"scenario.kind": "junction", "junction.n_vehicles": 0},
     "junction.n_vehicles = 0 is out of range; allowed: an integer in [1, 64]"),
    ({"scenario.kind": "junction", "junction.variant": "roundabout"},
     "junction.variant = 'roundabout' is out of range; allowed: major | all-way"),
    ({"scenario.kind": "junction", "junction.av_arm": 3},
     "junction.av_arm = 3 is out of range; allowed: east | north | west | south"),
    ({"scenario.kind": "junction", "junction.mix": "left"},
     "junction.mix = 'left' is out of range; allowed: a list of numbers"),
    ({"scenario.kind": "junction", "simulation.interactions": 3},
     "simulation.interactions = 3 is out of range; allowed: 1 with scenario.kind = junction"),
])
def test_bad_junction_configurations_are_refused_in_one_line(overrides, message):
    with pytest.raises(ConfigError) as err:
        Config().with_overrides(overrides)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_two_vehicle_builder_refuses_the_junction_in_one_line():
    with pytest.raises(ConfigError, match="scenario.kind = junction is a world of many vehicles"):
        build_scenario(JUNCTION)


def test_the_run_summary_of_a_junction_is_the_worlds_row():
    row = run_summary(JUNCTION, 2)
    by_hand, _ = run_seed(JUNCTION, JunctionSpec(n_vehicles=3, duration_s=8.0), 2)
    assert _same(row, _no_timing(by_hand))
    assert all(not isinstance(v, np.generic) for v in row.values())  # plain values


# -- simulate -------------------------------------------------------------------------------


def test_simulate_prints_writes_and_matches_the_world(capsys, tmp_path):
    log = tmp_path / "run.parquet"
    code, text, err = run_cli(capsys, "simulate", *SHORT, "--seed", 2, "--out", log)
    assert code == 0, err
    assert ("persuasive AV (one planner per human, yielding outside the junction) among 3 "
            "vehicles at the junction (major" in text)
    assert "AV stood inside the junction 0.0 s (a human waiting for it 0.0 s)" in text
    assert "corrected mode, shield worst-case" in text  # corrected unless a mode is given
    world = JunctionWorld.of(JUNCTION, 2).run()
    frame = pd.read_parquet(log)
    assert len(frame) == int(np.isfinite(world.S[: world.k + 1]).sum())
    av = frame[frame.vehicle == 0]
    np.testing.assert_array_equal(av.s_m.to_numpy(), world.S[av.step.to_numpy(), 0])
    inside = av.step.to_numpy() < world.A.shape[0]
    np.testing.assert_array_equal(av.a_mps2.to_numpy()[inside],
                                  world.A[av.step.to_numpy()[inside], 0])
    k = int(av.step.iloc[-1])
    world_k = JunctionWorld.of(JUNCTION, 2)
    for _ in range(k):
        world_k.step()
    xy, u = world_k.poses()
    last = av.iloc[-1]
    assert math.isclose(last.x_m, xy[0, 0], abs_tol=1e-9)
    assert math.isclose(last.y_m, xy[0, 1], abs_tol=1e-9)
    assert math.isclose(last.heading_rad, math.atan2(u[0, 1], u[0, 0]), abs_tol=1e-9)
    code, text, err = run_cli(capsys, "simulate", *SHORT, "--seed", 2, "--json")
    assert code == 0, err
    got = json.loads(text)  # valid JSON: no NaN
    reference = JunctionWorld.of(JUNCTION, 2, with_av=False).run()
    row = summary(world, reference)
    assert got["av_through"] == row["av_through"] and got["steps"] == row["steps"]
    assert got["caused_delay_s"] == pytest.approx(row["caused_delay_s"], abs=0, rel=0)
    code, text, _ = run_cli(capsys, "simulate", *SHORT, "--mode", "paper")
    assert code == 0 and "paper mode, shield off" in text


@pytest.mark.parametrize("args, message", [
    (("--vehicles", 3), "error: --vehicles is read only with --scenario junction (the "
                        "intersection holds two vehicles)"),
    (("--variant", "all-way", "--scenario", "merge"), "error: --variant is read only with "
                                                      "--scenario junction"),
    ((*SHORT, "--interactions", 2), "error: --interactions repeats one human's encounter"),
    (("--scenario", "junction", "--vehicles", 65), "error: --vehicles = 65 is out of range"),
    (("--scenario", "junction", "--hv", "idm", "--pa", 0.5),
     "error: --pa = 0.5 is not used by"),
])
def test_simulate_refuses_bad_junction_input_in_one_line(capsys, args, message):
    code, _, err = run_cli(capsys, "simulate", *args)
    assert code == 2 and err.startswith(message) and len(err.strip().splitlines()) == 1


def test_the_hv_option_sets_every_human_at_a_junction(capsys, tmp_path):
    """--hv is every human's kind at a junction, whether --scenario or a --config file names
    the junction: the printed row is the idm crowd's run, not the lfg crowd's."""
    config = JUNCTION.with_overrides({"junction.hv_kinds": "idm"})
    want, lfg = run_summary(config, 3), run_summary(JUNCTION, 3)
    assert not _same(want, lfg)  # the two crowds' runs differ on this seed
    assert JunctionWorld.of(config, 3).arrivals.kinds[1:] == ("idm",) * 2
    toml = tmp_path / "junction.toml"
    toml.write_text('mode = "corrected"\n[scenario]\nkind = "junction"\n'
                    '[junction]\nn_vehicles = 3\nduration_s = 8.0\n')
    for args in (SHORT, ("--config", toml)):
        code, text, err = run_cli(capsys, "simulate", *args, "--hv", "idm", "--seed", 3,
                                  "--json")
        assert code == 0, err
        got = {k: v for k, v in json.loads(text).items() if k in want}
        assert _same(got, json.loads(json.dumps(want, default=str).replace("NaN", "null")))


# -- plots ----------------------------------------------------------------------------------


def test_plot_and_animate_draw_the_junction(capsys, tmp_path):
    import imageio.v3 as iio

    for command in (("plot", "profile"), ("plot", "topview")):
        out = tmp_path / f"{command[1]}.png"
        code, text, err = run_cli(capsys, *command, *SHORT, "--seed", 1, "--out", out)
        assert code == 0, err
        assert out.stat().st_size > 0 and f"wrote {out}" in text
    code, text, err = run_cli(capsys, "animate", *SHORT, "--seed", 1, "--fps", 5,
                              "--out", tmp_path / "a.gif")
    assert code == 0, err
    frames = iio.imread(tmp_path / "a.gif", index=None)
    assert frames.shape[0] == JunctionWorld.of(JUNCTION, 1).run().k + 1
    code, _, err = run_cli(capsys, "plot", "topview", "--vehicles", 3, "--from",
                           tmp_path / "a.gif", "--out", tmp_path / "x.png")
    assert code == 2 and "--vehicles cannot be used with --from" in err


# -- compare --------------------------------------------------------------------------------


def test_compare_runs_every_cell_on_the_same_seeds(capsys, tmp_path):
    out = tmp_path / "cmp"
    code, text, err = run_cli(capsys, "compare", *SHORT, "--av", "persuasive,yield",
                              "--hv", "lfg,idm", "--seeds", 3, "--workers", 1, "--out", out,
                              "--quiet")
    assert code == 0, err
    assert "| persuasive | lfg | worst-case | 3 |" in text and "| yield | idm |" in text
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 2 * 2 * 3
    for (av, hv), cell in runs.groupby(["av", "hv"]):
        config = JUNCTION.with_overrides({"av.kind": av, "junction.hv_kinds": hv})
        row = _no_timing(cell.sort_values("seed").iloc[1].to_dict())
        want = run_summary(config, 2)
        assert row["av_through"] == want["av_through"]
        assert row["caused_delay_s"] == pytest.approx(want["caused_delay_s"], rel=0, abs=0)
    saved = json.loads((out / "summary.json").read_text())
    for p in saved["paired"]:
        ref = runs[(runs.av == "persuasive") & (runs.hv == p["hv"])].sort_values("seed")
        other = runs[(runs.av == p["av"]) & (runs.hv == p["hv"])].sort_values("seed")
        diff = other.caused_delay_s.to_numpy() - ref.caused_delay_s.to_numpy()
        assert p["caused_delay_s"]["mean"] == pytest.approx(diff.mean())
        through = 100.0 * (other.av_through.to_numpy(float) - ref.av_through.to_numpy(float))
        assert p["av_through_pts"]["mean"] == pytest.approx(through.mean())
    (out / "notes.txt").write_text("mine")
    code, _, err = run_cli(capsys, "compare", *SHORT, "--av", "yield", "--seeds", 1,
                           "--workers", 1, "--out", out, "--quiet")
    assert code == 2 and "holds other files" in err
    code, _, err = run_cli(capsys, "compare", *SHORT, "--av", "yield", "--seeds", 1,
                           "--workers", 1, "--out", out, "--quiet", "--force")
    assert code == 0, err
    assert (out / "notes.txt").read_text() == "mine"
    assert len(pd.read_parquet(out / "runs.parquet")) == 1
    code, _, err = run_cli(capsys, "compare", *SHORT, "--hv-role", "leader")
    assert code == 2 and "--hv-role is a two-vehicle option" in err


# -- sweep ----------------------------------------------------------------------------------


def test_a_sweep_over_the_number_of_vehicles(capsys, tmp_path):
    grid = tmp_path / "grid.toml"
    grid.write_text('seeds = 2\n[base]\nmode = "corrected"\nscenario.kind = "junction"\n'
                    'junction.duration_s = 8.0\n[axes]\n"junction.n_vehicles" = [2, 3]\n')
    out = tmp_path / "sweep"
    code, _, err = run_cli(capsys, "sweep", grid, "--out", out, "--workers", 1, "--quiet")
    assert code == 0, err
    from persuasive.sweep import load

    runs = load(out).sort_values(["junction.n_vehicles", "seed"])
    assert len(runs) == 4
    for _, r in runs.iterrows():
        config = JUNCTION.with_overrides({"junction.n_vehicles": int(r["junction.n_vehicles"])})
        want = run_summary(config, int(r["seed"]))
        assert r["av_through"] == want["av_through"] and r["steps"] == want["steps"]
    code, text, err = run_cli(capsys, "plot", "sweep", "--from", out, "--x",
                              "junction.n_vehicles", "--metric", "av_through_pct", "--out",
                              tmp_path / "s.png")
    assert code == 0, err
    code, _, err = run_cli(capsys, "plot", "sweep", "--from", out, "--x",
                           "junction.n_vehicles", "--metric", "collision_pct", "--out",
                           tmp_path / "s.png")
    assert code == 2 and "metric 'collision_pct' reads collision, which the runs of this " \
        "sweep do not have; allowed here:" in err and "av_through_pct" in err


# -- bench ----------------------------------------------------------------------------------


def test_bench_times_every_step_of_the_junction(capsys):
    code, text, err = run_cli(capsys, "bench", "--scenario", "junction", "--vehicles", 3,
                              "--runs", 2, "--json")
    assert code == 0, err
    got = json.loads(text)
    config = Config(mode="corrected").with_overrides({"scenario.kind": "junction",
                                                      "junction.n_vehicles": 3})
    steps = sum(JunctionWorld.of(config, s).run().k for s in (1, 2))
    assert got["vehicles"] == 3 and got["steps"] == steps
    assert 0.0 < got["step_ms_median"] <= got["step_ms_p99"]
    assert 0.0 < got["av_share"] < 1.0 and 0.0 < got["humans_share"] < 1.0
    for args, message in ((("--vehicles", 3), "--vehicles is read only with --scenario "
                                              "junction"),
                          (("--scenario", "junction", "--full"), "--full times the "
                                                                 "two-vehicle planner")):
        code, _, err = run_cli(capsys, "bench", *args)
        assert code == 2 and message in err
