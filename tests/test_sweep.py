"""Sweeps on Dask (persuasive.sweep, ``persuasive sweep``, ``persuasive plot sweep``).

Exact comparisons throughout: a sweep's rows must equal ``simulate(config, seed).summary()``
value for value, and its Parquet parts must be byte-identical whatever the cluster, the
number of workers, or an interruption. Grids are small (20-step runs where the outcome does
not matter) so the whole module stays well under a minute of compute on two cores.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from persuasive import sweep
from persuasive.cli import main
from persuasive.config import Config, ConfigError
from persuasive.simulation import simulate
from persuasive.sweep.metrics import metric_grid, wilson
from persuasive.sweep.records import flatten, unflatten
from persuasive.sweep.store import chunk_id, chunk_ids, default_chunk, part_paths

ROOT = Path(__file__).resolve().parents[1]

#: 2 x 2 combinations x 5 seeds = 20 short runs.
SMALL = {
    "seeds": 5,
    "base": {"simulation": {"n_steps": 20}},
    "axes": {"roles.p_a": [0.3, 1.0], "mode": ["paper", "corrected"]},
}

SMALL_TOML = """\
seeds = 5

[base]
simulation.n_steps = 20

[axes]
"roles.p_a" = [0.3, 1.0]
mode = ["paper", "corrected"]
"""

#: Seed 4 of these cannot draw an initial state in one draw (InitialStateError).
FAILING_TOML = """\
seeds = 6

[base.simulation]
n_steps = 20

[base.scenario]
max_init_draws = 1
hv_s0_halfwidth_m = 12.0

[axes]
"roles.p_a" = [0.5, 1.0]
"""


def cli(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def parts_bytes(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in part_paths(folder)}


def summaries(folder: Path) -> list[dict]:
    """The dataset's rows turned back into ``summary()`` dicts, in run order."""
    columns = sweep.summary_columns(folder)
    frame = sweep.load(folder)
    return [unflatten({c: row[c] for c in columns}) for row in frame.to_dict("records")]


# -- the grid -----------------------------------------------------------------------------------


def test_grid_runs_in_a_fixed_order():
    grid = sweep.Grid.from_dict(SMALL)
    assert len(grid) == 20 and grid.names == ("roles.p_a", "mode")
    runs = list(grid.runs())
    assert len(runs) == 20
    # the first axis slowest, the seeds fastest
    assert [(r[0]["roles.p_a"], r[0]["mode"], r[2]) for r in runs[:6]] == [
        (0.3, "paper", 1), (0.3, "paper", 2), (0.3, "paper", 3), (0.3, "paper", 4),
        (0.3, "paper", 5), (0.3, "corrected", 1)]
    assert runs[-1][0] == {"roles.p_a": 1.0, "mode": "corrected"} and runs[-1][2] == 5
    for i, (values, config, seed) in enumerate(runs):
        assert grid.run(i) == (values, config, seed)
        assert config == Config.from_dict(SMALL["base"]).with_overrides(values)
        assert grid.config_hash(i) == config.digest()


def test_grid_spellings_agree():
    """A TOML file, unquoted dotted axes, a [seeds] table and integers for floats: one grid."""
    a = sweep.Grid.from_dict(SMALL)
    b = sweep.Grid.from_dict({
        "seeds": {"start": 1, "stop": 5},  # both inclusive
        "base": {"simulation": {"n_steps": 20}},
        "axes": {"roles": {"p_a": [0.3, 1]}, "mode": ["paper", "corrected"]},
    })
    assert a == b and a.digest == b.digest
    assert b.axes[0] == ("roles.p_a", (0.3, 1.0))
    assert type(b.axes[0][1][1]) is float
    assert sweep.Grid.from_dict(a.to_dict()).digest == a.digest
    import tomllib

    assert sweep.Grid.from_dict(tomllib.loads(a.to_toml())).digest == a.digest
    c = sweep.Grid.from_dict({**SMALL, "seeds": {"start": 3, "stop": 4}})
    assert list(c.seeds) == [3, 4] and len(c) == 8 and c.digest != a.digest


def test_grid_from_toml(tmp_path):
    grid = sweep.Grid.from_toml(write(tmp_path / "grid.toml", SMALL_TOML))
    assert grid == sweep.Grid.from_dict(SMALL)
    assert sweep.Grid.from_dict({"seeds": 2}).names == ()  # no axes: one configuration
    assert len(sweep.Grid.from_dict({"seeds": 2})) == 2


