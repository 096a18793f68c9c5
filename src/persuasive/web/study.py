"""A user study of the browser page: its file, its conditions and their order per participant.

A study is a TOML file (:func:`load_study`; :func:`default_study` when none is given)::

    title = "Crossing with an automated vehicle"
    seed = 1                # practice uses seed, condition j uses seed + 1 + j
    countdown_s = 3.0       # shown before each trial starts
    show_belief = false     # show the AV's belief that the person leads (logged either way)
    consent = \"\"\"You will drive ... Your answers are stored under your participant ID.\"\"\"

    [base]                  # config overrides applied to every trial, as in --set
    mode = "corrected"
    scenario.hv_s0_halfwidth_m = 0.0
    simulation.n_steps = 80

    [practice]              # optional; enabled = false skips it
    set = { "av.kind" = "yield" }

    [[conditions]]          # two or more; names are [A-Za-z0-9_-] and never shown
    name = "persuasive-near"
    set = { "av.kind" = "persuasive", "scenario.hv_s0_m" = -18.0 }

    [[questions]]           # optional Likert items after each trial (not after practice)
    id = "safe"
    text = "I felt safe."
    scale = 7               # points 1..scale
    low = "strongly disagree"
    high = "strongly agree"

Override tables may be nested (``[base.scenario]``), dotted (``scenario.kind = "merge"``) or
quoted-dotted (``"scenario.kind" = "merge"``); they are flattened to the ``section.field``
keys of :meth:`persuasive.config.Config.with_overrides`. A condition's overrides apply on top
of ``[base]``. Every trial's configuration is built and its scenario checked when the file is
read, so a bad study fails before anyone sits down. Texts (``consent``, ``instructions``) are
shown as paragraphs: the lines of a paragraph are joined, a blank line starts the next one.

**Counterbalancing.** Conditions are ordered by a balanced Latin square (a Williams design,
:func:`balanced_latin_square`): every condition once per row and once per position over the
rows, and every condition immediately followed by every other equally often (``n`` rows for an
even number of conditions, ``2 n`` for an odd one). A participant's row is their index modulo
the number of rows; the index is the number the participant ID ends with (``P07`` -> 7), else
a stable hash of the ID (:func:`participant_index`). The page names conditions "Condition A",
"Condition B", ... by their position in the study file, never by their AV kind.
"""

from __future__ import annotations

import hashlib
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config import Config, ConfigError, read_toml

#: Characters allowed in participant IDs (others are replaced by "_") and condition names.
SAFE_NAME = re.compile(r"^[A-Za-z0-9_-]+$")
#: Longest participant ID kept [characters].
MAX_ID_LENGTH = 48
#: Keys of a study file.
STUDY_KEYS = ("title", "seed", "countdown_s", "show_belief", "consent", "instructions",
              "base", "practice", "conditions", "questions")


@dataclass(frozen=True)
class Question:
    """One Likert item asked after each trial."""

    id: str  #: [A-Za-z0-9_-], the answer's key
    text: str
    scale: int = 7  #: points 1..scale
    low: str = ""  #: label of point 1
    high: str = ""  #: label of point ``scale``


@dataclass(frozen=True)
class Condition:
    """One condition: a name (for the researcher, never shown), its overrides and config."""

    name: str
    label: str  #: what the page shows: "Condition A", ...
    overrides: dict[str, Any] = field(compare=False)
    config: Config = field(repr=False)
    seed: int = 0


