"""What the suite itself promises (tests/conftest.py): the same hypothesis examples on every
run of ``make test``, and temporary files only in the session's own folder."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

from hypothesis import settings


def test_make_test_runs_the_same_examples_every_time(pytestconfig):
    """The default profile is derandomized and keeps no example database, so a fresh clone's
    ``make test`` tries exactly what CI tried; ``--hypothesis-profile=explore`` draws anew."""
    profile = pytestconfig.getoption("hypothesis_profile", None) or "persuasive"
    assert settings.default.derandomize is (profile != "explore")
    if profile != "explore":
        assert settings.default.database is None


def test_temporary_files_stay_in_the_sessions_folder(own_temporary_folder, tmp_path):
    base = Path(own_temporary_folder)
    assert Path(tempfile.gettempdir()) == base
    assert os.environ["TMPDIR"] == str(base)
    # a process the suite starts inherits it
    child = subprocess.run([sys.executable, "-c", "import tempfile; print(tempfile.gettempdir())"],
                           capture_output=True, text=True, check=True)
    assert Path(child.stdout.strip()) == base
