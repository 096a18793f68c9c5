"""One writer per output, and one meaning of ``--force`` (``persuasive._files``: issue 39 item 2).

- Every command that takes ``--out`` (and ``sumo --video``, ``recordings pairs --figure``) is
  refused while another holder has its target's lock: exit status 2, one line naming the
  target and the holder's pid, nothing written. The lock is held here, in the test process,
  with the same helper the commands use (:func:`persuasive._files.writer_lock`), so each
  refusal costs no run; one test holds it from another process and kills it.
- ``--force`` replaces a command's own earlier results and keeps every other file: a user's
  ``notes.txt`` and a subfolder survive it in every command that has the option (compare,
  reproduce, sweep, sumo, recordings logs, recordings export), and the command's own stale
  files are gone.
"""

from __future__ import annotations

import dataclasses

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from _cli import run_cli as run
from persuasive._files import (INSIDE_LOCK, OutputError, atomic_folder,
                               check_replaceable_folder, is_lock_file, writer_lock)

from test_recordings import straight, write
from test_recordings_replay import fcd_file

SMALL_GRID = """\
seeds = {seeds}

[base]
simulation.n_steps = 20

[axes]
"roles.p_a" = [0.3, 1.0]
"""


@pytest.fixture(scope="module")
def pairs_file(tmp_path_factory):
    """A pairs file of one crossing pair (``recordings pairs`` on hand-made tracks)."""
    from persuasive.cli import main

    folder = tmp_path_factory.mktemp("pairs")
    tracks = write(folder / "vehicle_tracks_000.csv",
                   straight(1, (-50.0, 0.0), 0.0, [10.0] * 100),
                   straight(2, (0.0, -60.0), 90.0, [8.0] * 120))
    path = folder / "pairs.parquet"
    assert main(["recordings", "pairs", tracks, "--out", str(path)]) == 0
    return path


def _refused(code: int, out: str, err: str, target: Path) -> None:
    assert code == 2 and out == "", err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("error: ") and repr(str(target)) in lines[0]
    assert f"is being written by another persuasive command (pid {os.getpid()})" in lines[0]


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# -- the helper ---------------------------------------------------------------------------------


def test_a_second_holder_is_refused_and_nothing_is_left_behind(tmp_path):
    target = tmp_path / "made" / "for" / "res"
    with writer_lock(target, "results folder") as lock:
        assert lock == tmp_path / "made" / "for" / ".res.persuasive.lock"
        assert lock.read_text().split() == [str(os.getpid())]
        with pytest.raises(OutputError) as info:
            with writer_lock(target, "results folder"):
                pytest.fail("a second holder got the lock")
        assert str(info.value) == (
            f"results folder {str(target)!r} is being written by another persuasive command "
            f"(pid {os.getpid()}); wait until it ends or write elsewhere")
        with writer_lock(tmp_path / "made" / "for" / "other"):  # another target: its own lock
            pass
    assert list(tmp_path.iterdir()) == []  # the lock file and the folders made for it are gone
    with writer_lock(target):  # and it can be taken again
        pass


def test_the_lock_outlives_a_folder_written_as_a_whole(tmp_path):
    target = tmp_path / "res"
    with writer_lock(target, "results folder"):
        with atomic_folder(target, owned=("*.csv",)) as tmp:
            (tmp / "a.csv").write_text("1")
        with atomic_folder(target, owned=("*.csv",)) as tmp:  # swapped as a whole again
            (tmp / "b.csv").write_text("2")
        with pytest.raises(OutputError, match="is being written by another"):
            with writer_lock(target):
                pass
    assert _listing(tmp_path) == ["res", "res/b.csv"]


def test_lock_files_are_neither_results_nor_a_users_files(tmp_path):
    """A lock file a killed command left (inside the folder, or beside it) makes no later
    run refuse, is never deleted by one, and is taken over by the next writer."""
    target = tmp_path / "res"
    target.mkdir()
    (target / INSIDE_LOCK).write_text("12345\n")
    (tmp_path / ".res.persuasive.lock").write_text("12345\n")
    assert is_lock_file(INSIDE_LOCK) and is_lock_file(".res.persuasive.lock")
    assert not is_lock_file("notes.lock") and not is_lock_file("persuasive.lock")
    check_replaceable_folder(target, force=False, owned=("*.csv",))  # not "holds other files"
    with writer_lock(target):
        with atomic_folder(target, owned=("*.csv",)) as tmp:
            (tmp / "a.csv").write_text("1")
    assert _listing(tmp_path) == ["res", f"res/{INSIDE_LOCK}", "res/a.csv"]


