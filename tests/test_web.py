"""``persuasive drive``: the study page in a real browser, the server's defences, the study logic.

The browser tests drive Debian's ``chromium`` (``/usr/bin/chromium``) with Playwright; the
server runs in this process, in a background thread, on a free loopback port (the token test
starts ``persuasive drive`` as a user would, in a subprocess). Trials are short
(``simulation.n_steps = 30``, 3 s, no countdown). Without chromium the browser tests fail in CI
(``CI`` set; ``.ci/run`` installs it) and are skipped with the reason elsewhere.

``python tests/test_web.py --screenshot docs/drive-screenshot.png`` writes the README's
screenshot of the page mid-trial.
"""

from __future__ import annotations

import http.client
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from persuasive.config import ConfigError
from persuasive.web.human import HumanInput, command_of
from persuasive.web.scene import poses, scene_of
from persuasive.web.study import (balanced_latin_square, default_study, load_study,
                                  participant_index, sanitize_participant, study_from_dict)

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run"]
N_STEPS = 30

STUDY_TOML = f"""
title = "Test study"
seed = 3
countdown_s = 0
consent = "This is a test. Nothing is real."

[base]
mode = "corrected"
simulation.n_steps = {N_STEPS}
scenario.hv_s0_halfwidth_m = 0.0
scenario.hv_v0_halfwidth_mps = 0.0

[practice]
enabled = false

[[conditions]]
name = "persuasive"
set = {{ "av.kind" = "persuasive" }}

[[conditions]]
name = "passive"
set = {{ "av.kind" = "passive", "scenario.hv_s0_m" = -22.0 }}

[[questions]]
id = "safe"
text = "I felt safe."
scale = 5
low = "not at all"
high = "completely"
"""

#: Columns of the persuasive planner's log: present and non-null on every step of a trial.
MPC_COLUMNS = ("av_trajectory", "av_feasible", "av_n_feasible", "av_p_safe_min",
               "av_expected_reward", "av_belief_hv_leader", "av_belief_hv_follower")


# -- fixtures -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def study_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("study") / "study.toml"
    path.write_text(STUDY_TOML)
    return path


@pytest.fixture(scope="module")
def server(study_file, tmp_path_factory):
    """The drive server on a free loopback port, in a background thread."""
    from persuasive.web.server import DriveServer, bind, create_app, warm_up

    out = tmp_path_factory.mktemp("trials")
    study = load_study(study_file)
    warm_up(study)
    app = create_app(study, out)
    srv = DriveServer(app, bind("127.0.0.1", 0)).start()
    srv.out = out
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def browser():
    """Headless Debian chromium driven by Playwright (never Playwright's own download)."""
    problem = None
    if not os.access(CHROMIUM, os.X_OK):
        problem = (f"{CHROMIUM} is missing: install Debian's chromium (apt-get install -y "
                   "chromium; .ci/run does)")
    else:
        try:
            from playwright.sync_api import sync_playwright
        except ImportError:
            problem = "playwright is missing: pip install -e '.[test]'"
    if problem:
        if os.environ.get("CI"):
            pytest.fail(f"browser tests cannot run: {problem}", pytrace=False)
        pytest.skip(f"browser tests need chromium: {problem}")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


def _summary(out: Path, participant: str, until=lambda s: True, timeout_s: float = 10.0):
    """The participant's study summary, once ``until(summary)`` holds."""
    path = out / f"{participant}.json"
    t_end = time.monotonic() + timeout_s
    while True:
        if path.exists():
            summary = json.loads(path.read_text())
            if until(summary):
                return summary
        if time.monotonic() > t_end:
            raise AssertionError(f"{path} never satisfied the condition: "
                                 f"{path.read_text() if path.exists() else 'missing'}")
        time.sleep(0.05)


def _begin(page, url: str, participant: str) -> None:
    page.goto(f"{url}?participant={participant}")
    page.get_by_test_id("consent").check()
    page.get_by_test_id("begin").click()
    page.get_by_test_id("start").wait_for()


