"""The README's promises, run as a user would: its opening commands, its command-line examples
and its Python example (with the outputs written to a temporary folder).

The configuration and grid files the README used to show live in the guide now; their checks
are in ``tests/test_docs.py``, with the guide's examples and the docs' links."""

import json
import re
import shlex
from pathlib import Path

import pytest

from persuasive.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _block(after_heading: str, lang: str) -> str:
    section = README.split(after_heading, 1)[1]
    return re.search(rf"```{lang}\n(.*?)```", section, re.S).group(1)


def test_readme_opens_with_the_two_commands_and_ci_runs_the_test_one():
    first = re.search(r"```sh\n(.*?)```", README, re.S).group(1).splitlines()
    assert [line.split("#")[0].strip() for line in first] == ["make demo", "make test"]
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^demo: setup\n\t.*persuasive reproduce all$", makefile, re.M)
    # the suite in two workers, a test file per worker (README "Tests")
    assert re.search(r"^test: setup\n\t.*-m pytest -n 2 --dist loadfile$", makefile, re.M)
    assert "make test" in (ROOT / ".ci" / "run").read_text()


@pytest.mark.slow
def test_command_line_examples_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    block = _block("## A five-minute tour", "sh").replace("\\\n", " ")  # join continued lines
    commands = [line.split("  #")[0].strip() for line in block.splitlines()]
    commands = [c for c in commands if c.startswith(".venv/bin/persuasive ")]
    assert len(commands) >= 6
    for command in commands:
        argv = shlex.split(command)[1:]
        capsys.readouterr()
        assert main(argv) == 0, command
        if argv[0] == "fit":  # the fit the bullet quotes, as the tour prints it
            quoted = re.search(r"`(p_a = [^`]*)`", README.split("- **fit**", 1)[1]).group(1)
            assert quoted in capsys.readouterr().out
    capsys.readouterr()
    for made in ("run.parquet", "profile.pdf", "run.mp4"):
        assert (tmp_path / made).stat().st_size > 0, made
    # reproduce's default folder names the table, the mode and a hash of the settings, and
    # holds the sweep of its runs with the summary
    from persuasive import sweep

    (results,) = (tmp_path / "results").glob("table2-paper-*")
    assert json.loads((results / "summary.json").read_text())["seeds"] == 200
    assert len(sweep.load(results)) == 14 * 200


@pytest.mark.slow
def test_python_example_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(_block("From Python:", "python"), "README.md", "exec"), namespace)
    assert namespace["record"].outcome.first_at_line in (0, 1, 2, 3)
    assert namespace["plan"].feasible
    assert len(namespace["result"].runs) == 1400