def test_a_killed_holder_releases_its_lock(tmp_path, capsys):
    """A real second process holds the lock: the command is refused naming that process;
    once it is killed (no cleanup runs), the command writes."""
    target = tmp_path / "figure.png"
    script = textwrap.dedent(f"""
        import sys, time
        from persuasive._files import writer_lock
        with writer_lock({str(target)!r}):
            print("held", flush=True)
            time.sleep(60)
    """)
    holder = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                              text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        code, out, err = run(capsys, "plot", "table", "--from", tmp_path / "none", "--out",
                             target)
        assert code == 2 and f"(pid {holder.pid})" in err and len(err.splitlines()) == 1
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    assert (tmp_path / ".figure.png.persuasive.lock").exists()  # left by the kill
    code, out, err = run(capsys, "plot", "table", "--from", tmp_path / "none", "--out", target)
    assert code == 2 and "is being written" not in err  # past the lock: no summary to plot
    assert not (tmp_path / ".figure.png.persuasive.lock").exists()


# -- every command that writes an --out is refused while another writes it ------------------------


def _commands(tmp_path: Path, pairs: Path, log: Path) -> dict[str, tuple[Path, list[str]]]:
    """Each command (by name) with its target and arguments; every argument passes the
    command's checks, and every input is read only after the lock (absent ones included),
    but ``fit``'s logs, which it reads before anything (check first, then compile)."""
    grid = tmp_path / "grid.toml"  # written by the test
    t = tmp_path
    return {
        "simulate": (t / "run.parquet", ["simulate", "--out", t / "run.parquet"]),
        "fit": (t / "fit.json", ["fit", log, "--out", t / "fit.json"]),  # (read first)
        "fit pairs": (t / "eval.json", ["fit", pairs, "--holdout", "0.5", "--out",
                                        t / "eval.json"]),
        "plot profile": (t / "p.png", ["plot", "profile", "--out", t / "p.png"]),
        "plot topview": (t / "t.png", ["plot", "topview", "--out", t / "t.png"]),
        "plot table": (t / "tb.png", ["plot", "table", "--from", t / "r", "--out",
                                      t / "tb.png"]),
        "plot compare": (t / "c.png", ["plot", "compare", "--from", t / "c", "--out",
                                       t / "c.png"]),
        "plot sweep": (t / "s.png", ["plot", "sweep", "--from", t / "s", "--x", "roles.p_a",
                                     "--metric", "av_first_pct", "--out", t / "s.png"]),
        "animate": (t / "a.gif", ["animate", "--out", t / "a.gif"]),
        "recordings pairs": (t / "pairs.parquet", ["recordings", "pairs", t / "tracks",
                                                   "--out", t / "pairs.parquet"]),
        "recordings pairs --figure": (t / "pair.png", ["recordings", "pairs", t / "tracks",
                                                       "--figure", t / "pair.png",
                                                       "--pair", "0"]),
        "recordings replay": (t / "replay.csv", ["recordings", "replay", pairs, "--out",
                                                 t / "replay.csv"]),
        "recordings logs": (t / "logs", ["recordings", "logs", pairs, "--out", t / "logs"]),
        "recordings export": (t / "tracks", ["recordings", "export", t / "run.parquet",
                                             "--out", t / "tracks"]),
        "compare": (t / "cmp", ["compare", "--av", "persuasive", "--hv", "lfg", "--seeds",
                                "2", "--quiet", "--out", t / "cmp"]),
        "reproduce": (t / "rep", ["reproduce", "table1", "--seeds", "2", "--quiet", "--out",
                                  t / "rep"]),
        "sweep": (t / "sw", ["sweep", grid, "--quiet", "--out", t / "sw"]),
        "sumo": (t / "sumo", ["sumo", "--episodes", "1", "--quiet", "--out", t / "sumo"]),
        "sumo --video": (t / "v.gif", ["sumo", "--episodes", "1", "--quiet", "--video",
                                       t / "v.gif"]),
        "drive": (t / "trials", ["drive", "--port", "0", "--out", t / "trials"]),
    }


COMMANDS = list(_commands(Path("x"), Path("p"), Path("l")))


