"""The docs' promises: every example of the guide runs as written, the configuration and grid
files it shows are valid, and every link of the README and the docs resolves.

Each page of ``docs/guide/`` runs in its own temporary folder, its blocks in order:

- a ```` ```toml ```` block whose first line is ``# NAME.toml`` is written to that file (the
  commands after it read it); every TOML block must parse;
- every line of a ```` ```sh ```` block (continued lines joined) is a command: ``persuasive
  ...`` runs through :func:`persuasive.cli.main` and must exit 0 (``persuasive drive`` is
  started as a process, its page fetched once, then stopped with Ctrl-C);
  ``python examples/...`` runs the example script; nothing else may appear, and no command may
  write into the tracked ``docs/`` folder;
- a ```` ```python ```` block runs as a script;
- other blocks (```` ```text ````) are shown, not run.

Links: every relative link and image in ``README.md`` and ``docs/**/*.md`` names an existing
file, and a ``#fragment`` names a heading of the target (GitHub's slugs).
"""

from __future__ import annotations

import glob
import os
import re
import shlex
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from persuasive.cli import main

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
GUIDE = DOCS / "guide"
PAGES = sorted(p.name for p in GUIDE.glob("*.md"))
#: Pages whose examples take more than a few seconds (simulators, servers, studies).
SLOW_PAGES = {"drive.md", "gym-and-highway-env.md", "sumo.md", "sweeps.md", "reproduce.md",
              "compare.md", "safety.md", "figures.md"}
#: The pages the guide must have (issue 23): one per command or topic, and the map.
REQUIRED_PAGES = {"index.md", "reproduce.md", "compare.md", "safety.md", "scenarios.md",
                  "sweeps.md", "drive.md", "gym-and-highway-env.md", "sumo.md", "fit.md",
                  "figures.md", "configuration.md", "benchmarks.md"}

FENCE = re.compile(r"^```([\w-]*)[^\n]*\n(.*?)^```", re.S | re.M)


def blocks(text: str) -> list[tuple[str, str]]:
    """The fenced blocks of a Markdown text, in order: ``(language, body)``."""
    return [(m.group(1), m.group(2)) for m in FENCE.finditer(text)]


def commands(body: str) -> list[str]:
    """The command lines of a shell block: continued lines joined, comments and blanks out."""
    out = []
    for line in body.replace("\\\n", " ").splitlines():
        words = shlex.split(line, comments=True)
        if words:
            out.append(line)
    return out


def _expand(words: list[str], cwd: Path) -> list[str]:
    """Shell globbing of the words that hold a ``*`` (relative to ``cwd``), sorted."""
    out = []
    for word in words:
        if "*" in word:
            found = sorted(glob.glob(word, root_dir=cwd))
            assert found, f"{word!r} matches no file"
            out.extend(found)
        else:
            out.append(word)
    return out


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT / "src"),
                                                      env.get("PYTHONPATH")]))
    return env


