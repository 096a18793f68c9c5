"""Every command checks its arguments and inputs before any kernel compile: given a missing
input, each ends at once (exit status 2, one ``error:`` line naming the path) on a machine whose
kernel cache is cold, instead of compiling for minutes first.

Each command runs as a user types it, in its own process, with ``NUMBA_CACHE_DIR`` an empty
folder of the test's (the package's own cache is not touched: ``persuasive._compile``). The
limit of 3 s is on the process's CPU time (user + system), which a loaded machine does not
stretch: importing the package takes about 1 s of it, a compile tens of seconds; nothing may
be compiled at all (the cache folder holds no kernel afterwards). The wall time is bounded
loosely (a 2-core machine running the rest of the suite beside it can triple it).
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import time

import pytest

#: CPU seconds (user + system) a command may take to refuse a missing input.
CPU_LIMIT_S = 3.0
#: Wall seconds, only against a hang or a compile on a loaded machine.
WALL_LIMIT_S = 60.0

M = "missing-folder"  # under the test's folder, never created

CASES = {
    "simulate --config": (["simulate", "--config", f"{M}/c.toml"], f"{M}/c.toml"),
    "simulate replay file": (["simulate", "--hv", "replay", "--set",
                              f"hv.replay.file={M}/r.parquet"], f"{M}/r.parquet"),
    "reproduce --config": (["reproduce", "table1", "--seeds", "2", "--config", f"{M}/c.toml"],
                           f"{M}/c.toml"),
    "compare --config": (["compare", "--seeds", "2", "--config", f"{M}/c.toml"],
                         f"{M}/c.toml"),
    "sweep GRID": (["sweep", f"{M}/grid.toml"], f"{M}/grid.toml"),
    "plot profile --from": (["plot", "profile", "--from", f"{M}/r.parquet", "--out", "p.png"],
                            f"{M}/r.parquet"),
    "plot topview replay file": (["plot", "topview", "--single", "--hv", "replay", "--set",
                                  f"hv.replay.file={M}/r.parquet", "--out", "p.png"],
                                 f"{M}/r.parquet"),
    "animate --from": (["animate", "--from", f"{M}/r.parquet", "--out", "a.gif"],
                       f"{M}/r.parquet"),
    "drive --study": (["drive", "--study", f"{M}/s.toml", "--port", "0"], f"{M}/s.toml"),
    "fit LOGS": (["fit", "x.parquet", f"{M}/a.parquet"], f"{M}/a.parquet"),
    "recordings pairs": (["recordings", "pairs", f"{M}/tracks"], f"{M}/tracks"),
    "recordings logs": (["recordings", "logs", f"{M}/pairs.parquet", "--out", "logs"],
                        f"{M}/pairs.parquet"),
    "recordings export": (["recordings", "export", f"{M}/r.parquet", "--out", "tracks"],
                          f"{M}/r.parquet"),
    "recordings replay": (["recordings", "replay", f"{M}/pairs.parquet"],
                          f"{M}/pairs.parquet"),
    "highway --video": (["highway", "--episodes", "1", "--video", f"{M}/v.gif"], M),
    "sumo --video": (["sumo", "--episodes", "1", "--video", f"{M}/v.gif"], M),
}


def _cpu_of_children() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def refuse(tmp_path, argv: list[str]) -> tuple[int, str, float, float, list[str]]:
    """Run ``persuasive argv`` in ``tmp_path`` with an empty kernel cache: (exit status,
    stderr, CPU seconds, wall seconds, the kernel files the cache holds afterwards)."""
    cache = tmp_path / "empty-cache"
    cache.mkdir()
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    cpu0, t0 = _cpu_of_children(), time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "persuasive", *argv], cwd=tmp_path,
                            env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        _, err = proc.communicate(timeout=WALL_LIMIT_S)
    finally:
        proc.kill()
        proc.wait()
    wall, cpu = time.monotonic() - t0, _cpu_of_children() - cpu0
    kernels = sorted(p.name for p in cache.rglob("*") if p.suffix in (".nbi", ".nbc"))
    return proc.returncode, err, cpu, wall, kernels


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_a_missing_input_is_refused_before_any_compile(tmp_path, case):
    argv, path = CASES[case]
    if case == "drive --study":
        pytest.importorskip("starlette")  # the web extra
    if case == "fit LOGS":  # a good log first: the missing one is found before any work
        from persuasive import Config, simulate

        config = Config().with_overrides({"simulation.n_steps": 5})
        simulate(config, 1).save(tmp_path / "x.parquet")
    code, err, cpu, wall, kernels = refuse(tmp_path, argv)
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert code == 2, err
    assert len(errors) == 1 and path in errors[0], err
    assert "compiling" not in err and kernels == [], (err, kernels)
    assert cpu < CPU_LIMIT_S, (cpu, wall, err)
