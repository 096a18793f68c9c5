"""Shared fixtures, the hypothesis profiles and the suite's own temporary folder.

Hypothesis profiles. ``persuasive`` (the default, what ``make test`` and CI run) is
derandomized: every run tries the same examples, so a fresh clone's ``make test`` cannot fail
on an example nobody has seen; an example that once failed is kept as an explicit
``@example`` beside its test. ``explore`` (``pytest --hypothesis-profile=explore``) draws at
random, ten times as many examples where a test does not set its own count, and keeps what
it finds in ``.hypothesis/``: run it while developing. Both drop hypothesis' per-example
deadline: the first call of a Numba kernel loads it from the on-disk cache (or compiles it),
which takes longer than any sensible deadline.

Temporary folders. Every test and every process it starts writes its temporary files under
the session's own folder (``TMPDIR`` points there for the whole session), never into the
machine's temporary folder, so that suites running side by side cannot see each other's
files.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from persuasive._processes import descendants
from persuasive.packing import discounts, pack
from persuasive.scenarios import build_scenario
from persuasive.config import Config

settings.register_profile(
    "persuasive", deadline=None, suppress_health_check=[HealthCheck.too_slow],
    derandomize=True, database=None, print_blob=True,
)
settings.register_profile(
    "explore", deadline=None, suppress_health_check=[HealthCheck.too_slow],
    derandomize=False, max_examples=1000, print_blob=True,
)
settings.load_profile("persuasive")  # --hypothesis-profile=explore replaces it


@pytest.fixture(scope="session", autouse=True)
def own_temporary_folder(tmp_path_factory):
    """``TMPDIR`` (and :mod:`tempfile`'s folder) is a folder of this session's."""
    folder = tmp_path_factory.mktemp("tmp")
    old = os.environ.get("TMPDIR")
    os.environ["TMPDIR"] = str(folder)
    tempfile.tempdir = None  # read TMPDIR again
    yield folder
    if old is None:
        os.environ.pop("TMPDIR", None)
    else:
        os.environ["TMPDIR"] = old
    tempfile.tempdir = None


def _stat(pid: int) -> list[str]:
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()


@pytest.fixture
def gone():
    """``gone(pid, within_s=10)``: True once the process has ended (or is a zombie)."""
    def check(pid: int, within_s: float = 10.0) -> bool:
        end = time.monotonic() + within_s
        while time.monotonic() < end:
            try:
                if _stat(pid)[0] == "Z":
                    return True
            except OSError:
                return True
            time.sleep(0.05)
        return False

    return check


@pytest.fixture
def kill_mid_run(tmp_path):
    """``kill_mid_run(argv, started, workers=2, group=False)``: start ``persuasive argv``
    with a ``TMPDIR`` of its own, SIGKILL it (``group``: its whole process group, as
    ``kill -9 -PGID`` would) once ``started()`` holds and its workers run, and return the
    processes it had below it and its ``TMPDIR``."""
    import signal
    import subprocess
    import sys

    def run(argv: list[str], started, workers: int = 2,
            group: bool = False) -> tuple[list[int], Path]:
        temp = tmp_path / "killed-tmp"
        temp.mkdir()
        env = dict(os.environ, TMPDIR=str(temp))
        err_path = tmp_path / "killed-stderr.txt"
        with open(err_path, "w") as err:
            proc = subprocess.Popen([sys.executable, "-m", "persuasive", *argv], env=env,
                                    stdout=subprocess.DEVNULL, stderr=err,
                                    start_new_session=group)
        deadline = time.monotonic() + 240
        try:
            while time.monotonic() < deadline and proc.poll() is None:
                # the fork server, multiprocessing's resource tracker and the workers
                if started() and len(descendants(proc.pid)) >= 2 + workers:
                    break
                time.sleep(0.1)
            assert proc.poll() is None, ("the command ended before it was killed: "
                                         + err_path.read_text()[-1000:])
            below = descendants(proc.pid)
        finally:
            if group:
                os.killpg(proc.pid, signal.SIGKILL)
            elif proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
        return below, temp

    return run


class Packed:
    """A configuration with its kernel parameter vectors and discounts ``disc``.

    ``P`` is the AV's vector and ``P_hv`` the HV's; at the paper's intersection they differ
    only in the path's direction, which the perpendicular kernels never read, so tests of one
    vehicle's library may use either.
    """

    def __init__(self, config: Config):
        self.config = config
        self.P, self.P_hv = pack(config, build_scenario(config))
        self.P_av = self.P
        self.disc = discounts(config)


@pytest.fixture(scope="session")
def paper() -> Packed:
    """The paper-mode defaults (quirks Q1..Q7 on)."""
    return Packed(Config(mode="paper"))


@pytest.fixture(scope="session")
def corrected() -> Packed:
    """The corrected-mode defaults (Q1, Q2, Q3, Q5 off)."""
    return Packed(Config(mode="corrected"))


@pytest.fixture(scope="session")
def unequal() -> Packed:
    """Paper mode with vehicles of different size and limits: the HV 4 m long with
    ``v_max = 8 m/s`` and ``u_min = -3 m/s^2`` (crossing line -6 m, h_go = 5 + 8 / 0.6 m),
    the AV with the defaults; the pair's safety distance is 1.5 (5 + 4) / 2 = 6.75 m."""
    return Packed(Config().with_overrides({"hv.vehicle.length_m": 4.0,
                                           "hv.vehicle.v_max_mps": 8.0,
                                           "hv.vehicle.u_min_mps2": -3.0}))


@pytest.fixture(scope="session", params=["paper", "corrected"])
def packed(request) -> Packed:
    """Both modes, one after the other."""
    return Packed(Config(mode=request.param))