@dataclass(frozen=True)
class Study:
    """A whole study (see the module docstring for the file format)."""

    title: str
    seed: int
    countdown_s: float
    show_belief: bool
    consent: str
    instructions: str
    conditions: tuple[Condition, ...]
    practice: Condition | None
    questions: tuple[Question, ...]
    source: str = "built-in default study"

    @property
    def rows(self) -> tuple[tuple[int, ...], ...]:
        """The balanced Latin square over the conditions (rows of condition indices)."""
        return balanced_latin_square(len(self.conditions))

    def order_for(self, participant: str) -> tuple[int, tuple[Condition, ...]]:
        """The participant's row of the Latin square and their conditions in that order."""
        rows = self.rows
        row = participant_index(participant) % len(rows)
        return row, tuple(self.conditions[j] for j in rows[row])

    def with_seed(self, seed: int) -> Study:
        """The same study with another base seed (``persuasive drive --seed``)."""
        from dataclasses import replace

        from ..record import check_seed

        check_seed(seed)
        check_seed(seed + len(self.conditions))
        practice = replace(self.practice, seed=seed) if self.practice else None
        conditions = tuple(replace(c, seed=seed + 1 + j) for j, c in enumerate(self.conditions))
        return replace(self, seed=seed, practice=practice, conditions=conditions)

    def with_shield(self, shield: str) -> Study:
        """The same study with the AV's safety shield set in every condition and in the
        practice trial (``persuasive drive --shield``; docs/method.md §12)."""
        from dataclasses import replace

        def shielded(c: Condition) -> Condition:
            return replace(c, overrides={**c.overrides, "av.shield": shield},
                           config=c.config.with_overrides({"av.shield": shield}))

        return replace(self, practice=shielded(self.practice) if self.practice else None,
                       conditions=tuple(shielded(c) for c in self.conditions))


# -- counterbalancing ----------------------------------------------------------------------------


