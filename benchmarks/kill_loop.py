"""Kill (or interrupt) a running command N times under CPU load; check nothing outlives it.

    python benchmarks/kill_loop.py [--times 20] [--load 2] [--command reproduce|sumo]
                                   [--signal kill|int] [--workers 2]

Each round starts ``persuasive reproduce table2`` (or ``persuasive sumo``) with two workers
(``--workers``) and
a ``TMPDIR`` of its own, waits until its workers run, sends it SIGKILL (or SIGINT, Ctrl-C),
and checks that within 10 s every process that was below it (the fork server,
multiprocessing's resource tracker, the workers) has ended and its ``TMPDIR`` is empty; with
SIGINT also that it exited with status 130, and how long it took. ``--load`` busy processes
keep the cores loaded for the whole loop. Prints one line per round and the count of clean
rounds (and the median and largest time to exit after Ctrl-C); exits 1 if any round left
something behind. The test suite runs one round of each (tests/test_processes.py,
tests/test_sumo.py).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from persuasive._processes import descendants


def alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def burn() -> None:  # pragma: no cover - a load process
    while True:
        pass


def one_round(command: str, folder: Path, sig: int = signal.SIGKILL,
              workers: int = 2) -> tuple[bool, str, float]:
    temp = folder / "tmp"
    temp.mkdir(parents=True)
    out = folder / "out"
    if command == "reproduce":
        argv = ["reproduce", "table2", "--seeds", str(200 * workers), "--workers", str(workers), "--quiet",
                "--out", str(out)]

        def started() -> bool:
            return any((out / "runs").glob("*.parquet"))
    else:
        argv = ["sumo", "--episodes", str(10 * workers), "--workers", str(workers), "--quiet", "--out", str(out)]

        def started() -> bool:
            return any(not p.name.startswith("sumo-net-")
                       for p in temp.glob("persuasive-*/sumo-*"))
    env = dict(os.environ, TMPDIR=str(temp))
    proc = subprocess.Popen([sys.executable, "-m", "persuasive", *argv], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if started() and len(descendants(proc.pid)) >= 2 + workers:
            break
        time.sleep(0.1)
    if proc.poll() is not None:
        return False, f"the command ended first (exit {proc.returncode})", 0.0
    below = descendants(proc.pid)
    t_signal = time.monotonic()
    os.kill(proc.pid, sig)
    proc.wait()
    t0 = time.monotonic()
    to_exit = t0 - t_signal
    while (any(alive(p) for p in below) or any(temp.iterdir())) and time.monotonic() - t0 < 10:
        time.sleep(0.05)
    left = [p for p in below if alive(p)]
    files = sorted(str(p.relative_to(temp)) for p in temp.rglob("*"))
    status_ok = sig == signal.SIGKILL or proc.returncode == 130
    ok = not left and not files and status_ok
    exited = "" if sig == signal.SIGKILL else f"exit {proc.returncode} {to_exit:.2f} s after it; "
    return ok, (f"{exited}{len(below)} processes below it, all gone "
                f"{time.monotonic() - t0:.2f} s after the exit" if ok else
                f"{exited}left: processes {left}, files {files[:5]}"), to_exit


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--times", type=int, default=20)
    parser.add_argument("--load", type=int, default=2, help="busy processes beside it")
    parser.add_argument("--command", choices=["reproduce", "sumo"], default="reproduce")
    parser.add_argument("--signal", choices=["kill", "int"], default="kill")
    parser.add_argument("--workers", type=int, default=2, help="the command's worker processes")
    args = parser.parse_args()
    sig = signal.SIGKILL if args.signal == "kill" else signal.SIGINT
    burners = [multiprocessing.get_context("spawn").Process(target=burn, daemon=True)
               for _ in range(args.load)]
    for b in burners:
        b.start()
    root = Path(tempfile.mkdtemp(prefix="kill-loop-"))
    clean, times = 0, []
    try:
        for i in range(args.times):
            ok, what, to_exit = one_round(args.command, root / str(i), sig, args.workers)
            clean += ok
            times.append(to_exit)
            print(f"round {i + 1}: {'clean' if ok else 'LEFT SOMETHING'}: {what}", flush=True)
    finally:
        for b in burners:
            b.kill()
        shutil.rmtree(root, ignore_errors=True)
    after = (f"; exit after Ctrl-C: median {statistics.median(times):.2f} s, largest "
             f"{max(times):.2f} s" if sig == signal.SIGINT else "")
    print(f"{clean} of {args.times} rounds clean ({args.command}, SIG{args.signal.upper()}, "
          f"{args.workers} workers, {args.load} busy processes beside it, {os.cpu_count()} cores)"
          f"{after}")
    sys.exit(0 if clean == args.times else 1)


if __name__ == "__main__":
    main()
