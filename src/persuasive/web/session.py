"""One participant's session: the protocol, the trials, the server's clock, what is saved.

A session is one websocket connection (``persuasive.web.server``); it runs as its own asyncio
task, and each trial as another, so a slow or stalled client holds up only its own messages.

**Protocol** (JSON text messages; :data:`CLIENT_MESSAGES` lists what the page may send):

====================  ===========================================================================
server -> page        when
====================  ===========================================================================
``welcome``           on connect: study title and consent text
``plan``              after ``begin``: the participant's trials by their blinded labels
``ready``             before each trial (its label, number, total)
``scene``             at trial start: geometry (``persuasive.web.scene``), initial poses,
                      countdown
``state``             each step: ``j`` (state index), ``t`` [s], each vehicle's ``[x, y,
                      heading, v]``, ``ts`` (the tick's ``time.monotonic()``), and the AV's belief
                      that the person leads only if the study says ``show_belief``
``done``              the trial is saved; whether questions follow
``finished``          every trial done
``error``             a refused ``begin`` (with ``field``), or a trial that failed on the server
====================  ===========================================================================

page -> server: ``begin {participant, consent: true}``, ``start {}``, ``input {up, down, axis,
source[, seq]}`` (any time; the latest one counts), ``answers {trial, answers: {id: 1..scale}}``
(after every trial, ``{}`` when no questions apply). Anything else (not JSON, not an object,
an unknown type, unknown or ill-typed fields, over :data:`MAX_MESSAGE_CHARS`, binary, or a
message out of turn) is dropped and counted by reason in the summary; it never ends the
session.

**The clock.** The server is the clock: step ``k`` runs at ``T0 + k dt`` with the person's
latest input as the HV's acceleration (``persuasive.web.human``) and the AV's planner
deciding as in ``persuasive simulate`` (:class:`persuasive.world.PythonWorld`); the new state is
then queued for the page. A step takes well under a millisecond, so it runs in the event loop;
building a trial's world and writing files run in worker threads. When the loop falls behind
by more than a step, the schedule restarts from now instead of running a burst of steps.

**Files** (in the output folder; names come from the server only: the participant ID
sanitized to ``[A-Za-z0-9_-]``, a suffix ``-2``, ``-3``, ... when that ID already has a session
there, the trial index and the condition's name):

- ``<id>-tNN-<condition>.parquet``: a trial (``RunRecord.save``: the per-step log of
  ``simulate --out`` with its metadata, so ``plot --from``, ``animate --from`` and the
  ``replay`` human read it; the metadata also holds ``trial``: the participant ID, the session,
  the trial's index and condition, whether it was practice and complete, so that ``persuasive
  fit --per-participant`` knows who drove a trial whatever its file is called), plus the
  person's input per step (``hv_key_up``, ``hv_key_down``, ``hv_axis``, ``hv_input_source``,
  ``hv_command_mps2``, ``hv_command_age_ms``) and the timings (``step_latency_ms``: from the
  tick, command in hand, to the state written to the socket; ``step_compute_ms``: the step
  alone; ``tick_late_ms``: how late the tick fired);
- ``<id>-tNN-<condition>-partial.parquet``: a trial cut short (the page closed, the server
  stopped), the steps taken so far;
- ``<id>.json``: the study summary (participant, Latin-square row, order, conditions,
  answers, files, each trial's ``complete`` flag and outcome, dropped messages), rewritten
  atomically after every change.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as _dt
import json
import logging
import math
import time
from collections import Counter, deque
from pathlib import Path
from typing import Any, Awaitable, Callable

import numpy as np

from .._files import json_safe
from ..config import ConfigError
from .human import INPUT_SOURCES, HumanInput, LiveHuman
from .scene import poses, scene_of
from .study import Condition, Study, sanitize_participant

log = logging.getLogger("persuasive.web")

#: Longest text message read [characters]; longer ones are dropped unread.
MAX_MESSAGE_CHARS = 4096
#: Messages waiting for a slow client beyond which new states are dropped for it.
MAX_QUEUED = 64
#: The fields each client message may carry (all required unless listed in OPTIONAL).
CLIENT_MESSAGES = {
    "begin": ("participant", "consent"),
    "start": (),
    "input": ("up", "down", "axis", "source"),
    "answers": ("trial", "answers"),
}
OPTIONAL = {"input": ("seq",)}


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


class Hub:
    """What all sessions share: the study, the output folder, who is connected."""

    def __init__(self, study: Study, out_dir: str | Path):
        self.study = study
        self.out_dir = Path(out_dir)
        self.sessions: set[Session] = set()
        self._stems: set[str] = set()

    def claim_stem(self, participant: str) -> str:
        """A file stem for a new session of ``participant``: the ID itself, or ``ID-2``,
        ``ID-3``, ... when a session of that ID is connected or has a summary here."""
        n = 1
        while True:
            stem = participant if n == 1 else f"{participant}-{n}"
            if stem not in self._stems and not (self.out_dir / f"{stem}.json").exists():
                self._stems.add(stem)
                return stem
            n += 1

    def release(self, session: Session) -> None:
        self.sessions.discard(session)

    async def close_all(self, reason: str) -> None:
        """Save every open trial as partial and close the sessions (server shutdown)."""
        for session in list(self.sessions):
            await session.close(reason)


class Trial:
    """One trial of a session: its world, the person, its timings, and its file.

    ``stem``: the session's file stem (the participant ID, or ``ID-2``, ... for a later session
    of the same ID); ``participant``: the participant ID stored in the trial's metadata (the
    stem when not given).
    """

    def __init__(self, index: int, condition: Condition, practice: bool, stem: str,
                 out_dir: Path, number: int, total: int, participant: str | None = None):
        self.index, self.condition, self.practice = index, condition, practice
        self.number, self.total = number, total
        self.stem = stem
        self.participant = stem if participant is None else participant
        self.config = condition.config
        self.seed = condition.seed
        self.n = self.config.simulation.n_steps
        self.dt = self.config.simulation.dt_s
        self.name = f"{stem}-t{index:02d}-{condition.name}"
        self.out_dir = out_dir
        self.human = LiveHuman()
        self.world = None
        self.latency_ms = np.full(self.n, np.nan)
        self.compute_ms = np.full(self.n, np.nan)
        self.late_ms = np.full(self.n, np.nan)
        self.dropped = 0
        self.finished = False  #: saved (or being saved); set before the first await
        self._belief = None

    @property
    def steps(self) -> int:
        return 0 if self.world is None else self.world.k

    def build(self) -> None:
        """Build the world (scenario, streams, both policies); run in a worker thread."""
        from ..world import PythonWorld

        # the record says who drove: a person (not a model of the simulation)
        world = PythonWorld(self.config.with_overrides({"hv.kind": "person"}), self.seed,
                            hv=self.human)
        columns = tuple(world.av.log_columns)
        for name in ("belief_hv_leader", "belief_other_leader"):
            if name in columns:
                self._belief = columns.index(name)
                break
        self.world = world

    def scene_message(self, countdown_s: float) -> dict[str, Any]:
        w = self.world
        return {"type": "scene", "trial": self.index, "label": self.condition.label,
                "number": self.number, "of": self.total, "dt_s": self.dt, "n_steps": self.n,
                "countdown_s": countdown_s, "scene": scene_of(w.scenario, w.states[0], self.n),
                "state": self.state_message(0)}

    def state_message(self, j: int, show_belief: bool = False) -> dict[str, Any]:
        """The state ``x_j`` for the page."""
        w = self.world
        msg = {"type": "state", "j": j, "t": round(j * self.dt, 4),
               **poses(w.scenario, w.states[j])}
        if show_belief and j > 0 and self._belief is not None:
            b = float(w.av_log[j - 1, self._belief])
            msg["belief"] = round(b, 4) if math.isfinite(b) else None
        return msg

    def record(self):
        """The :class:`~persuasive.simulation.RunRecord` of the steps taken, with the
        person's inputs and the timings added to its log."""
        k = self.steps
        rec = self.world.record()
        rec.log.update(self.human.columns(k))
        rec.log["step_latency_ms"] = self.latency_ms[:k].copy()
        rec.log["step_compute_ms"] = self.compute_ms[:k].copy()
        rec.log["tick_late_ms"] = self.late_ms[:k].copy()
        return rec

    def metadata(self, complete: bool) -> dict[str, Any]:
        """Who drove this trial and which it is: stored in its file's metadata (``trial``)."""
        return {"participant": self.participant, "session": self.stem, "index": self.index,
                "condition": self.condition.name, "practice": self.practice,
                "complete": complete}

    def save(self, complete: bool) -> dict[str, Any]:
        """Write the trial (``-partial`` when not ``complete``); returns its summary entry.
        Nothing is written for a trial that took no step. Runs in a worker thread."""
        from ..record import ARRIVAL_LABELS, OUTCOME_FIELDS

        entry: dict[str, Any] = {
            "index": self.index, "condition": self.condition.name,
            "label": self.condition.label, "practice": self.practice, "seed": self.seed,
            "n_steps": self.n, "steps": self.steps, "complete": complete, "file": None,
            "saved_utc": _now(), "dropped_messages": self.dropped,
        }
        if self.steps == 0:
            return entry
        rec = self.record()
        name = self.name + ("" if complete else "-partial") + ".parquet"
        rec.save(self.out_dir / name, extra={"trial": self.metadata(complete)})
        entry["file"] = name
        o = rec.outcome
        entry["outcome"] = json_safe({f: getattr(o, f) for f in OUTCOME_FIELDS})
        entry["outcome"]["first_at_line_label"] = ARRIVAL_LABELS[o.first_at_line]
        lat = self.latency_ms[:self.steps]
        lat = lat[np.isfinite(lat)]
        if lat.size:
            entry["step_latency_ms"] = {"median": float(np.median(lat)),
                                        "p99": float(np.percentile(lat, 99)),
                                        "max": float(lat.max())}
        return entry