@pytest.fixture(scope="module")
def log_file(tmp_path_factory):
    """A run's log (``fit`` reads its logs before anything else, the lock included)."""
    from persuasive import Config, simulate

    path = tmp_path_factory.mktemp("log") / "log.parquet"
    simulate(Config().with_overrides({"simulation.n_steps": 5}), 1).save(path)
    return path


@pytest.mark.parametrize("name", COMMANDS)
def test_a_second_writer_is_refused_in_one_line_writing_nothing(name, tmp_path, capsys,
                                                                 pairs_file, log_file,
                                                                 monkeypatch):
    from persuasive.envs import sumo as S

    monkeypatch.setattr(S, "run_study", lambda *a, **k: pytest.fail("the study started"))
    target, args = _commands(tmp_path, pairs_file, log_file)[name]
    (tmp_path / "grid.toml").write_text(SMALL_GRID.format(seeds=2))
    before = _listing(tmp_path)
    with writer_lock(target, "held by the test"):
        code, out, err = run(capsys, *args)
        _refused(code, out, err, target)
        assert _listing(tmp_path) == sorted([*before, f".{target.name}.persuasive.lock"])
    assert _listing(tmp_path) == before


def test_the_default_folders_are_locked_too(tmp_path, capsys, monkeypatch):
    """``compare`` without ``--out`` writes results/compare-<grid hash>: the same lock."""
    from persuasive.config import Config
    from persuasive.studies import compare as cmp

    monkeypatch.chdir(tmp_path)
    grid = cmp.comparison_grid(cmp.comparison_base(Config()), ["persuasive"], ["lfg"], 2)
    folder = cmp.default_folder(grid)
    with writer_lock(folder):
        code, out, err = run(capsys, "compare", "--av", "persuasive", "--hv", "lfg",
                             "--seeds", "2", "--quiet")
        _refused(code, out, err, folder)
    assert list(tmp_path.iterdir()) == []


# -- --force replaces the command's own results and keeps the rest ------------------------------


def _users_files(folder: Path) -> None:
    (folder / "notes.txt").write_text("mine")
    (folder / "sub").mkdir()
    (folder / "sub" / "keep.csv").write_text("mine too")


def _kept(folder: Path) -> bool:
    return ((folder / "notes.txt").read_text() == "mine"
            and (folder / "sub" / "keep.csv").read_text() == "mine too")


def test_export_force_keeps_a_users_files_and_replaces_its_own(tmp_path, capsys):
    steps = [(0.1 * k, [f'<vehicle id="a" x="{k:.3f}" y="0.0" angle="90.00" speed="10.0"/>'])
             for k in range(4)]
    fcd = fcd_file(tmp_path / "fcd.xml", steps)
    other = fcd_file(tmp_path / "other.xml", steps)
    out = tmp_path / "tracks"
    assert run(capsys, "recordings", "export", fcd, other, "--out", out)[0] == 0
    assert _listing(out) == ["vehicle_ids_000.csv", "vehicle_ids_001.csv",
                             "vehicle_tracks_000.csv", "vehicle_tracks_001.csv"]
    first = (out / "vehicle_tracks_000.csv").read_bytes()
    _users_files(out)
    code, text, err = run(capsys, "recordings", "export", fcd, "--out", out)
    assert code == 2 and "holds other files (notes.txt)" in err and len(err.splitlines()) == 1
    code, text, err = run(capsys, "recordings", "export", fcd, "--out", out, "--noise-m", "1",
                          "--force")
    assert code == 0, err
    assert _kept(out)
    assert _listing(out) == ["notes.txt", "sub", "sub/keep.csv", "vehicle_ids_000.csv",
                             "vehicle_tracks_000.csv"]  # the second input's files were stale
    assert (out / "vehicle_tracks_000.csv").read_bytes() != first  # the new one, with noise
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fcd.xml", "other.xml", "tracks"]


def test_logs_force_keeps_a_users_files_and_replaces_its_own(tmp_path, capsys, pairs_file):
    out = tmp_path / "logs"
    assert run(capsys, "recordings", "logs", pairs_file, "--out", out)[0] == 0
    own = _listing(out)
    assert own and all(n.endswith(".parquet") for n in own)
    _users_files(out)
    (out / "crossing-45-p00009-hv1.parquet").write_bytes(b"an earlier run's")
    code, text, err = run(capsys, "recordings", "logs", pairs_file, "--out", out, "--force")
    assert code == 0, err
    assert _kept(out) and _listing(out) == sorted([*own, "notes.txt", "sub", "sub/keep.csv"])


