"""Eclipse SUMO's floating-car data as a recording: ``--fcd-output`` files read into the
INTERACTION track format (docs/guide/recordings.md, "SUMO's floating-car data").

SUMO's fcd file (``sumo --fcd-output FILE.xml``) holds ``<timestep time="T">`` elements with
one ``<vehicle id x y angle type speed .../>`` per vehicle (persons and containers are
skipped). It is read as follows:

- **Frames.** The timesteps whose time is a multiple of 100 ms (to 1 microsecond) are kept,
  INTERACTION's frame (``frame_id = round(10 T) + 1``, ``timestamp_ms = round(1000 T)``): run
  SUMO with ``--step-length 0.1`` (or a divisor of it). Each vehicle's kept samples must be
  one frame apart; a gap (a longer step, ``--device.fcd.period``) is refused.
- **Centre.** SUMO's ``x, y`` are the middle of the **front bumper** and ``angle`` is the
  heading in navigational degrees (clockwise from north); the centre is ``length / 2`` behind
  the front along the heading, the INTERACTION heading ``psi = pi / 2 - radians(angle)``
  (wrapped to ``(-pi, pi]``) and ``vx, vy`` SUMO's ``speed`` along it.
- **Sizes and classes** come from the vehicle types: the ``<vType id length width vClass>``
  elements of the files given as ``types`` (route or additional files), else SUMO's built-in
  types (``DEFAULT_VEHTYPE``, a passenger car); a length or width a type does not set is its
  vClass's default (:data:`VCLASS_DEFAULTS`, SUMO's). The vClass gives the INTERACTION
  ``agent_type`` (:data:`AGENT_TYPES`: passenger cars ``car``, trucks ``truck``, buses
  ``bus``, delivery vans ``van``; others, such as bicycles, are kept under their own name and
  never paired). A vehicle of an unknown type is refused.
- **Noise**: uniform measurement noise ``U(-noise_m, noise_m)`` on the centre's ``x`` and
  ``y``, independently per sample, from the caller's generator (as ``simulate --out`` runs are
  exported, :mod:`persuasive.recordings.export`).

Vehicles become tracks ``1, 2, ...`` in order of first appearance; their SUMO IDs are
returned beside the rows.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Sequence

import numpy as np

from .formats import INTERACTION_COLUMNS, RecordingError, noisy_speed

#: SUMO's default length and width per vehicle class [m] (SUMO's "Vehicle Type Parameter
#: Defaults").
VCLASS_DEFAULTS = {
    "passenger": (5.0, 1.8), "private": (5.0, 1.8), "taxi": (5.0, 1.8),
    "emergency": (6.5, 2.16), "delivery": (6.5, 2.16), "truck": (7.1, 2.4),
    "trailer": (16.5, 2.55), "bus": (12.0, 2.5), "coach": (14.0, 2.6),
    "motorcycle": (2.2, 0.9), "moped": (2.1, 0.8), "bicycle": (1.6, 0.65),
}
#: SUMO's built-in vehicle types and their classes.
BUILTIN_TYPES = {"DEFAULT_VEHTYPE": "passenger", "DEFAULT_TAXITYPE": "taxi",
                 "DEFAULT_BIKETYPE": "bicycle"}
#: The INTERACTION agent type of a SUMO vehicle class (others keep the class's name).
AGENT_TYPES = {"passenger": "car", "private": "car", "taxi": "car", "emergency": "van",
               "delivery": "van", "truck": "truck", "trailer": "truck", "bus": "bus",
               "coach": "bus"}
#: A timestep whose time is within this of a multiple of 100 ms is on a frame [s].
FRAME_TOL_S = 1e-6


def read_types(files: Sequence[str | Path]) -> dict[str, tuple[float, float, str]]:
    """The vehicle types ``{id: (length [m], width [m], vClass)}`` of SUMO XML files (their
    ``vType`` elements), with SUMO's built-in types; :class:`RecordingError` naming a file
    that cannot be read or a type whose size is not a positive number."""
    types = {name: (*VCLASS_DEFAULTS[c], c) for name, c in BUILTIN_TYPES.items()}
    for f in files:
        try:
            root = ET.parse(f).getroot()
        except (OSError, ET.ParseError) as exc:
            raise RecordingError(f"types file {str(f)!r} cannot be read: "
                                 f"{str(exc).splitlines()[0]}") from None
        for el in root.iter("vType"):
            vclass = el.get("vClass", "passenger")
            length, width = VCLASS_DEFAULTS.get(vclass, VCLASS_DEFAULTS["passenger"])
            try:
                length = float(el.get("length", length))
                width = float(el.get("width", width))
            except ValueError:
                length = width = math.nan
            if not (length > 0.0 and width > 0.0 and math.isfinite(length + width)):
                raise RecordingError(f"types file {str(f)!r}: vType {el.get('id')!r} has "
                                     f"length {el.get('length')!r}, width {el.get('width')!r};"
                                     " allowed: positive numbers [m]")
            types[el.get("id", "")] = (length, width, vclass)
    return types


def _float(el, name: str, path: Path, t: str) -> float:
    raw = el.get(name)
    try:
        x = float(raw)
    except (TypeError, ValueError):
        x = math.nan
    if not math.isfinite(x):
        raise RecordingError(f"fcd file {str(path)!r}: non-finite: vehicle {el.get('id')!r} "
                             f"at time {t} has {name} = {raw!r}; allowed: finite numbers")
    return x


def read_fcd(path: str | Path, types: dict[str, tuple[float, float, str]],
             rng: np.random.Generator, noise_m: float = 0.0, noise_mps: float = 0.0
             ) -> tuple[dict[str, np.ndarray], list[str]]:
    """The INTERACTION rows of one fcd file (module docstring; ``noise_mps``: as
    :func:`persuasive.recordings.formats.noisy_speed`) and the SUMO ID of each track
    (track ``i + 1`` is ``ids[i]``). :class:`RecordingError` (one line naming the file and
    the check) for a file that is not an fcd file, a value that is missing or not finite, an
    unknown vehicle type, a vehicle whose frames are not one 100 ms step apart, or no
    vehicle on a 100 ms frame."""
    path = Path(path)
    order: dict[str, int] = {}
    rows: dict[str, list] = {c: [] for c in ("track", "t", "x", "y", "angle", "speed",
                                             "length", "width", "agent")}
    try:
        context = ET.iterparse(path, events=("start", "end"))
        _, root = next(context)
        if root.tag != "fcd-export":
            raise RecordingError(f"fcd file {str(path)!r} is not an fcd file: its root "
                                 f"element is <{root.tag}>, not <fcd-export> (write it with "
                                 "sumo --fcd-output FILE.xml)")
        t_text, on_frame = "", False
        for event, el in context:
            if event == "start":
                if el.tag == "timestep":
                    t_text = el.get("time", "")
                    try:
                        t = float(t_text)
                    except ValueError:
                        t = math.nan
                    if not math.isfinite(t):
                        raise RecordingError(f"fcd file {str(path)!r}: non-finite: timestep "
                                             f"time = {t_text!r}; allowed: finite numbers")
                    on_frame = abs(t * 10.0 - round(t * 10.0)) <= FRAME_TOL_S * 10.0
                continue
            if el.tag == "vehicle" and on_frame:
                vid = el.get("id", "")
                vtype = el.get("type", "DEFAULT_VEHTYPE")
                if vtype not in types:
                    raise RecordingError(f"fcd file {str(path)!r}: vehicle {vid!r} is of type "
                                         f"{vtype!r}, whose length is not known; give the "
                                         "route or additional file that defines it (--types)")
                length, width, vclass = types[vtype]
                rows["track"].append(order.setdefault(vid, len(order) + 1))
                rows["t"].append(round(float(t_text) * 10.0))
                for name in ("x", "y", "angle", "speed"):
                    rows[name].append(_float(el, name, path, t_text))
                rows["length"].append(length)
                rows["width"].append(width)
                rows["agent"].append(AGENT_TYPES.get(vclass, vclass))
            if el.tag == "timestep":
                el.clear()
                root.clear()  # keep memory flat on long files
    except ET.ParseError as exc:
        raise RecordingError(f"fcd file {str(path)!r} cannot be parsed: "
                             f"{str(exc).splitlines()[0]}") from None
    except OSError as exc:
        raise RecordingError(f"fcd file {str(path)!r} cannot be read: "
                             f"{(exc.strerror or str(exc)).lower()}") from None
    if not rows["track"]:
        raise RecordingError(f"fcd file {str(path)!r} holds no vehicle on a 100 ms frame "
                             "(run SUMO with --step-length 0.1)")
    track = np.asarray(rows["track"], np.int64)
    frame = np.asarray(rows["t"], np.int64)
    order_rows = np.lexsort((frame, track))
    track, frame = track[order_rows], frame[order_rows]
    same = track[1:] == track[:-1]
    bad = same & (np.diff(frame) != 1)
    if bad.any():
        i = int(np.argmax(bad))
        ids = list(order)
        raise RecordingError(f"fcd file {str(path)!r}: frame step: vehicle "
                             f"{ids[track[i] - 1]!r} goes from t = {frame[i] / 10:g} s to "
                             f"{frame[i + 1] / 10:g} s; allowed: steps of exactly one frame "
                             "(100 ms; run SUMO with --step-length 0.1)")
    get = {k: np.asarray(v)[order_rows] for k, v in rows.items() if k not in ("track", "t")}
    angle = np.radians(get["angle"].astype(float))
    half = get["length"].astype(float) / 2.0
    x = get["x"] - half * np.sin(angle)  # navigational: 0 north, clockwise
    y = get["y"] - half * np.cos(angle)
    n = track.shape[0]
    x = x + rng.uniform(-noise_m, noise_m, n)
    y = y + rng.uniform(-noise_m, noise_m, n)
    psi = np.angle(np.exp(1j * (math.pi / 2.0 - angle)))
    speed = noisy_speed(get["speed"].astype(float), rng, noise_mps)
    out = {"track_id": track, "frame_id": frame + 1, "timestamp_ms": frame * 100,
           "agent_type": get["agent"].astype(object), "x": x, "y": y,
           "vx": speed * np.cos(psi), "vy": speed * np.sin(psi), "psi_rad": psi,
           "length": get["length"].astype(float), "width": get["width"].astype(float)}
    return {c: out[c] for c in INTERACTION_COLUMNS}, list(order)


__all__ = ["AGENT_TYPES", "BUILTIN_TYPES", "FRAME_TOL_S", "VCLASS_DEFAULTS", "read_fcd",
           "read_types"]
