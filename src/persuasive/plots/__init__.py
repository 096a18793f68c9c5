"""Figures and animations of closed-loop runs and of the reproduced tables (issue 5).

This is the only package of ``persuasive`` that imports matplotlib. Every function takes the
data objects the model produces — a :class:`~persuasive.simulation.RunRecord` from
:func:`~persuasive.simulation.simulate`, or a table summary as written by ``persuasive
reproduce`` (:func:`~persuasive.experiments.load_summary`) — and returns a
:class:`matplotlib.figure.Figure` built with the object API: no pyplot state, no ``show()``,
no backend requirement (frames are rendered with an explicit Agg canvas).

One module per figure kind, all re-exported here:

- :mod:`~persuasive.plots.profile`: :func:`profile_figure` / :func:`profile_single`, the
  paper's Fig. 2, time profiles of roles, beliefs, speeds and accelerations.
- :mod:`~persuasive.plots.topview`: :func:`topview_figure` / :func:`topview_single`, the
  paper's Fig. 3, the intersection to scale with snapshots of both vehicles
  (:func:`draw_intersection`, :func:`snapshot_indices`).
- :mod:`~persuasive.plots.table`: :func:`table_figure`, a reproduced table beside the
  published shares.
- :mod:`~persuasive.plots.animation`: :func:`animation_frames` / :func:`animate`, a run as a
  top-view animation with the beliefs and roles shown live.
- :mod:`~persuasive.plots.files`: :func:`save_figure` writes PNG, SVG or PDF by extension;
  :func:`check_figure_path` / :func:`check_animation_path` check a target before any work.
- :mod:`~persuasive.plots._common`: colours, sizes, fonts and titles the figures share.

Conventions: HV blue, AV red (:data:`HV_COLOR`, :data:`AV_COLOR`). Time of state index ``k``
is ``k * dt``; the log row ``k`` (decision step ``k``) is taken at the same time, and a
quantity held over a step (role, acceleration) is drawn as a step line over
``[k dt, (k + 1) dt)``. Every data artist carries a ``gid`` (e.g. ``"hv-speed"``,
``"av-crossing"``) so that it can be found in the figure and in an SVG. Sizes suit a
two-column paper: :data:`DOUBLE_COLUMN_IN` wide for two-panel figures,
:data:`SINGLE_COLUMN_IN` for one. Files are checked before any work and written atomically;
a target that cannot be written raises :class:`persuasive._files.OutputError` with a one-line
message naming it.
"""

from ._common import (AV_COLOR, DOUBLE_COLUMN_IN, HV_COLOR, SINGLE_COLUMN_IN, belief_column,
                      case_title, crossing_time, run_label)
from .animation import animate, animation_frames
from .compare import compare_figure
from .files import (ANIMATION_EXTENSIONS, FIGURE_EXTENSIONS, check_animation_path,
                    check_figure_path, save_figure)
from .profile import PROFILE_ROWS, profile_figure, profile_single
from .table import table_figure, table_row_label
from .topview import (draw_intersection, draw_scene, snapshot_indices, topview_figure,
                      topview_single)

__all__ = [
    "compare_figure",
    "draw_scene",
    "ANIMATION_EXTENSIONS",
    "AV_COLOR",
    "DOUBLE_COLUMN_IN",
    "FIGURE_EXTENSIONS",
    "HV_COLOR",
    "PROFILE_ROWS",
    "SINGLE_COLUMN_IN",
    "animate",
    "animation_frames",
    "belief_column",
    "case_title",
    "check_animation_path",
    "check_figure_path",
    "crossing_time",
    "draw_intersection",
    "profile_figure",
    "profile_single",
    "run_label",
    "save_figure",
    "snapshot_indices",
    "table_figure",
    "table_row_label",
    "topview_figure",
    "topview_single",
]