class Session:
    """One participant's connection (see the module docstring).

    ``send_text``: a coroutine function writing one text message to the client.
    """

    def __init__(self, hub: Hub, send_text: Callable[[str], Awaitable[None]]):
        self.hub = hub
        self.study = hub.study
        self._send_text = send_text
        self.state = "welcome"  # welcome | ready | running | answering | finished
        self.dropped: Counter[str] = Counter()
        self.states_dropped = 0
        self.input = HumanInput()
        self.participant: str | None = None
        self.stem: str | None = None
        self.plan: list[tuple[Condition, bool]] = []
        self.row = -1
        self.next_index = 0
        self.trial: Trial | None = None
        self.trial_task: asyncio.Task | None = None
        self.entries: list[dict[str, Any]] = []
        self.started = _now()
        self.closed = False
        self.ended: str | None = None
        self._outbox: deque[tuple[str, tuple | None]] = deque()
        self._wake = asyncio.Event()
        self._idle = asyncio.Event()
        self._idle.set()
        self._sender_task: asyncio.Task | None = None
        self._summary_lock = asyncio.Lock()
        self._bg: set[asyncio.Task] = set()
        self._closing: asyncio.Future | None = None
        hub.sessions.add(self)

    # -- sending -----------------------------------------------------------------------------

    def start(self) -> None:
        """Start the sender and greet the page."""
        self._sender_task = asyncio.create_task(self._sender())
        self.post({"type": "welcome", "title": self.study.title, "consent": self.study.consent})

    def post(self, message: dict[str, Any], stamp: tuple | None = None) -> None:
        """Queue a message for the page. A state message is dropped when the client has not
        read :data:`MAX_QUEUED` earlier ones (a stalled page only loses its own frames)."""
        if self.closed:
            return
        if stamp is not None and len(self._outbox) >= MAX_QUEUED:
            self.states_dropped += 1
            return
        self._outbox.append((json.dumps(message, separators=(",", ":"), allow_nan=False),
                             stamp))
        self._idle.clear()
        self._wake.set()

    async def _sender(self) -> None:
        try:
            while True:
                await self._wake.wait()
                self._wake.clear()
                while self._outbox:
                    text, stamp = self._outbox.popleft()
                    await self._send_text(text)
                    if stamp is not None:  # (trial, step, perf_counter at the tick)
                        trial, k, t0 = stamp
                        trial.latency_ms[k] = (time.perf_counter() - t0) * 1e3
                self._idle.set()
        except asyncio.CancelledError:
            raise
        except Exception:  # noqa: BLE001 - the connection is gone; the session closes
            log.debug("send failed", exc_info=True)
        finally:
            self._outbox.clear()
            self._idle.set()

    async def _drain(self, timeout_s: float) -> None:
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(self._idle.wait(), timeout_s)

    # -- receiving ---------------------------------------------------------------------------

    def _drop(self, reason: str) -> None:
        self.dropped[reason] += 1
        if self.trial is not None and not self.trial.finished:
            self.trial.dropped += 1

    def receive(self, text: str | None = None, data: bytes | None = None) -> None:
        """Handle one message from the page; never raises."""
        if text is None:
            self._drop("binary" if data is not None else "empty")
            return
        if len(text) > MAX_MESSAGE_CHARS:
            self._drop("too-large")
            return
        try:
            msg = json.loads(text)
        except Exception:  # noqa: BLE001 - JSONDecodeError, RecursionError, ...
            self._drop("not-json")
            return
        if not isinstance(msg, dict):
            self._drop("not-object")
            return
        kind = msg.get("type")
        if not isinstance(kind, str) or kind not in CLIENT_MESSAGES:
            self._drop("unknown-type")
            return
        allowed = {"type", *CLIENT_MESSAGES[kind], *OPTIONAL.get(kind, ())}
        if set(msg) - allowed or any(f not in msg for f in CLIENT_MESSAGES[kind]):
            self._drop("bad-fields")
            return
        try:
            getattr(self, f"_on_{kind}")(msg)
        except Exception:  # noqa: BLE001 - a bug must not take the session down
            log.exception("error handling a %s message", kind)

    def _background(self, coro) -> None:
        task = asyncio.get_running_loop().create_task(coro)
        self._bg.add(task)
        task.add_done_callback(self._bg.discard)

    def _on_input(self, msg: dict) -> bool | None:
        up, down, axis, source = msg["up"], msg["down"], msg["axis"], msg["source"]
        seq = msg.get("seq", 0)
        if not (isinstance(up, bool) and isinstance(down, bool) and source in INPUT_SOURCES
                and (axis is None or (isinstance(axis, (int, float)) and not isinstance(axis, bool)
                                      and math.isfinite(axis) and -1.0 <= axis <= 1.0))
                and isinstance(seq, int) and not isinstance(seq, bool)):
            self._drop("bad-fields")
            return False
        self.input = HumanInput(up, down, math.nan if axis is None else float(axis), source,
                                time.monotonic())
        if self.trial is not None:
            self.trial.human.input = self.input
        return True

    def _on_begin(self, msg: dict) -> bool | None:
        if self.state != "welcome":
            self._drop("out-of-order")
            return False
        if msg["consent"] is not True:
            self.post({"type": "error", "field": "consent",
                       "message": "Please read the information and tick the box to agree."})
            return True
        raw = msg["participant"]
        try:
            if not isinstance(raw, str) or len(raw) > 200:
                raise ConfigError("participant ID is too long")
            participant = sanitize_participant(raw)
        except ConfigError as exc:
            self.post({"type": "error", "field": "participant",
                       "message": f"Please enter a valid participant ID ({exc})."})
            return True
        self.participant = participant
        self.stem = self.hub.claim_stem(participant)
        self.row, order = self.study.order_for(participant)
        self.plan = ([(self.study.practice, True)] if self.study.practice else []) + \
            [(c, False) for c in order]
        self.state = "ready"
        log.info("participant %s: session %s, Latin-square row %d", participant, self.stem,
                 self.row)
        self.post({"type": "plan", "participant": participant,
                   "instructions": self.study.instructions,
                   "trials": [{"index": i, "label": c.label, "practice": p}
                              for i, (c, p) in enumerate(self.plan)],
                   "questions": [{"id": q.id, "text": q.text, "scale": q.scale, "low": q.low,
                                  "high": q.high} for q in self.study.questions]})
        self._post_ready()
        self._background(self.write_summary())
        return True

    def _post_ready(self) -> None:
        c, practice = self.plan[self.next_index]
        self.post({"type": "ready", "trial": self.next_index, "label": c.label,
                   "practice": practice, "number": self.next_index + 1, "of": len(self.plan)})

    def _on_start(self, msg: dict) -> bool | None:
        if self.state != "ready":
            self._drop("out-of-order")
            return False
        condition, practice = self.plan[self.next_index]
        trial = Trial(self.next_index, condition, practice, self.stem, self.hub.out_dir,
                      self.next_index + 1, len(self.plan), participant=self.participant)
        trial.human.input = self.input
        self.trial = trial
        self.state = "running"
        self.trial_task = asyncio.get_running_loop().create_task(self._run_trial(trial))
        return True

    def _on_answers(self, msg: dict) -> bool | None:
        trial = self.trial
        if self.state != "answering" or trial is None:
            self._drop("out-of-order")
            return False
        answers = msg["answers"]
        questions = () if trial.practice else self.study.questions
        if msg["trial"] != trial.index or not isinstance(answers, dict) \
                or set(answers) != {q.id for q in questions} \
                or any(isinstance(answers[q.id], bool) or not isinstance(answers[q.id], int)
                       or not 1 <= answers[q.id] <= q.scale for q in questions):
            self._drop("bad-fields")
            return False
        for entry in self.entries:
            if entry["index"] == trial.index:
                entry["answers"] = {q.id: answers[q.id] for q in questions}
        self.next_index += 1
        self.trial = None
        if self.next_index >= len(self.plan):
            self.state = "finished"
            self.ended = "finished"
            self.post({"type": "finished"})
            log.info("participant %s: study finished", self.participant)
        else:
            self.state = "ready"
            self._post_ready()
        self._background(self.write_summary())
        return True

    # -- the trial ---------------------------------------------------------------------------

    async def _run_trial(self, trial: Trial) -> None:
        try:
            await self._steps(trial)
        except asyncio.CancelledError:
            raise
        except Exception:  # noqa: BLE001 - keep the server and what the trial has so far
            log.exception("participant %s: trial %d failed", self.participant, trial.index)
            self.post({"type": "error", "message": "The trial stopped because of an error on "
                                                   "the server. Please tell the researcher."})
            await self._finish(trial, complete=False)

    async def _steps(self, trial: Trial) -> None:
        await asyncio.to_thread(trial.build)
        study = self.study
        self.post(trial.scene_message(study.countdown_s))
        if study.countdown_s > 0:
            await asyncio.sleep(study.countdown_s)
        loop = asyncio.get_running_loop()
        world, dt, show = trial.world, trial.dt, study.show_belief
        t0 = loop.time()
        for k in range(trial.n):
            target = t0 + k * dt
            delay = target - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            late = loop.time() - target
            if late > dt:  # fell behind (the machine stalled): restart the schedule from now
                t0 += late
            tick, tick_mono = time.perf_counter(), time.monotonic()
            world.step()
            trial.compute_ms[k] = (time.perf_counter() - tick) * 1e3
            trial.late_ms[k] = late * 1e3
            msg = trial.state_message(k + 1, show)
            msg["ts"] = round(tick_mono, 6)  # lets a client on this machine time the step
            self.post(msg, stamp=(trial, k, tick))
        await self._drain(1.0)  # so that the last steps' latencies are in the file
        await self._finish(trial, complete=True)

    async def _finish(self, trial: Trial, complete: bool) -> None:
        if trial.finished:
            return
        trial.finished = True
        try:
            entry = await asyncio.to_thread(trial.save, complete)
        except Exception as exc:  # noqa: BLE001 - keep the session; say what was lost
            log.error("participant %s: trial %d could not be saved: %s", self.participant,
                      trial.index, exc)
            entry = {"index": trial.index, "condition": trial.condition.name,
                     "complete": False, "file": None, "error": str(exc)}
        self.entries = [e for e in self.entries if e["index"] != trial.index] + [entry]
        log.info("participant %s: trial %d (%s) %s after %d of %d steps -> %s",
                 self.participant, trial.index, trial.condition.name,
                 "complete" if complete else "cut short", trial.steps, trial.n,
                 entry.get("file"))
        if complete and not self.closed:
            self.state = "answering"
            asks = bool(self.study.questions) and not trial.practice
            self.post({"type": "done", "trial": trial.index, "questions": asks,
                       "last": trial.index + 1 >= len(self.plan)})
        await self.write_summary()

    # -- the summary -------------------------------------------------------------------------

    def summary(self) -> dict[str, Any]:
        study = self.study
        done = [e for e in self.entries if e.get("complete")]
        return json_safe({
            "participant": self.participant, "session": self.stem, "study": study.title,
            "study_source": study.source, "version": _version(),
            "started_utc": self.started, "updated_utc": _now(),
            "latin_square_row": self.row, "latin_square_rows": len(study.rows),
            "order": [c.name for c, p in self.plan if not p],
            "conditions": [{"name": c.name, "label": c.label, "overrides": c.overrides,
                            "seed": c.seed, "config_digest": c.config.digest()}
                           for c in study.conditions],
            "practice": None if study.practice is None else {
                "overrides": study.practice.overrides, "seed": study.practice.seed,
                "config_digest": study.practice.config.digest()},
            "trials": sorted(self.entries, key=lambda e: e["index"]),
            "files": [e["file"] for e in sorted(self.entries, key=lambda e: e["index"])
                      if e.get("file")],
            "complete": self.state == "finished" and len(done) == len(self.plan),
            "ended": self.ended,
            "dropped_messages": dict(self.dropped),
            "states_dropped": self.states_dropped,
        })

    async def write_summary(self) -> None:
        """Rewrite ``<id>.json`` atomically (in a worker thread)."""
        if self.stem is None:
            return
        from .._files import atomic_write

        async with self._summary_lock:
            text = json.dumps(self.summary(), indent=2)
            path = self.hub.out_dir / f"{self.stem}.json"
            try:
                await asyncio.to_thread(
                    atomic_write, path, lambda p: p.write_text(text, encoding="utf-8"))
            except Exception as exc:  # noqa: BLE001
                log.error("summary %s could not be written: %s", path, exc)

    # -- closing -----------------------------------------------------------------------------

    async def close(self, reason: str = "disconnected") -> None:
        """The page went away (or the server stops): save an open trial as partial, write the
        summary, stop the sender. Safe to call more than once and from several tasks: every
        call returns once the session is closed."""
        if self._closing is None:
            self._closing = asyncio.ensure_future(self._close(reason))
        await asyncio.shield(self._closing)

    async def _close(self, reason: str) -> None:
        self.closed = True
        if self.ended is None:
            self.ended = reason
        task, trial = self.trial_task, self.trial
        if task is not None and not task.done():
            if trial is not None and trial.world is not None and trial.world.done:
                self._idle.set()
                with contextlib.suppress(Exception):
                    await task  # the steps are over: let it save the whole trial
            else:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
        if trial is not None and not trial.finished:
            await self._finish(trial, complete=False)
        if self._sender_task is not None:
            self._sender_task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._sender_task
        if self._bg:
            await asyncio.gather(*self._bg, return_exceptions=True)
        await self.write_summary()
        self.hub.release(self)
        if self.participant:
            log.info("participant %s: session %s ended (%s)", self.participant, self.stem,
                     self.ended)


def _version() -> str:
    from .._version import __version__

    return __version__


__all__ = ["CLIENT_MESSAGES", "Hub", "MAX_MESSAGE_CHARS", "Session", "Trial"]