BAD_GRIDS = [
    ({"seeds": 2, "axis": {}}, "unknown key 'axis'"),
    ({"axes": {"roles.p_a": [0.5]}}, "seeds is missing"),
    ({"seeds": 0}, "seeds = 0 is out of range"),
    ({"seeds": "10"}, "seeds = '10' is out of range"),
    ({"seeds": True}, "seeds = True is out of range"),
    ({"seeds": {"start": 5, "stop": 4}}, "seeds.stop = 4 is out of range"),
    ({"seeds": {"start": 1, "end": 4}}, "seeds.end: unknown key"),
    ({"seeds": {"start": 1}}, "seeds.stop is missing"),
    ({"seeds": {"start": -1, "stop": 4}}, "seeds.start = -1 is out of range"),
    ({"seeds": 2, "base": {"nope": {}}}, "[base]: unknown section 'nope'"),
    ({"seeds": 2, "base": {"roles": {"p_a": 2.0}}}, "[base]: roles.p_a = 2.0 is out of range"),
    ({"seeds": 2, "axes": {"roles.p_a": 0.5}}, "axes.roles.p_a = 0.5 is not a list"),
    ({"seeds": 2, "axes": {"roles.p_a": []}}, "axes.roles.p_a is empty"),
    ({"seeds": 2, "axes": {"roles.p_a": [0.3, 0.3]}}, "axes.roles.p_a holds 0.3 twice"),
    ({"seeds": 2, "axes": {"roles.p_a": [1, 1.0]}}, "axes.roles.p_a holds 1.0 twice"),
    ({"seeds": 2, "axes": {"roles.p_a": [0.5, 1.5]}}, "axes.roles.p_a = 1.5: roles.p_a"),
    ({"seeds": 2, "axes": {"roles.p_a": [[0.5]]}}, "axes.roles.p_a: value [0.5] is not"),
    ({"seeds": 2, "axes": {"roles.nope": [1]}}, "axes.roles.nope = 1: roles.nope"),
    ({"seeds": 2, "axes": {"nope.x": [1]}}, "axes.nope.x = 1: unknown section 'nope'"),
    ({"seeds": 2, "axes": {"mode": ["paper", "papers"]}}, 'axes.mode = "papers": mode'),
    ({"seeds": 2, "axes": {"seed": [1, 2]}}, "axes.seed: 'seed' cannot be an axis"),
    ({"seeds": 2, "axes": {"roles": {}}}, "axes.roles is an empty table"),
    ({"seeds": 2**32}, "seeds = 4294967296 is out of range; allowed: integer in [1, 4294967295]"),
    ({"seeds": {"start": 0, "stop": 2**32}}, "seeds.stop = 4294967296 is out of range"),
    # six axes of ten values: refused before a million configurations are built
    ({"seeds": 1, "axes": {name: [0.1 * i for i in range(1, 11)]
                           for name in ("roles.p_a", "mpc.p_a_hat", "roles.w_s_m2",
                                        "roles.w_v_m2ps2", "reward.w_c", "reward.w_u")}},
     "the axes give 1000000 combinations (10 x 10 x 10 x 10 x 10 x 10); allowed: at most "
     "100000"),
    # each value is valid on its own, one combination is not
    ({"seeds": 2, "base": {"scenario": {"hv_v0_halfwidth_mps": 0.0}},
      "axes": {"scenario.hv_v0_mps": [4.0, 9.5], "scenario.hv_v0_halfwidth_mps": [0.0, 1.0]}},
     "the combination scenario.hv_v0_mps = 9.5, scenario.hv_v0_halfwidth_mps = 1.0 is invalid"),
]


@pytest.mark.parametrize("data, message", BAD_GRIDS, ids=[m for _, m in BAD_GRIDS])
def test_bad_grid_is_one_line_naming_the_key(data, message):
    with pytest.raises(ConfigError) as info:
        sweep.Grid.from_dict(data)
    text = str(info.value)
    assert "\n" not in text and text.startswith("grid")
    assert message in text