def _run_drive(argv: list[str], cwd: Path) -> None:
    """Start ``persuasive drive`` as a process, fetch its page once, stop it with Ctrl-C."""
    proc = subprocess.Popen([sys.executable, "-m", "persuasive", *argv], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=_env())
    try:
        url = None
        for line in proc.stdout:
            match = re.search(r"open (http://\S+)", line)
            if match:
                url = match.group(1)
                break
        assert url, f"drive printed no URL; stderr: {proc.stderr.read()[-2000:]}"
        deadline = time.monotonic() + 60
        while True:  # the URL is printed just before the server starts serving
            try:
                with urllib.request.urlopen(url, timeout=10) as response:
                    assert response.status == 200
                break
            except OSError:
                assert time.monotonic() < deadline, f"{url} did not answer"
                time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err[-2000:]  # Ctrl-C's status, the drive's too
        assert "stopped;" in out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def run_command(line: str, cwd: Path) -> None:
    """Run one command line of a guide page in ``cwd`` (see the module docstring)."""
    words = shlex.split(line, comments=True)
    assert not any(w == "docs" or w.startswith("docs/") or "/docs/" in w or "=docs/" in w
                   for w in words), f"{line!r} writes into the tracked docs/ folder"
    if words[0] == "persuasive":
        argv = _expand(words[1:], cwd)
        if argv[0] == "drive":
            _run_drive(argv, cwd)
            return
        assert main(argv) == 0, line
    elif words[0] == "python" and words[1].startswith("examples/"):
        script = ROOT / words[1]
        assert script.is_file(), line
        done = subprocess.run([sys.executable, str(script), *_expand(words[2:], cwd)],
                              cwd=cwd, env=_env(), capture_output=True, text=True,
                              timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
    else:
        raise AssertionError(f"{line!r}: a guide's shell blocks hold only persuasive and "
                             "python examples/... commands (show others as ```text)")


def run_page(name: str, cwd: Path) -> int:
    """Run every block of a guide page in ``cwd``; the number of commands and scripts run."""
    import tomllib

    ran = 0
    for lang, body in blocks((GUIDE / name).read_text(encoding="utf-8")):
        if lang == "toml":
            tomllib.loads(body)
            first = body.splitlines()[0] if body.strip() else ""
            match = re.fullmatch(r"#\s*([\w.-]+\.toml)\s*", first)
            if match:
                (cwd / match.group(1)).write_text(body, encoding="utf-8")
        elif lang == "sh":
            for line in commands(body):
                run_command(line, cwd)
                ran += 1
        elif lang == "python":
            namespace: dict = {"__name__": "__docs__"}
            exec(compile(body, str(GUIDE / name), "exec"), namespace)
            ran += 1
    return ran


def test_the_guide_has_its_pages_and_the_index_links_them():
    assert REQUIRED_PAGES <= set(PAGES)
    index = (GUIDE / "index.md").read_text(encoding="utf-8")
    for name in PAGES:
        if name != "index.md":
            assert f"]({name})" in index, f"docs/guide/index.md does not link {name}"
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "](docs/guide/index.md)" in readme


@pytest.mark.parametrize("name", [
    pytest.param(name, marks=pytest.mark.slow) if name in SLOW_PAGES else name
    for name in PAGES])
def test_guide_examples_run(name, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    ran = run_page(name, tmp_path)
    capsys.readouterr()
    if name != "index.md":
        assert ran, f"docs/guide/{name} has no example"


def test_configuration_and_grid_examples_are_valid(tmp_path):
    """The configuration file of the configuration guide and the example grid of the sweeps
    guide say what they claim (they were the README's; the README now links them)."""
    import tomllib

    from persuasive import Config, sweep

    config_toml = next(body for lang, body in
                       blocks((GUIDE / "configuration.md").read_text(encoding="utf-8"))
                       if lang == "toml")
    config = Config.from_dict(tomllib.loads(config_toml))
    assert (config.mode, config.hv.kind, config.scenario.kind) == ("corrected", "idm", "crossing")
    assert config.vehicle_of("hv").length_m == 4.5
    grid_toml = next(body for lang, body in
                     blocks((GUIDE / "sweeps.md").read_text(encoding="utf-8"))
                     if lang == "toml")
    grid_file = tmp_path / "grid.toml"
    grid_file.write_text(grid_toml)
    grid = sweep.Grid.from_toml(grid_file)
    runs = list(grid.runs())
    assert len(runs) == 4 * 5 * 200
    # the guide shows the example grid file as it is
    assert runs == list(sweep.Grid.from_toml(ROOT / "examples" / "sweep-persuasion.toml").runs())


# -- links -----------------------------------------------------------------------------------

MARKDOWN = [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(([^()\s]+)(?:\s+\"[^\"]*\")?\)")


def _prose(text: str) -> str:
    """``text`` without fenced blocks and inline code spans (links there are not links)."""
    text = FENCE.sub("", text)
    return re.sub(r"`[^`\n]*`", "", text)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: link texts kept, lower case, punctuation dropped, spaces
    to hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip())
    text = text.lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file (repeated headings get ``-1``, ``-2``, ...)."""
    seen: dict[str, int] = {}
    out = set()
    for line in FENCE.sub("", path.read_text(encoding="utf-8")).splitlines():
        match = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not match:
            continue
        base = slug(match.group(1))
        n = seen.get(base, 0)
        out.add(base if n == 0 else f"{base}-{n}")
        seen[base] = n + 1
    return out


def test_slugs_are_githubs():
    assert slug("9. Paper mode and corrected mode (quirks Q1-Q7)") == \
        "9-paper-mode-and-corrected-mode-quirks-q1-q7"
    assert slug("13.9 Online `p_a`: a grid posterior in the planner") == \
        "139-online-p_a-a-grid-posterior-in-the-planner"
    assert slug("Baselines and other humans (`compare`)") == "baselines-and-other-humans-compare"


@pytest.mark.parametrize("path", MARKDOWN, ids=[str(p.relative_to(ROOT)) for p in MARKDOWN])
def test_every_link_resolves(path):
    broken = []
    for target in LINK.findall(_prose(path.read_text(encoding="utf-8"))):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        file_part, _, fragment = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        if not dest.exists():
            broken.append(f"{target}: no such file")
        elif fragment and dest.suffix == ".md" and fragment not in anchors(dest):
            broken.append(f"{target}: no heading #{fragment} in {dest.relative_to(ROOT)}")
    assert not broken, f"{path.relative_to(ROOT)}: " + "; ".join(broken)


def test_install_lines_name_the_checkout():
    """``persuasive`` is not on a registry: installs are from the checkout (``pip install -e``)."""
    for path in MARKDOWN:
        text = path.read_text(encoding="utf-8")
        assert not re.search(r"pip install\s+['\"]?persuasive", text), \
            f"{path.relative_to(ROOT)}: install from the checkout, pip install -e '.[extra]'"


def test_readme_stays_a_front_page():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 260, \
        f"README.md has {len(lines)} lines; measured tables go to docs/results.md"
