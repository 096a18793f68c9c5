"""Every module of the package imports on its own, in a fresh interpreter (no import cycles
that only work in one order)."""

import pkgutil
import subprocess
import sys

import persuasive

#: Every module but ``persuasive.__main__``, which runs the command line when imported.
MODULES = sorted(m.name for m in pkgutil.walk_packages(persuasive.__path__, "persuasive.")
                 if m.name != "persuasive.__main__")


def test_every_module_imports_on_its_own():
    assert "persuasive.cli" in MODULES and "persuasive.cli.plots" in MODULES
    procs = {}
    failures = {}
    for name in MODULES:  # a few at a time: each start pays the numpy/numba import
        procs[name] = subprocess.Popen([sys.executable, "-c", f"import {name}"],
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                       text=True)
        if len(procs) >= 4:
            _drain(procs, failures)
    while procs:
        _drain(procs, failures)
    assert failures == {}


def _drain(procs, failures):
    name = next(iter(procs))
    proc = procs.pop(name)
    _, err = proc.communicate(timeout=120)
    if proc.returncode != 0:
        failures[name] = err.strip().splitlines()[-1]