def test_bad_grid_file_exits_2_before_any_work(capsys, tmp_path):
    out = tmp_path / "never"
    bad = write(tmp_path / "bad.toml", 'seeds = 3\n[axes]\n"roles.p_a" = 0.5\n')
    code, stdout, err = cli(capsys, "sweep", bad, "--out", out)
    assert code == 2 and stdout == ""
    assert err == "error: grid: axes.roles.p_a = 0.5 is not a list; an axis is a list of " \
                  "values, e.g. [0.3, 0.7]\n"
    assert not out.exists()
    code, _, err = cli(capsys, "sweep", write(tmp_path / "x.toml", "seeds = [\n"), "--out", out)
    assert code == 2 and err.count("\n") == 1 and "is not valid TOML" in err
    code, _, err = cli(capsys, "sweep", tmp_path / "missing.toml", "--out", out)
    assert code == 2 and err.count("\n") == 1 and "cannot be read" in err
    code, _, err = cli(capsys, "sweep", write(tmp_path / "g.toml", SMALL_TOML), "--out", out,
                       "--workers", "2", "--scheduler", "tcp://127.0.0.1:1")
    assert code == 2 and "--workers applies to the local cluster only" in err
    assert not out.exists()


def test_a_grid_checks_its_seeds_however_it_is_built():
    with pytest.raises(ConfigError, match=r"grid: seeds.stop = 4294967296 is out of range; "
                                          r"allowed: integer in \[0, 4294967295\]"):
        sweep.Grid(Config(), (), 1, 2**32)
    with pytest.raises(ConfigError, match="grid: seeds.stop = 1 is out of range"):
        sweep.Grid(Config(), (), 2, 1)


#: Plans a sweep of 2 x (2^32 - 1) runs in a process allowed 1.5 GB of data: the chunks must
#: be planned lazily (listing their 34 million ranges and ids would take several GB).
_HUGE_SWEEP = """\
import itertools, json, os, resource, sys, time
resource.setrlimit(resource.RLIMIT_DATA, (1536 * 2**20, resource.RLIM_INFINITY))
from persuasive.sweep import Grid
from persuasive.sweep.store import MANIFEST, SweepStore
grid = Grid.from_dict({"seeds": 4294967295, "axes": {"roles.p_a": [0.5, 1.0]}})
t = time.perf_counter()
store = SweepStore.open(sys.argv[1], grid)
todo, chunks = store.pending()
store.start()  # writes the manifest
first = [(c.index, c.start, c.stop, c.id) for c in itertools.islice(chunks, 2)]
last = store.chunk_at(store.n_chunks - 1)
print(json.dumps({"runs": len(grid), "todo": todo, "chunks": store.n_chunks, "first": first,
                  "last": [last.index, last.start, last.stop], "s": time.perf_counter() - t,
                  "manifest": os.path.getsize(os.path.join(sys.argv[1], MANIFEST))}))
"""