def balanced_latin_square(n: int) -> tuple[tuple[int, ...], ...]:
    """A balanced Latin square (Williams design) over ``n`` conditions ``0 .. n-1``.

    Row ``r`` is the first row ``0, 1, n-1, 2, n-2, ...`` plus ``r`` modulo ``n``. For even
    ``n`` the ``n`` rows are carry-over balanced (each ordered pair of conditions adjacent
    exactly once); for odd ``n`` the mirrored rows are appended (``2 n`` rows, each ordered pair
    adjacent exactly twice). Every condition appears once per row and equally often at every
    position.
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ConfigError(f"number of conditions = {n!r} is out of range; allowed: >= 1")
    first, lo, hi = [0], 1, n - 1
    while len(first) < n:
        first.append(lo)
        lo += 1
        if len(first) < n:
            first.append(hi)
            hi -= 1
    rows = [tuple((c + r) % n for c in first) for r in range(n)]
    if n % 2 == 1 and n > 1:
        rows += [tuple(reversed(row)) for row in rows]
    return tuple(rows)


def sanitize_participant(raw: Any) -> str:
    """The participant ID used in file names: characters outside ``[A-Za-z0-9_-]`` replaced
    by ``_``, at most :data:`MAX_ID_LENGTH` long. Raises :class:`ConfigError` for an ID that
    is not text or has no letter or digit."""
    if not isinstance(raw, str):
        raise ConfigError("participant ID is not text")
    text = re.sub(r"[^A-Za-z0-9_-]", "_", raw.strip())[:MAX_ID_LENGTH]
    if not re.search(r"[A-Za-z0-9]", text):
        raise ConfigError("participant ID needs at least one letter or digit")
    return text


def participant_index(participant: str) -> int:
    """The participant's index: the number their ID ends with (``P07`` -> 7, ``s-12`` -> 12),
    else the first 8 bytes of the SHA-256 of the ID (stable across processes)."""
    m = re.search(r"(\d+)$", participant)
    if m:
        return int(m.group(1)[-9:])
    return int.from_bytes(hashlib.sha256(participant.encode("utf-8")).digest()[:8], "big")


# -- reading a study -----------------------------------------------------------------------------


def flatten(table: Any, where: str, prefix: str = "") -> dict[str, Any]:
    """A nested override table as ``{"section.field": value}``."""
    if not isinstance(table, dict):
        raise ConfigError(f"{where} is not a table of config overrides")
    out: dict[str, Any] = {}
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten(value, where, dotted + "."))
        else:
            out[dotted] = value
    return out


def _condition_config(base: dict[str, Any], overrides: dict[str, Any], where: str) -> Config:
    from ..record import static_setup

    merged = {**base, **overrides}
    if merged.get("hv.kind", "lfg") == "replay":
        raise ConfigError(f"{where}: hv.kind = 'replay' cannot be used in a study (the person "
                          "drives the HV)")
    try:
        config = Config().with_overrides(merged) if merged else Config()
        static_setup(config)  # builds the scenario: checks the starts and the geometry
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    return config


def paragraphs(text: str) -> str:
    """Text as the page shows it: lines within a paragraph joined (a TOML string wraps like
    the file), paragraphs kept apart by one blank line."""
    parts = re.split(r"\n\s*\n", text.strip())
    return "\n\n".join(" ".join(line.strip() for line in p.splitlines() if line.strip())
                       for p in parts if p.strip())


def _text(data: dict, key: str, default: str, where: str) -> str:
    value = data.get(key, default)
    if not isinstance(value, str):
        raise ConfigError(f"{where}{key} = {value!r} is not text")
    return value


def _int(value: Any, name: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ConfigError(f"{name} = {value!r} is out of range; allowed: integer in "
                          f"[{lo}, {hi}]")
    return value


def study_from_dict(data: dict[str, Any], source: str = "study") -> Study:
    """Build and check a :class:`Study` from the parsed TOML of a study file."""
    if not isinstance(data, dict):
        raise ConfigError("a study is a table of keys")
    unknown = sorted(set(data) - set(STUDY_KEYS))
    if unknown:
        raise ConfigError(f"unknown key {unknown[0]!r}; allowed: "
                          f"{', '.join(STUDY_KEYS)}")
    title = _text(data, "title", "Driving study", "")
    seed = _int(data.get("seed", 1), "seed", 0, 2**32 - 1001)
    countdown = data.get("countdown_s", 3.0)
    if isinstance(countdown, bool) or not isinstance(countdown, (int, float)) \
            or not math.isfinite(countdown) or not 0.0 <= countdown <= 30.0:
        raise ConfigError(f"countdown_s = {countdown!r} is out of range; allowed: [0, 30] s")
    show_belief = data.get("show_belief", False)
    if not isinstance(show_belief, bool):
        raise ConfigError(f"show_belief = {show_belief!r} is not a boolean (true | false)")
    consent = paragraphs(_text(data, "consent", "", ""))
    if not consent:
        raise ConfigError("consent is required (the text participants accept)")
    instructions = paragraphs(_text(data, "instructions", DEFAULT_INSTRUCTIONS, ""))
    base = flatten(data.get("base", {}), "base")

    raw_conditions = data.get("conditions")
    if not isinstance(raw_conditions, list) or len(raw_conditions) < 1:
        raise ConfigError("[[conditions]] is required (one table per condition)")
    if len(raw_conditions) > 26:
        raise ConfigError(f"{len(raw_conditions)} conditions; allowed: 1..26")
    conditions: list[Condition] = []
    for j, raw in enumerate(raw_conditions):
        where = f"conditions[{j}]"
        if not isinstance(raw, dict) or set(raw) - {"name", "set"}:
            raise ConfigError(f"{where}: a condition has the keys name and set")
        name = raw.get("name")
        if not isinstance(name, str) or not SAFE_NAME.match(name) or len(name) > 40:
            raise ConfigError(f"{where}.name = {name!r} is not a name of 1-40 characters "
                              "[A-Za-z0-9_-]")
        if any(c.name == name for c in conditions):
            raise ConfigError(f"{where}.name = {name!r} is used twice")
        overrides = flatten(raw.get("set", {}), f"{where}.set")
        conditions.append(Condition(name, f"Condition {chr(ord('A') + j)}", overrides,
                                    _condition_config(base, overrides, f"{where} ({name})"),
                                    seed + 1 + j))

    practice = None
    raw_practice = data.get("practice", {})
    if not isinstance(raw_practice, dict) or set(raw_practice) - {"enabled", "set"}:
        raise ConfigError("practice: a table with the keys enabled and set")
    enabled = raw_practice.get("enabled", True)
    if not isinstance(enabled, bool):
        raise ConfigError(f"practice.enabled = {enabled!r} is not a boolean (true | false)")
    if enabled:
        overrides = flatten(raw_practice.get("set", {}), "practice.set")
        practice = Condition("practice", "Practice", overrides,
                             _condition_config(base, overrides, "practice"), seed)

    questions: list[Question] = []
    raw_questions = data.get("questions", [])
    if not isinstance(raw_questions, list):
        raise ConfigError("questions: use [[questions]] tables")
    for i, raw in enumerate(raw_questions):
        where = f"questions[{i}]."
        if not isinstance(raw, dict) or set(raw) - {"id", "text", "scale", "low", "high"}:
            raise ConfigError(f"questions[{i}]: a question has the keys id, text, scale, low, "
                              "high")
        qid = raw.get("id")
        if not isinstance(qid, str) or not SAFE_NAME.match(qid) or len(qid) > 40:
            raise ConfigError(f"{where}id = {qid!r} is not a name of 1-40 characters "
                              "[A-Za-z0-9_-]")
        if any(q.id == qid for q in questions):
            raise ConfigError(f"{where}id = {qid!r} is used twice")
        text = _text(raw, "text", "", where).strip()
        if not text:
            raise ConfigError(f"{where}text is required")
        questions.append(Question(qid, text, _int(raw.get("scale", 7), where + "scale", 2, 11),
                                  _text(raw, "low", "", where), _text(raw, "high", "", where)))
    return Study(title, seed, float(countdown), show_belief, consent, instructions,
                 tuple(conditions), practice, tuple(questions), source)


def load_study(path: str | Path) -> Study:
    """Read and check a study file (see the module docstring)."""
    data = read_toml(path, "study file")
    try:
        return study_from_dict(data, str(path))
    except ConfigError as exc:
        raise ConfigError(f"study file {str(path)!r}: {exc}") from None


DEFAULT_INSTRUCTIONS = (
    "You drive the blue car. Hold the Up arrow key (or the Go button, or a gamepad trigger) "
    "to accelerate and the Down arrow key (or Brake) to brake; release both to coast. "
    "The red car is an automated vehicle. Cross the intersection as you would in traffic.")

#: The built-in study: the persuasive planner against the same MPC without persuasion, with
#: the person starting near or far from the crossing; a practice against a yielding AV.
DEFAULT_STUDY_TOML = """\
title = "Driving with an automated vehicle"
seed = 1
countdown_s = 3.0
show_belief = false
consent = \"\"\"
This study is about how people drive when they meet an automated vehicle at an intersection.
You will drive a car on this screen for a practice trial and four short trials, and answer a
few questions after each. It takes about ten minutes. Your driving and your answers are
stored under your participant ID only, with no name attached. You may stop at any time by
closing this page; what you did so far is kept unless you ask the researcher to delete it.
\"\"\"