def _wait_clock(page, t_s: float, timeout_s: float = 20.0) -> None:
    """Wait until the page's clock shows ``t_s`` (polled from Python: the page's
    Content-Security-Policy forbids the string evaluation ``wait_for_function`` uses)."""
    clock = page.get_by_test_id("clock")
    t_end = time.monotonic() + timeout_s
    while float(clock.inner_text().split()[0] or 0) < t_s:
        assert time.monotonic() < t_end, f"the clock never reached {t_s} s"
        time.sleep(0.02)


def _frames(page) -> list[str]:
    """Every websocket frame the page receives, as text (for the blinding check)."""
    frames: list[str] = []
    page.on("websocket", lambda ws: ws.on("framereceived", lambda payload: frames.append(
        payload if isinstance(payload, str) else repr(payload))))
    return frames


# -- 1. a whole trial in the browser ------------------------------------------------------------


def test_holding_arrow_up_drives_a_whole_recorded_trial(server, browser, tmp_path):
    from persuasive.cli import main
    from persuasive.simulation import load_record, simulate

    page = browser.new_page(viewport={"width": 1000, "height": 700})
    frames = _frames(page)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    _begin(page, server.url, "P01")
    assert page.get_by_test_id("ready").inner_text().count("Condition") == 1
    page.get_by_test_id("start").click()
    page.keyboard.down("ArrowUp")
    page.get_by_test_id("trial-done").wait_for(timeout=20_000)
    page.keyboard.up("ArrowUp")

    summary = _summary(server.out, "P01", lambda s: s["trials"])
    # P01: row 1 of the 2x2 balanced square puts the second condition first
    assert summary["order"] == ["passive", "persuasive"] and summary["latin_square_row"] == 1
    entry = summary["trials"][0]
    assert entry["complete"] and entry["steps"] == N_STEPS
    assert entry["file"] == "P01-t00-passive.parquet"
    path = server.out / entry["file"]
    record = load_record(path)
    frame = record.frame()
    assert len(frame) == N_STEPS and record.config.av.kind == "passive"
    # the person's throttle reached the HV on (nearly) every step
    assert (frame["hv_accel_mps2"] > 0).mean() >= 0.8
    assert frame["hv_key_up"].mean() >= 0.8 and set(frame["hv_input_source"]) <= {
        "none", "keyboard"}
    np.testing.assert_array_equal(frame["hv_accel_mps2"], frame["hv_command_mps2"])
    # the AV's planner decided at every step
    for column in MPC_COLUMNS:
        assert column in frame and frame[column].notna().all(), column
    # every step's latency and compute time were measured
    for column in ("step_latency_ms", "step_compute_ms", "tick_late_ms"):
        assert np.isfinite(frame[column]).all() and (frame[column] >= 0).all(), column
    assert frame["step_latency_ms"].median() < 50.0
    # the trial replays bit for bit with the replay human, and plots like a simulated run
    again = simulate(record.config.with_overrides({"hv.kind": "replay",
                                                  "hv.replay.file": str(path)}), record.seed)
    np.testing.assert_array_equal(again.states, record.states)
    out_png = tmp_path / "topview.png"
    assert main(["plot", "topview", "--from", str(path), "--out", str(out_png)]) == 0
    assert out_png.stat().st_size > 10_000

    # the questionnaire, then the next (blinded) condition
    page.get_by_test_id("q-safe-4").check()
    page.get_by_test_id("next").click()
    page.get_by_test_id("start").wait_for()
    assert "Condition A" in page.get_by_test_id("ready").inner_text()
    summary = _summary(server.out, "P01", lambda s: s["trials"][0].get("answers"))
    assert summary["trials"][0]["answers"] == {"safe": 4}
    # the page never learns which AV it faces
    text = page.inner_text("body") + "".join(frames)
    assert frames and not re.search(r"persuasive|passive|av\.kind|yield", text)
    assert errors == []
    page.close()


# -- 2. garbage on the websocket, path traversal over HTTP --------------------------------------