def test_a_sweep_of_billions_of_runs_is_planned_lazily(tmp_path):
    done = subprocess.run([sys.executable, "-c", _HUGE_SWEEP, str(tmp_path / "huge")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    runs = 2 * (2**32 - 1)
    assert result["runs"] == result["todo"] == runs
    assert result["chunks"] == -(-runs // 250) == 34359739
    assert [f[:3] for f in result["first"]] == [[0, 0, 250], [1, 250, 500]]
    digest = sweep.Grid.from_dict({"seeds": 4294967295, "axes": {"roles.p_a": [0.5, 1.0]}}).digest
    assert result["first"][0][3] == chunk_id(digest, 0, 0, 250, result["chunks"])
    assert result["first"][0][3].startswith("00000000-")  # as wide as the last index
    assert result["last"] == [34359738, 8589934500, runs]
    assert result["manifest"] < 4096 and result["s"] < 10.0


# -- flattening -----------------------------------------------------------------------------------


def test_flatten_round_trip():
    nested = {"a": 1, "b": {"c": True, "d": {"e": "x"}}, "s": [1.5, -2.0], "n": None,
              "m": [{"k": 1}, {"k": 2}]}
    flat = flatten(nested)
    assert flat == {"a": 1, "b.c": True, "b.d.e": "x", "s.0": 1.5, "s.1": -2.0, "n": None,
                    "m.0.k": 1, "m.1.k": 2}
    assert unflatten(flat) == nested
    assert unflatten({"n": math.nan})["n"] is None  # a null read back through pandas
    summary = simulate(Config().with_overrides({"simulation.n_steps": 5}), 3).summary()
    assert unflatten(flatten(summary)) == summary
    assert "hv_initial_state.0" in flatten(summary) and "quirks.q1_branch_time_offset" in \
        flatten(summary)


# -- running on a local Dask cluster --------------------------------------------------------------


@pytest.fixture(scope="module")
def small_grid() -> sweep.Grid:
    return sweep.Grid.from_dict(SMALL)


@pytest.fixture(scope="module")
def reference(small_grid, tmp_path_factory) -> Path:
    """The small grid run on a 2-worker local cluster in chunks of 7 runs."""
    folder = tmp_path_factory.mktemp("sweep") / "ref"
    seen = []
    summary = sweep.run(small_grid, folder, workers=2, chunk=7,
                        progress=lambda done, total: seen.append((done, total)))
    assert summary.ok and summary.runs == 20 and summary.ran == 20 and summary.skipped == 0
    assert summary.chunks == 3 and summary.chunk == 7 and summary.workers == 2
    assert seen[0] == (0, 20) and seen[-1] == (20, 20) and len(seen) == 4
    return folder


def test_records_equal_simulate(reference, small_grid):
    frame = sweep.load(reference)
    assert frame["run"].tolist() == list(range(20))
    assert list(frame.columns[:5]) == ["run", "roles.p_a", "mode", "seed", "config_hash"]
    assert {"hv_initial_state.0", "hv_initial_state.1", "quirks.q5_leader_agg_max"} <= \
        set(frame.columns)
    for row, summary, (values, config, seed) in zip(frame.to_dict("records"),
                                                    summaries(reference), small_grid.runs()):
        assert summary == simulate(config, seed).summary()
        assert row["seed"] == seed and row["config_hash"] == config.digest()
        assert {k: row[k] for k in values} == values
    # pandas reads the folder of parts as it is
    pd.testing.assert_frame_equal(pd.read_parquet(reference / "runs"), frame)


def test_record_equals_simulate_json(reference, small_grid, capsys, tmp_path):
    """Run 13 as ``persuasive simulate --json`` prints it, through its configuration file."""
    values, config, seed = small_grid.run(13)
    config_file = write(tmp_path / "run13.toml", config.to_toml())
    code, out, _ = cli(capsys, "simulate", "--json", "--config", config_file, "--seed", seed)
    assert code == 0
    assert json.loads(out) == json.loads(json.dumps(summaries(reference)[13]))


def test_same_dataset_whatever_the_workers_and_chunks(reference, small_grid, tmp_path):
    ones = sweep.run(small_grid, tmp_path / "one", workers=2, chunk=1)
    assert ones.ok and ones.chunks == 20
    assert len(part_paths(tmp_path / "one")) == 20
    pd.testing.assert_frame_equal(sweep.load(tmp_path / "one"), sweep.load(reference))
    single = sweep.run(small_grid, tmp_path / "single", workers=1, chunk=7)
    assert single.workers == 1
    assert parts_bytes(tmp_path / "single") == parts_bytes(reference)
    assert (tmp_path / "single/manifest.json").read_bytes() == \
        (reference / "manifest.json").read_bytes()


def test_rerun_skips_finished_chunks(reference, small_grid, tmp_path):
    import shutil

    folder = tmp_path / "copy"
    shutil.copytree(reference, folder)
    before = {p.name: p.stat().st_mtime_ns for p in part_paths(folder)}
    again = sweep.run(small_grid, folder)  # the folder's chunk size; no cluster is started
    assert again.ok and again.ran == 0 and again.skipped == 20 and again.workers == 0
    assert {p.name: p.stat().st_mtime_ns for p in part_paths(folder)} == before
    # a lost part is rerun alone
    lost = part_paths(folder)[1]
    lost.unlink()
    again = sweep.run(small_grid, folder, workers=1)
    assert again.ran == 7 and again.skipped == 13
    assert parts_bytes(folder) == parts_bytes(reference)


def test_a_manifest_left_half_written_is_ignored(small_grid, tmp_path):
    folder = tmp_path / "out"
    folder.mkdir()
    write(folder / ".manifest.x1y2z3.tmp.json", '{"format": "persuasive-sw')  # killed here
    summary = sweep.run(small_grid, folder, workers=1, chunk=10)
    assert summary.ok and sorted(os.listdir(folder)) == ["failed", "manifest.json", "runs"]


def test_manifest(reference, small_grid):
    manifest = sweep.read_manifest(reference)
    assert manifest["grid_digest"] == small_grid.digest
    assert manifest["runs"] == 20 and manifest["chunk"] == 7 and manifest["chunks"] == 3
    assert manifest["axes"] == ["roles.p_a", "mode"] and manifest["seeds"] == [1, 5]
    import tomllib

    assert sweep.Grid.from_dict(tomllib.loads(manifest["grid_toml"])) == small_grid
    assert "chunk_ids" not in manifest  # planned from the chunk size, never listed
    assert [p.name for p in part_paths(reference)] == \
        [f"part-{cid}.parquet" for cid in chunk_ids(small_grid.digest, [(0, 7), (7, 14),
                                                                        (14, 20)])]
    assert sorted(os.listdir(reference)) == ["failed", "manifest.json", "runs"]
    assert os.listdir(reference / "failed") == []
    assert default_chunk(20) == 1 and default_chunk(6400) == 200 and default_chunk(10**6) == 250


# -- an existing scheduler with two workers, started as separate processes -------------------


@pytest.fixture(scope="module")
def scheduler_address(tmp_path_factory):
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1; killed at the end."""
    folder = tmp_path_factory.mktemp("dask")
    info = folder / "scheduler.json"
    procs = []

    def start(*args):  # Dask's own files in the fixture's folder, not in TMPDIR
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", *args], cwd=folder,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                      start_new_session=True,
                                      env=dict(os.environ,
                                               DASK_TEMPORARY_DIRECTORY=str(folder))))

    try:
        start("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
              "--scheduler-file", str(info))
        deadline = time.monotonic() + 60
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        for _ in range(2):
            start("worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
                  "--host", "127.0.0.1")
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address
    finally:
        for proc in procs:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        for proc in procs:
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def test_existing_scheduler_gives_the_same_dataset(scheduler_address, reference, capsys,
                                                   tmp_path):
    grid_file = write(tmp_path / "grid.toml", SMALL_TOML)
    code, out, err = cli(capsys, "sweep", grid_file, "--out", tmp_path / "remote",
                         "--scheduler", scheduler_address, "--chunk", "7", "--json",
                         "--quiet")
    assert code == 0 and err == ""
    payload = json.loads(out)
    assert payload["workers"] == 2 and payload["ran"] == 20 and payload["failed"] == 0
    assert parts_bytes(tmp_path / "remote") == parts_bytes(reference)


def test_unreachable_scheduler_is_one_line(capsys, tmp_path, monkeypatch):
    import socket

    from persuasive.sweep import runner

    monkeypatch.setattr(runner, "CONNECT_TIMEOUT_S", 1.0)

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    grid_file = write(tmp_path / "grid.toml", SMALL_TOML)
    code, _, err = cli(capsys, "sweep", grid_file, "--out", tmp_path / "x" / "y", "--scheduler",
                       f"tcp://127.0.0.1:{port}", "--quiet")
    assert code == 2 and err.count("\n") == 1
    assert err.startswith(f"error: scheduler 'tcp://127.0.0.1:{port}' cannot be reached")
    assert not (tmp_path / "x").exists()  # no manifest, no runs/ or failed/: nothing started


def test_a_sweep_that_cannot_start_leaves_the_folder_as_it_was(capsys, tmp_path, monkeypatch,
                                                               reference):
    from persuasive.sweep import runner

    monkeypatch.setattr(runner, "CONNECT_TIMEOUT_S", 1.0)
    other = write(tmp_path / "other.toml", 'seeds = 2\n[axes]\n"roles.p_a" = [0.5]\n')
    before = sorted((p.relative_to(reference), p.read_bytes()) for p in reference.rglob("*")
                    if p.is_file())
    # --force would replace the sweep in the folder, but the scheduler is not there
    code, _, err = cli(capsys, "sweep", other, "--out", reference, "--force", "--quiet",
                       "--scheduler", "tcp://127.0.0.1:1")
    assert code == 2 and "cannot be reached" in err
    after = sorted((p.relative_to(reference), p.read_bytes()) for p in reference.rglob("*")
                   if p.is_file())
    assert after == before


# -- killed and resumed -----------------------------------------------------------------------


def test_killed_sweep_resumes_without_lost_or_duplicated_runs(tmp_path):
    # (foresight off: its 15 predicted runs before each corrected run would make this test of
    # the store's resume a minute longer)
    grid_file = write(tmp_path / "grid.toml", """\
seeds = 150

[base]
av.yield_line_choices_m = []

[axes]
"roles.p_a" = [0.5, 1.0]
mode = ["paper", "corrected"]
""")
    folder = tmp_path / "killed"
    command = [sys.executable, "-m", "persuasive", "sweep", str(grid_file), "--out",
               str(folder), "--workers", "2", "--chunk", "4", "--quiet"]
    proc = subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True)
    n_chunks = 150
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            runs = folder / "runs"
            done = len(list(runs.glob("part-*.parquet"))) if runs.is_dir() else 0
            if 0 < done < n_chunks:
                break
            time.sleep(0.002)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # the command and its workers, at once
        except ProcessLookupError:  # it ended by itself: the assertion below says how
            pass
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()
    proc.stderr.close()
    killed_parts = len(part_paths(folder))
    assert 0 < killed_parts < n_chunks
    done = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    # only the missing chunks ran (a part being written at the kill was not renamed yet)
    assert f"{4 * killed_parts} finished earlier, {600 - 4 * killed_parts} run now" in \
        done.stdout
    frame = sweep.load(folder)
    assert frame["run"].tolist() == list(range(600))  # none lost, none twice
    assert not [p for p in (folder / "runs").iterdir() if not p.name.startswith("part-")]
    whole = sweep.run(sweep.Grid.from_toml(grid_file), tmp_path / "whole", workers=2, chunk=4)
    assert whole.ok
    assert parts_bytes(folder) == parts_bytes(tmp_path / "whole")
    assert (folder / "manifest.json").read_bytes() == \
        (tmp_path / "whole/manifest.json").read_bytes()


# -- another grid into the same folder ------------------------------------------------------------


def test_changed_grid_is_refused_unless_force(capsys, tmp_path):
    folder = tmp_path / "out"
    grid_file = write(tmp_path / "grid.toml", SMALL_TOML)
    code, out, _ = cli(capsys, "sweep", grid_file, "--out", folder, "--quiet")
    assert code == 0 and "20 runs in 20 chunks of up to 1" in out
    first = parts_bytes(folder)
    changed = write(tmp_path / "changed.toml", SMALL_TOML.replace("seeds = 5", "seeds = 3"))
    code, out, err = cli(capsys, "sweep", changed, "--out", folder, "--quiet")
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "holds another sweep" in err and "--force" in err
    assert parts_bytes(folder) == first  # untouched
    code, _, err = cli(capsys, "sweep", grid_file, "--out", folder, "--chunk", "3", "--quiet")
    assert code == 2 and "in chunks of 1 runs" in err and "--force" in err
    code, out, _ = cli(capsys, "sweep", changed, "--out", folder, "--force", "--quiet",
                       "--json")
    assert code == 0 and json.loads(out)["runs"] == 12
    assert len(part_paths(folder)) == 12 and not set(parts_bytes(folder)) & set(first)
    assert sweep.load(folder)["seed"].max() == 3
    other = tmp_path / "other"
    other.mkdir()
    write(other / "notes.txt", "mine")
    code, _, err = cli(capsys, "sweep", grid_file, "--out", other, "--quiet")
    assert code == 2 and "holds other files" in err


def test_default_folder(capsys, tmp_path, monkeypatch, small_grid):
    monkeypatch.chdir(tmp_path)
    write(tmp_path / "mine.toml", SMALL_TOML)
    code, out, _ = cli(capsys, "sweep", "mine.toml", "--quiet", "--workers", "1")
    assert code == 0
    folder = Path("results") / f"sweep-mine-{small_grid.digest[:10]}"
    assert len(sweep.load(folder)) == 20 and str(folder) in out


# -- failed runs ----------------------------------------------------------------------------------


def test_failed_runs_are_recorded_and_retried(capsys, tmp_path):
    grid_file = write(tmp_path / "fail.toml", FAILING_TOML)
    folder = tmp_path / "out"
    code, out, err = cli(capsys, "sweep", grid_file, "--out", folder, "--chunk", "2",
                         "--quiet")
    assert code == 1
    lines = err.splitlines()
    assert lines[0].startswith("error: run 3 failed (seed 4, roles.p_a = 0.5, config ")
    assert "InitialStateError: " in lines[0]
    assert lines[1].startswith("error: run 9 failed (seed 4, roles.p_a = 1.0")
    assert lines[2] == (f"error: 2 run(s) failed (listed in {folder}/failed/); rerun the same "
                        "command to retry them (only their chunks run again)")
    frame = sweep.load(folder)
    assert frame["run"].tolist() == [0, 1, 2, 4, 5, 6, 7, 8, 10, 11]
    failures = sweep.load_failures(folder)
    assert failures["run"].tolist() == [3, 9] and failures["seed"].tolist() == [4, 4]
    assert failures["roles.p_a"].tolist() == [0.5, 1.0]
    grid = sweep.Grid.from_toml(grid_file)
    assert failures["config_hash"].tolist() == [grid.config_hash(3), grid.config_hash(9)]
    assert all(e.startswith("InitialStateError: ") and "\n" not in e
               for e in failures["error"])
    files = sorted(p.name for p in (folder / "failed").iterdir())
    assert len(files) == 2 and all(f.startswith("failed-") and f.endswith(".json")
                                   for f in files)
    # the others are right
    for row, summary in zip(frame.to_dict("records"), summaries(folder)):
        assert summary == simulate(grid.run(row["run"])[1], row["seed"]).summary()
    # rerunning retries the two chunks that hold a failed run, and only them
    code, out, err = cli(capsys, "sweep", grid_file, "--out", folder, "--quiet", "--json")
    assert code == 1 and "rerun the same command" in err
    payload = json.loads(out)
    assert payload["ran"] == 4 and payload["skipped"] == 8 and payload["failed"] == 2
    pd.testing.assert_frame_equal(sweep.load(folder), frame)


# -- plots --------------------------------------------------------------------------------------


def test_wilson_interval_by_hand():
    lo, hi = wilson(5, 10)  # centre 0.5; half-width z sqrt(0.025 + z^2/400) / (1 + z^2/10)
    assert lo == pytest.approx(0.236593, abs=1e-6) and hi == pytest.approx(0.763407, abs=1e-6)
    lo, hi = wilson(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.277533, abs=1e-6)
    assert all(math.isnan(b) for b in wilson(0, 0))


def test_metric_grid_matches_the_runs(reference):
    frame = sweep.load(reference)
    data = metric_grid(reference, "av_first_pct", "roles.p_a", "mode")
    assert data.x_values == (0.3, 1.0) and data.y_values == ("paper", "corrected")
    assert data.estimate.shape == (2, 2) and data.n.tolist() == [[5, 5], [5, 5]]
    for i, mode in enumerate(data.y_values):
        for j, pa in enumerate(data.x_values):
            cell = frame[(frame["mode"] == mode) & (frame["roles.p_a"] == pa)]
            k = int((cell["first_at_line"] == 1).sum())
            assert data.estimate[i, j] == 100.0 * k / 5
            assert (data.lo[i, j], data.hi[i, j]) == tuple(100.0 * b for b in wilson(k, 5))
    mean = metric_grid(reference, "min_distance_m", "mode", where={"roles.p_a": 1.0})
    cell = frame[(frame["mode"] == "paper") & (frame["roles.p_a"] == 1.0)]["min_distance_m"]
    half = 1.959963984540054 * cell.std(ddof=1) / math.sqrt(5)
    assert mean.estimate[0] == pytest.approx(cell.mean(), rel=1e-12)
    assert mean.hi[0] - mean.estimate[0] == pytest.approx(half, rel=1e-9)
    assert mean.where == (("roles.p_a", 1.0),) and mean.pooled == ()
    assert metric_grid(reference, "collision_pct", "mode").pooled == ("roles.p_a",)


@pytest.mark.parametrize("args", [
    ("--x", "roles.p_a", "--metric", "av_first_pct"),
    ("--x", "mode", "--metric", "min_distance_m", "--where", "roles.p_a=0.3"),
    ("--x", "roles.p_a", "--y", "mode", "--metric", "infeasible_pct"),
    ("--x", "roles.p_a", "--series", "mode", "--metric", "av_first_pct"),
], ids=["line", "line-where", "heatmap", "series"])
def test_plot_sweep_writes_a_png(reference, capsys, tmp_path, args):
    out = tmp_path / "fig.png"
    code, stdout, err = cli(capsys, "plot", "sweep", "--from", reference, *args, "--out", out)
    assert code == 0 and stdout == f"wrote {out}\n"
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("args, message", [
    (("--x", "roles.p_a", "--metric", "nope"), "metric 'nope' is not known; allowed: "),
    (("--x", "nope", "--metric", "av_first_pct"), "--x 'nope' is not an axis of the sweep; "
                                                  "allowed: roles.p_a, mode"),
    (("--x", "mode", "--y", "mode", "--metric", "av_first_pct"), "--y 'mode' is the same"),
    (("--x", "mode", "--metric", "av_first_pct", "--where", "roles.p_a=0.7"),
     "--where roles.p_a = 0.7 is not a value of the axis"),
    (("--x", "mode", "--y", "roles.p_a", "--series", "roles.p_a", "--metric",
      "av_first_pct"), "--series and --y are two ways to draw a second axis; allowed: one"),
], ids=["metric", "axis", "same-axis", "where", "series-and-y"])
def test_plot_sweep_bad_input_exits_2(reference, capsys, tmp_path, args, message):
    out = tmp_path / "fig.png"
    code, _, err = cli(capsys, "plot", "sweep", "--from", reference, *args, "--out", out)
    assert code == 2 and err.count("\n") == 1 and message in err
    assert not out.exists()


def test_a_series_figure_draws_one_line_per_value_of_the_second_axis(reference):
    from persuasive.plots.sweep import sweep_figure

    data = metric_grid(reference, "av_first_pct", "roles.p_a", "mode")
    ax = sweep_figure(data, series=True).axes[0]
    series = {c.get_label(): c.lines[0] for c in ax.containers}  # errorbar: the data line
    assert sorted(series) == sorted(data.y_values)
    for i, mode in enumerate(data.y_values):  # each line is its row of the grid, x in order
        line = series[mode]
        assert list(line.get_xdata()) == [0.3, 1.0]
        assert list(line.get_ydata()) == list(data.estimate[i])
    assert [t.get_text() for t in ax.get_legend().get_texts()] == list(data.y_values)


def test_plot_sweep_needs_a_sweep_folder(capsys, tmp_path):
    code, _, err = cli(capsys, "plot", "sweep", "--from", tmp_path, "--x", "mode", "--metric",
                       "av_first_pct", "--out", tmp_path / "f.png")
    assert code == 2 and "has no manifest.json" in err


# -- the benchmark and the SLURM example, at smoke size ------------------------------------------


def test_bench_sweep_tiny():
    from persuasive.bench_sweep import bench_sweep

    result = bench_sweep(sizes=(8,), workers=2, repeats=1)
    (size,) = result["sizes"]
    assert size["runs"] == 8 and size["same_results"] is True
    assert size["pool_runs_per_s"] > 0 and size["sweep_runs_per_s"] > 0
    assert size["client_peak_rss_mb"] >= size["client_rss_before_mb"] > 0
    assert result["ratio"] == size["ratio"] == size["pool_s"] / size["sweep_s"]


def test_slurm_example_smoke(tmp_path):
    grid_file = write(tmp_path / "grid.toml", SMALL_TOML)
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks/slurm_sweep.py"),
                           str(grid_file), "--out", str(tmp_path / "slurm"), "--chunk", "7",
                           "--smoke"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "20 of 20 runs" in done.stdout
    assert len(sweep.load(tmp_path / "slurm")) == 20


def test_an_axis_mixing_a_word_and_numbers_points_to_cases(capsys, tmp_path):
    """``["online", 0.9]`` for mpc.p_a_hat cannot be one axis (one column of one type); the
    message says how to write it as cases, and what it says builds the intended grid."""
    grid_file = write(tmp_path / "g.toml", 'seeds = 2\n[axes]\n"mpc.p_a_hat" = ["online", 0.9]\n'
                      '"roles.p_a" = [0.5, 1.0]\n')
    out = tmp_path / "never"
    code, stdout, err = cli(capsys, "sweep", grid_file, "--out", out)
    advice = '[[cases]] "mpc.p_a_hat" = "online" [[cases]] "mpc.p_a_hat" = 0.9'
    assert (code, stdout) == (2, "")
    assert err == ("error: grid: axes.mpc.p_a_hat mixes value types (number and string); give "
                   f"values of one type, or run each value as a case of its own: {advice} (and "
                   "no axes.mpc.p_a_hat)\n")
    assert not out.exists()
    cases = advice.replace(" [[cases]]", "\n[[cases]]").replace("] ", "]\n")
    fixed = write(tmp_path / "fixed.toml",
                  f'seeds = 2\n[axes]\n"roles.p_a" = [0.5, 1.0]\n{cases}\n')
    grid = sweep.Grid.from_toml(fixed)
    assert [grid.config(i).mpc.p_a_hat for i in range(grid.n_combinations)] == \
        ["online", "online", 0.9, 0.9]
    assert len(grid) == 8