[base]
mode = "corrected"
simulation.n_steps = 80
scenario.hv_s0_halfwidth_m = 0.0
scenario.hv_v0_halfwidth_mps = 0.0

[practice]
set = { "av.kind" = "yield" }

[[conditions]]
name = "persuasive-near"
set = { "av.kind" = "persuasive", "scenario.hv_s0_m" = -18.0 }

[[conditions]]
name = "persuasive-far"
set = { "av.kind" = "persuasive", "scenario.hv_s0_m" = -22.0 }

[[conditions]]
name = "passive-near"
set = { "av.kind" = "passive", "scenario.hv_s0_m" = -18.0 }

[[conditions]]
name = "passive-far"
set = { "av.kind" = "passive", "scenario.hv_s0_m" = -22.0 }

[[questions]]
id = "safe"
text = "I felt safe."
low = "strongly disagree"
high = "strongly agree"

[[questions]]
id = "intent"
text = "I understood what the other car was going to do."
low = "strongly disagree"
high = "strongly agree"

[[questions]]
id = "cooperative"
text = "The other car drove cooperatively."
low = "strongly disagree"
high = "strongly agree"
"""


def default_study() -> Study:
    """The built-in study (:data:`DEFAULT_STUDY_TOML`)."""
    return study_from_dict(tomllib.loads(DEFAULT_STUDY_TOML), "built-in default study")


__all__ = ["Condition", "DEFAULT_STUDY_TOML", "Question", "Study", "balanced_latin_square",
           "default_study", "flatten", "load_study", "participant_index",
           "sanitize_participant", "study_from_dict"]