GARBAGE = [
    "not json", "", "{", "[]", "null", "42", '"input"', "{}", '{"type": 7}',
    '{"type": "teleport", "x": 1}', '{"type": "input"}',
    '{"type": "input", "up": "yes", "down": false, "axis": null, "source": "keyboard"}',
    '{"type": "input", "up": true, "down": false, "axis": 5, "source": "keyboard"}',
    '{"type": "input", "up": true, "down": false, "axis": null, "source": "x", "extra": 1}',
    '{"type": "input", "up": true, "down": false, "axis": 1e999, "source": "keyboard"}',
    '{"type": "start"}',  # out of turn: a trial is running
    '{"type": "begin", "participant": "../../etc/passwd", "consent": true}',  # out of turn
    '{"type": "answers", "trial": 99, "answers": {}}',  # out of turn
    "[" * 3000,  # nesting deep enough to break a naive parser
    "x" * 20_000,  # over the size limit
]

TRAVERSALS = ["/static/../pyproject.toml", "/static/..%2f..%2fpyproject.toml",
              "/%2e%2e/pyproject.toml", "/static/%2e%2e/%2e%2e/pyproject.toml",
              "/../../../../etc/passwd", "//etc/passwd", "/static//etc/passwd",
              "/static/drive.js/../../pyproject.toml", "/static/index.html/..",
              "/static/", "/static/__init__.py", "/static/../session.py", "/etc/passwd",
              "/static/%2fetc%2fpasswd", "/static/C:%5cwindows%5cwin.ini"]


def _get(port: int, target: str, headers: dict | None = None) -> tuple[int, bytes, dict]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
    try:
        conn.putrequest("GET", target, skip_host=True, skip_accept_encoding=True)
        for k, v in {"Host": f"127.0.0.1:{port}", **(headers or {})}.items():
            conn.putheader(k, v)
        conn.endheaders()
        resp = conn.getresponse()
        return resp.status, resp.read(), dict(resp.getheaders())
    finally:
        conn.close()


def test_garbage_messages_and_path_traversal_are_refused(server, browser):
    port = server.port
    status, body, headers = _get(port, "/static/drive.js")
    assert status == 200 and b"WebSocket" in body
    assert "script-src 'self'" in headers["content-security-policy"]
    for target in TRAVERSALS + [f"http://127.0.0.1:{port}/../pyproject.toml"]:
        status, body, _ = _get(port, target)
        assert status == 404, (target, status)
        assert b"build-system" not in body and b"root:" not in body
    # a page of another origin may not open the study's websocket; another Host is refused
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    with pytest.raises(InvalidStatus) as refused:
        connect(f"ws://127.0.0.1:{port}/ws", origin="http://evil.example", open_timeout=5)
    assert refused.value.response.status_code == 403
    assert _get(port, "/", {"Host": "evil.example"})[0] == 403

    page = browser.new_page()
    page.add_init_script("""
        window.__sockets = [];
        const Native = window.WebSocket;
        window.WebSocket = function (...args) {
            const s = new Native(...args); window.__sockets.push(s); return s; };
        window.WebSocket.prototype = Native.prototype;
        window.WebSocket.OPEN = Native.OPEN;
    """)
    _begin(page, server.url, "P02")
    page.get_by_test_id("start").click()
    page.keyboard.down("ArrowUp")
    time.sleep(0.3)
    page.evaluate("""(garbage) => {
        const s = window.__sockets[0];
        for (const g of garbage) s.send(g);
        s.send(new Uint8Array([0, 255, 1, 2]).buffer);
    }""", GARBAGE)
    page.get_by_test_id("trial-done").wait_for(timeout=20_000)
    page.keyboard.up("ArrowUp")
    summary = _summary(server.out, "P02", lambda s: s["trials"])
    dropped = summary["dropped_messages"]
    assert sum(dropped.values()) == len(GARBAGE) + 1, dropped
    assert dropped["out-of-order"] == 3 and dropped["binary"] == 1
    assert dropped["too-large"] == 1 and dropped["not-json"] >= 4
    entry = summary["trials"][0]
    assert entry["complete"] and entry["steps"] == N_STEPS
    assert entry["dropped_messages"] == len(GARBAGE) + 1
    assert sorted(p.name for p in server.out.glob("P02*")) == [
        "P02-t00-persuasive.parquet", "P02.json"]
    page.close()


