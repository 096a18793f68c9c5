"""Real drivers from recordings: recorded tracks read, paired at their conflicts, projected
onto the scenario form and written as fit logs; our own runs written as recordings
(docs/guide/recordings.md).

One concept per module:

- :mod:`~persuasive.recordings.formats`: the INTERACTION and inD readers (one tidy table at
  10 Hz, with their checks and :class:`RecordingError`) and the INTERACTION writer;
- :mod:`~persuasive.recordings.tracks`: the Savitzky-Golay smoothing of every vehicle track:
  positions, arc length, speed and acceleration;
- :mod:`~persuasive.recordings.geometry`: the compiled search for crossings and merges between
  two tracks' paths;
- :mod:`~persuasive.recordings.pairs`: candidate pairs, their projection through
  ``persuasive.envs.external.route_conflict``, the labels (first passer, PET, slowing) and the
  pairs file;
- :mod:`~persuasive.recordings.logs`: each pair from each driver's view as the log ``persuasive
  fit`` reads;
- :mod:`~persuasive.recordings.export`: ``simulate --out`` runs as INTERACTION track files.
"""

from .formats import RecordingError, read_ind, read_interaction, read_tracks
from .pairs import Pair, PairParams, PairsResult, find_pairs, read_pairs, write_pairs
from .tracks import SmoothingParams, Tracks, smooth_tracks

__all__ = ["Pair", "PairParams", "PairsResult", "RecordingError", "SmoothingParams", "Tracks",
           "find_pairs", "read_ind", "read_interaction", "read_pairs", "read_tracks",
           "smooth_tracks", "write_pairs"]