def test_sumo_force_keeps_a_users_files_and_replaces_its_own(tmp_path, capsys, monkeypatch):
    """SUMO's folder through the command, the study itself stubbed (it takes minutes)."""
    from persuasive.cli import sumo as sumo_cli
    from persuasive.envs import sumo as S

    @dataclasses.dataclass
    class Report:
        episodes: tuple = ()
        wall_time_s: float = 0.0

        def to_dict(self):
            return {"episodes": [], "summary": {}}

    def study(*args, **kwargs):
        folder = tmp_path / "scratch"
        folder.mkdir(exist_ok=True)
        for name in ("net.nod.xml", "net.edg.xml", "net.net.xml"):
            (folder / name).write_text(f"<{name}/>")
        return Report(), [], folder

    monkeypatch.setattr(S, "run_study", study)
    monkeypatch.setattr(S, "sumo_binaries", lambda: None)
    monkeypatch.setattr(sumo_cli, "summary_lines", lambda report: ["| new |"])
    out = tmp_path / "res"
    out.mkdir()
    _users_files(out)
    (out / "summary.md").write_text("| old |\n")
    args = ["sumo", "--episodes", "1", "--quiet", "--json", "--out", out]
    code, text, err = run(capsys, *args)
    assert code == 2 and "holds other files (notes.txt)" in err
    code, text, err = run(capsys, *args, "--force")
    assert code == 0, err
    assert _kept(out) and (out / "summary.md").read_text() == "| new |\n"
    assert _listing(out) == sorted(["notes.txt", "sub", "sub/keep.csv", *sumo_cli.OUT_FILES])


def test_sweep_force_keeps_a_users_files_and_replaces_its_own(tmp_path, capsys):
    from persuasive.sweep import load

    out = tmp_path / "sw"
    grid = tmp_path / "grid.toml"
    grid.write_text(SMALL_GRID.format(seeds=2))
    assert run(capsys, "sweep", grid, "--out", out, "--quiet", "--workers", "1")[0] == 0
    old_parts = sorted((out / "runs").iterdir())
    _users_files(out)
    (out / "runs" / "mine.txt").write_text("mine")
    grid.write_text(SMALL_GRID.format(seeds=1))
    code, text, err = run(capsys, "sweep", grid, "--out", out, "--quiet", "--workers", "1",
                          "--force")
    assert code == 0, err
    assert _kept(out) and (out / "runs" / "mine.txt").read_text() == "mine"
    assert not set(old_parts) & set((out / "runs").iterdir()) and len(load(out)) == 2


def test_compare_force_keeps_a_users_files_and_replaces_its_own(tmp_path, capsys):
    from persuasive.sweep import load

    out = tmp_path / "cmp"
    args = ["compare", "--av", "persuasive", "--hv", "lfg", "--quiet", "--workers", "1",
            "--timing-seeds", "1", "--out", out]
    assert run(capsys, *args, "--seeds", "2")[0] == 0
    _users_files(out)
    code, text, err = run(capsys, *args, "--seeds", "1", "--force")
    assert code == 0, err
    assert _kept(out) and len(load(out)) == 1
    assert json.loads((out / "summary.json").read_text())["seeds"] == 1


def test_reproduce_force_keeps_a_users_files_and_replaces_its_own(tmp_path, capsys):
    from persuasive.sweep import load

    out = tmp_path / "rep"
    args = ["reproduce", "table1", "--quiet", "--workers", "1", "--out", out]
    assert run(capsys, *args, "--seeds", "2")[0] == 0
    rows = len(load(out)) // 2
    _users_files(out)
    code, text, err = run(capsys, *args, "--seeds", "1", "--force")
    assert code == 0, err
    assert _kept(out) and len(load(out)) == rows
    assert json.loads((out / "summary.json").read_text())["seeds"] == 1


def test_a_name_the_command_does_not_own_is_never_overwritten(tmp_path):
    """A new file whose name is taken by a file the command does not own is refused before
    anything moves (only a command whose list of names is incomplete could ask it)."""
    target = tmp_path / "res"
    target.mkdir()
    (target / "notes.txt").write_text("mine")
    with pytest.raises(OutputError, match="holds 'notes.txt', which this command did not write"):
        with atomic_folder(target, owned=("*.csv",)) as tmp:
            (tmp / "a.csv").write_text("1")
            (tmp / "notes.txt").write_text("theirs")
    assert _listing(tmp_path) == ["res", "res/notes.txt"]
    assert (target / "notes.txt").read_text() == "mine"