# -- 3. a non-loopback bind needs the token; Ctrl-C saves open trials ---------------------------


def test_non_loopback_bind_requires_the_token_and_ctrl_c_saves_open_trials(
        study_file, tmp_path):
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    from persuasive.web.server import create_app

    with pytest.raises(ConfigError, match="not a loopback address.*token"):
        create_app(load_study(study_file), tmp_path, token=None, host="0.0.0.0")

    out = tmp_path / "trials"
    proc = subprocess.Popen(
        [sys.executable, "-m", "persuasive", "drive", "--host", "0.0.0.0", "--port", "0",
         "--study", str(study_file), "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = ""
        t_end = time.monotonic() + 60
        while "token=" not in line:
            line = proc.stdout.readline()
            assert line or proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < t_end, "no URL printed"
        m = re.search(r"http://[^:/]+:(\d+)/\?token=([A-Za-z0-9_-]+)", line)
        assert m, line
        port, token = int(m.group(1)), m.group(2)
        assert len(token) >= 32
        for target in ("/", "/?token=wrong", "/static/drive.js", f"/?token={token[:-1]}",
                       "/static/../pyproject.toml"):
            assert _get(port, target)[0] == 403, target
        status, body, _ = _get(port, f"/?token={token}")
        assert status == 200 and f"drive.js?token={token}".encode() in body
        assert _get(port, f"/static/drive.js?token={token}")[0] == 200
        assert _get(port, f"/static/../x?token={token}")[0] == 404
        with pytest.raises(InvalidStatus) as refused:
            connect(f"ws://127.0.0.1:{port}/ws", open_timeout=5)
        assert refused.value.response.status_code == 403

        # a participant mid-trial when the researcher presses Ctrl-C
        with connect(f"ws://127.0.0.1:{port}/ws?token={token}", open_timeout=5) as ws:
            assert json.loads(ws.recv(5))["type"] == "welcome"
            ws.send(json.dumps({"type": "begin", "participant": "P/3 x", "consent": True}))
            ws.send(json.dumps({"type": "start"}))
            seen = 0
            while seen < 8:
                if json.loads(ws.recv(5))["type"] == "state":
                    seen += 1
            proc.send_signal(signal.SIGINT)
            code = proc.wait(20)
        out_text, err_text = proc.communicate()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert code == 130, err_text  # stopped by Ctrl-C, as every command: 130 (issue 39)
    assert "warning: listening on 0.0.0.0, not a loopback address" in err_text
    assert "stopped; 1 trial file" in out_text
    summary = json.loads((out / "P_3_x.json").read_text())
    assert summary["participant"] == "P_3_x" and summary["ended"] == "server-shutdown"
    entry = summary["trials"][0]
    assert not entry["complete"] and entry["file"].endswith("-partial.parquet")
    assert 8 <= entry["steps"] < N_STEPS


# -- 4. the browser closes mid-trial ------------------------------------------------------------


def test_closing_the_browser_mid_trial_keeps_a_partial_trial(server, browser):
    """The person brakes with a gamepad's left trigger half pressed, then the browser closes."""
    from persuasive.simulation import load_record

    context = browser.new_context()
    context.add_init_script("""
        const pad = {id: "test pad", index: 0, connected: true, mapping: "standard",
                     timestamp: 0, axes: [0, 0, 0, 0],
                     buttons: Array.from({length: 17}, (_, i) =>
                         ({pressed: i === 6, touched: i === 6, value: i === 6 ? 0.5 : 0}))};
        Object.defineProperty(navigator, "getGamepads", {value: () => [pad, null, null, null]});
    """)
    page = context.new_page()
    _begin(page, server.url, "P04")
    page.get_by_test_id("start").click()
    _wait_clock(page, 1.0)
    context.close()
    summary = _summary(server.out, "P04", lambda s: s["trials"] and s["ended"])
    assert summary["ended"] == "disconnected" and not summary["complete"]
    entry = summary["trials"][0]
    assert not entry["complete"] and entry["file"] == "P04-t00-persuasive-partial.parquet"
    assert 8 <= entry["steps"] < N_STEPS
    record = load_record(server.out / entry["file"])
    assert len(record.frame()) == entry["steps"]
    frame = record.frame()
    assert (frame["hv_input_source"] == "gamepad").all() and (frame["hv_axis"] == -0.5).all()
    assert (frame["hv_accel_mps2"] == -1.0).all()  # half of u_min = -2 m/s^2


# -- 4b. who drove a trial: stored in it --------------------------------------------------------


def test_each_trial_stores_its_participant_so_a_renamed_trial_stays_theirs(tmp_path):
    """Two sessions of one participant ID (the second one's files are ``P05-2-...``), run
    through the session's own protocol: each trial's metadata names the participant and the
    session, and ``persuasive fit`` reads the participant from there, not from the name."""
    import asyncio
    import shutil
    import tomllib
    from concurrent.futures import ThreadPoolExecutor

    import pyarrow.parquet as pq

    from persuasive.fitting import read_log
    from persuasive.record import RECORD_METADATA
    from persuasive.web.session import Hub, Session

    data = tomllib.loads(STUDY_TOML)
    data["base"]["simulation"]["n_steps"] = 3  # 0.3 s a trial
    hub = Hub(study_from_dict(data), tmp_path)

    async def session(participant: str) -> Session:
        async def send(text: str) -> None:
            pass

        s = Session(hub, send)
        s.start()
        s.receive(json.dumps({"type": "begin", "participant": participant, "consent": True}))
        s.receive(json.dumps({"type": "start"}))
        await s.trial_task
        await s.close()
        return s

    async def both():
        return [await session("P05"), await session("P05")]

    # a thread of its own: the browser tests leave Playwright's event loop running in this one
    with ThreadPoolExecutor(max_workers=1) as pool:
        first, second = pool.submit(asyncio.run, both()).result()
    assert (first.stem, second.stem) == ("P05", "P05-2")
    for s in (first, second):
        name = s.entries[0]["file"]
        assert name.startswith(f"{s.stem}-t00-")
        record = json.loads(pq.read_schema(tmp_path / name).metadata[RECORD_METADATA])
        assert record["trial"] == {"participant": "P05", "session": s.stem, "index": 0,
                                   "condition": s.entries[0]["condition"],
                                   "practice": False, "complete": True}
        # renamed as someone else's trial, or to no trial name at all: still P05's
        for other in ("Q99-t01-renamed.parquet", "anything.parquet"):
            shutil.copy(tmp_path / name, tmp_path / other)
            assert read_log(tmp_path / other).participant == "P05"
        assert read_log(tmp_path / name).participant == "P05"  # its name says "P05-2"


# -- 5. counterbalancing and the study file ------------------------------------------------------


@pytest.mark.parametrize("n", range(1, 9))
def test_balanced_latin_square(n):
    rows = np.array(balanced_latin_square(n))
    per = 1 if n % 2 == 0 or n == 1 else 2
    assert rows.shape == (per * n, n)
    for row in rows:  # each condition once per row
        assert sorted(row) == list(range(n))
    for col in rows.T:  # each condition equally often at each position
        assert np.bincount(col, minlength=n).tolist() == [per] * n
    if n > 1:  # carry-over: each ordered pair adjacent equally often
        pairs = np.zeros((n, n), int)
        for row in rows:
            for a, b in zip(row[:-1], row[1:]):
                pairs[a, b] += 1
        assert (pairs[~np.eye(n, dtype=bool)] == per).all() and np.trace(pairs) == 0


def test_participants_walk_the_rows_of_the_square():
    study = default_study()
    rows = study.rows
    assert len(rows) == 4
    orders = [study.order_for(f"P{i:02d}") for i in range(1, 9)]
    assert [row for row, _ in orders] == [1, 2, 3, 0, 1, 2, 3, 0]
    for row, conditions in orders:
        assert [study.conditions.index(c) for c in conditions] == list(rows[row])
    # over any four consecutive participants every condition takes every position once
    positions = np.array([[c.name for c in conds] for _, conds in orders[:4]])
    for col in positions.T:
        assert len(set(col)) == 4
    # IDs without a number get a stable row from their hash
    assert participant_index("alice") == participant_index("alice") != participant_index("bob")
    assert sanitize_participant(" P 7/../x ") == "P_7____x"
    with pytest.raises(ConfigError, match="letter or digit"):
        sanitize_participant("../")


def test_study_file_errors_name_the_field(tmp_path):
    import tomllib

    base = tomllib.loads(STUDY_TOML)
    for change, message in [
        ({"colour": "red"}, "unknown key 'colour'"),
        ({"consent": " "}, "consent is required"),
        ({"countdown_s": -1}, r"countdown_s = -1 is out of range"),
        ({"conditions": [{"name": "a b", "set": {}}]}, r"conditions\[0\]\.name"),
        ({"conditions": [{"name": "x", "set": {"av": {"kind": "teleport"}}}]},
         r"conditions\[0\] \(x\): av.kind = 'teleport' is out of range"),
        ({"conditions": [{"name": "x", "set": {"scenario.hv_s0_m": -3.0}}]},
         r"scenario.hv_s0_m = -3"),
        ({"questions": [{"id": "q", "text": "t", "scale": 1}]}, r"questions\[0\]\.scale"),
    ]:
        with pytest.raises(ConfigError, match=message):
            study_from_dict({**base, **change})
    consent = study_from_dict({**base, "consent": "One\nparagraph.\n\n  Two.  \n"}).consent
    assert consent == "One paragraph.\n\nTwo."
    bad = tmp_path / "bad.toml"
    bad.write_text("title = ")
    with pytest.raises(ConfigError, match="bad.toml.*not valid TOML"):
        load_study(bad)


def test_drive_command_bad_input_is_one_line_and_exit_2(capsys, tmp_path, study_file):
    import socket

    from persuasive.cli import main

    assert main(["drive", "--study", str(tmp_path / "missing.toml")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: study file") and "cannot be read" in err
    assert err.count("\n") == 1
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        assert main(["drive", "--study", str(study_file), "--port", str(port),
                     "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err == f"error: cannot listen on 127.0.0.1:{port}: address already in use\n"
    assert not (tmp_path / "out").exists()  # nothing made before the server could start


def test_drive_that_cannot_start_creates_nothing(capsys, tmp_path, study_file):
    import os
    import socket

    from persuasive.cli import main

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        cases = [(["--port", str(port)], "address already in use"),
                 (["--host", "no-such-host.invalid"], "--host 'no-such-host.invalid' cannot "
                                                      "be resolved"),
                 # an address that is not this machine's (TEST-NET-1)
                 (["--host", "192.0.2.1"], "cannot listen on 192.0.2.1:8765: cannot assign "
                                           "requested address")]
        if os.geteuid() != 0:  # a port below 1024 needs privileges
            cases.append((["--port", "1"], "cannot listen on 127.0.0.1:1: permission denied"))
        for args, message in cases:
            out = tmp_path / "trials" / "here"
            code = main(["drive", "--study", str(study_file), "--out", str(out), *args])
            err = capsys.readouterr().err
            assert code == 2 and err.startswith("error: ") and message in err, err
            assert err.count("\n") == 1
            assert not (tmp_path / "trials").exists()


def test_commands_from_the_controls():
    u_min, u_max = -2.0, 1.0
    assert command_of(HumanInput(), u_min, u_max) == 0.0  # coast
    assert command_of(HumanInput(up=True), u_min, u_max) == 1.0
    assert command_of(HumanInput(down=True), u_min, u_max) == -2.0
    assert command_of(HumanInput(up=True, down=True), u_min, u_max) == -2.0  # brake wins
    assert command_of(HumanInput(axis=0.5), u_min, u_max) == 0.5
    assert command_of(HumanInput(axis=-0.5), u_min, u_max) == -1.0


@pytest.mark.parametrize("kind", ["intersection", "crossing", "left-turn", "merge"])
def test_every_scenario_has_a_scene_to_draw(kind):
    """The scene the page draws holds the roads, lines and vehicles where the scenario's paths
    put them (drawn to scale by the page from these numbers alone)."""
    from persuasive.config import Config
    from persuasive.world import PythonWorld
    from persuasive.web.human import LiveHuman

    overrides = {"scenario.kind": kind, "simulation.n_steps": N_STEPS}
    if kind == "crossing":
        overrides["scenario.angle_deg"] = 60.0
    world = PythonWorld(Config(mode="corrected").with_overrides(overrides), 1, hv=LiveHuman())
    scene = json.loads(json.dumps(scene_of(world.scenario, world.states[0], N_STEPS)))
    x_lo, y_lo, x_hi, y_hi = scene["view"]
    pose = poses(world.scenario, world.states[0])
    assert scene["lane_width_m"] == 4.0 and scene["min_dist_m"] == 7.5
    cx, cy = scene["conflict"]
    assert x_lo < cx < x_hi and y_lo < cy < y_hi
    for who in ("av", "hv"):
        vehicle = scene["vehicles"][who]
        path = np.array(vehicle["path"])
        x, y, heading, v = pose[who]
        assert x_lo < x < x_hi and y_lo < y < y_hi  # the start is in view
        assert v == pytest.approx(world.states[0, 1 if who == "av" else 3], abs=1e-3)
        # the vehicle and its lines lie on its road, across it
        assert np.hypot(*(path - [x, y]).T).min() < 0.3
        near = np.argmin(np.hypot(*(path - [x, y]).T))
        d = path[min(near + 1, len(path) - 1)] - path[max(near - 1, 0)]
        assert abs(np.arctan2(d[1], d[0]) - heading) < 0.05
        kinds = [line["kind"] for line in vehicle["lines"]]
        assert kinds[0] == "crossing" and (kind == "merge") == ("yield" in kinds)
        for line in vehicle["lines"]:
            assert np.hypot(*(path - [line["x"], line["y"]]).T).min() < 0.3
            assert abs(np.hypot(line["nx"], line["ny"]) - 1.0) < 1e-5
        # the road reaches past where the vehicle can get to in the trial
        assert path.shape[0] > 100 and len(json.dumps(vehicle["path"])) < 60_000


# -- the README's screenshot ----------------------------------------------------------------------


def screenshot(out: str, at_s: float = 2.6) -> None:
    """Write a screenshot of the page mid-trial (the default study, accelerating) to ``out``."""
    import tempfile

    from playwright.sync_api import sync_playwright

    from persuasive.web.server import DriveServer, bind, create_app, warm_up

    study = default_study()
    warm_up(study)
    with tempfile.TemporaryDirectory() as tmp:
        srv = DriveServer(create_app(study, tmp), bind("127.0.0.1", 0)).start()
        try:
            with sync_playwright() as p:
                b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
                page = b.new_page(viewport={"width": 1200, "height": 760})
                _begin(page, srv.url, "P04")  # row 0: the persuasive AV, person near
                page.get_by_test_id("start").click()  # practice (yielding AV)
                page.get_by_test_id("trial-done").wait_for(timeout=30_000)
                page.get_by_test_id("next").click()
                page.get_by_test_id("start").click()
                page.keyboard.down("ArrowUp")
                _wait_clock(page, at_s)
                page.screenshot(path=out)
                page.keyboard.up("ArrowUp")
                b.close()
        finally:
            srv.stop()


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--screenshot":
        screenshot(sys.argv[2])
    else:
        sys.exit("usage: python tests/test_web.py --screenshot docs/drive-screenshot.png")
