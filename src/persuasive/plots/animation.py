"""A run as an animation: the top view, with the beliefs and roles shown live.

:func:`animation_frames` renders one frame per decision step with an explicit Agg canvas
(blitting the moving artists over a static background); :func:`animate` writes them as MP4
(H.264) or GIF through :func:`persuasive._files.atomic_write`, so a failed write raises a
one-line :class:`persuasive._files.OutputError` naming the target and leaves nothing beside
it. The scene comes from :mod:`persuasive.plots.topview` (:func:`draw_intersection` and the
vehicle footprints).
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from ..config import ConfigError
from ..simulation import RunRecord
from ._common import (_COLORS, _FONT, AV_COLOR, HV_COLOR, _has_role, _planner, _state_times,
                      _style, belief_column, case_title, crossing_time, hv_label, run_label)
from .files import check_animation_path, write_frames
from .topview import (_corners, _scene_handles, _vehicle_patch, _vehicle_xy,
                      _view_limits, draw_intersection)


class _AnimationScene:
    """The animation's figure, built once and updated in place frame by frame."""

    def __init__(self, run: RunRecord, width_in: float, height_in: float, dpi: float):
        self.run = run
        self.fig = Figure(figsize=(width_in, height_in), dpi=dpi, layout="constrained")
        self.canvas = FigureCanvasAgg(self.fig)
        grid = self.fig.add_gridspec(2, 2, width_ratios=(1.0, 1.05), height_ratios=(1.0, 0.85))
        self.ax_top = self.fig.add_subplot(grid[:, 0])
        self.ax_belief = self.fig.add_subplot(grid[0, 1])
        self.ax_text = self.fig.add_subplot(grid[1, 1])
        self.ax_text.axis("off")
        limits = _view_limits((run,))
        draw_intersection(self.ax_top, run, limits)
        self.ax_top.set_xlabel("x [m]", fontsize=_FONT["label"])
        self.ax_top.set_ylabel("y [m]", fontsize=_FONT["label"])
        self.ax_top.set_title(case_title(run), fontsize=_FONT["title"])
        self.fig.suptitle(run_label(run), fontsize=_FONT["title"])
        _style(self.ax_top, grid=False)
        self.paths, self.cars, self.beliefs, self.now = {}, {}, {}, {}
        for who in ("hv", "av"):
            color = _COLORS[who]
            self.paths[who] = self.ax_top.plot([], [], color=color, lw=1.0, zorder=2,
                                               gid=f"{who}-path")[0]
            self.cars[who] = _vehicle_patch(run, who, 0, fc=color, ec="black", lw=0.5, zorder=3,
                                            gid=f"{who}-vehicle")
            self.ax_top.add_patch(self.cars[who])
            other = "AV" if who == "hv" else "HV"
            self.beliefs[who] = self.ax_belief.plot(
                [], [], color=color, label=f"{who.upper()}: P({other} = leader)",
                gid=f"{who}-belief")[0]
            # The current value, so that the first frame already shows both beliefs; the
            # HV's dot is drawn larger underneath, so that equal beliefs stay visible.
            self.now[who] = self.ax_belief.plot(
                [], [], ls="none", marker="o", ms=6.0 if who == "hv" else 3.5, color=color,
                zorder=3 if who == "hv" else 4, clip_on=False, gid=f"{who}-belief-now")[0]
            self.now[who].set_in_layout(False)  # unclipped, it would pull the layout apart
        self.ax_belief.set_xlim(0.0, _state_times(run)[-1])
        self.ax_belief.set_ylim(-0.06, 1.06)
        self.ax_belief.set_xlabel("time [s]", fontsize=_FONT["label"])
        self.ax_belief.set_ylabel("belief", fontsize=_FONT["label"])
        self.ax_belief.legend(handles=list(self.beliefs.values()), loc="lower center",
                              bbox_to_anchor=(0.5, 1.0), ncols=2, frameon=False,
                              fontsize=_FONT["legend"])
        _style(self.ax_belief)
        # The key to the top view, below the status text.
        vehicles = [Patch(fc=HV_COLOR, ec="black", lw=0.5, label=hv_label([run])),
                    Patch(fc=AV_COLOR, ec="black", lw=0.5, label="AV (autonomous)")]
        self.ax_text.legend(handles=vehicles + _scene_handles(run), loc="lower left",
                            ncols=2, frameon=False, fontsize=_FONT["legend"], handlelength=1.6,
                            borderaxespad=0.2, columnspacing=1.5)
        self.text = self.ax_text.text(0.02, 0.98, "", transform=self.ax_text.transAxes,
                                      ha="left", va="top", fontsize=_FONT["label"],
                                      family="monospace", linespacing=1.4)
        self.crossing = {who: crossing_time(run, who) for who in ("hv", "av")}
        # Blitting: draw the static scene once, freeze the layout, then redraw only the
        # moving artists over a copy of that background in each frame.
        self.moving = [*self.paths.values(), *self.cars.values(), *self.beliefs.values(),
                       *self.now.values(), self.text]
        for artist in self.moving:
            artist.set_animated(True)
        self.canvas.draw()
        self.fig.set_layout_engine("none")
        self.background = self.canvas.copy_from_bbox(self.fig.bbox)

    def _status(self, k: int) -> str:
        run, t = self.run, float(self.run.log["t_s"][k])
        lines = [f"t = {t:4.1f} s   (step {k})"]
        for who in ("hv", "av"):
            name = who.upper()
            if _has_role(run, who):
                lines.append(f"{name} role: {run.log[f'{who}_role'][k]}")
            else:
                lines.append(f"{name}: {_planner(run)}, no role")
        for who in ("hv", "av"):
            tc = self.crossing[who]
            state = f"at {tc:.1f} s" if tc is not None and tc <= t else "not yet"
            lines.append(f"{who.upper()} at the crossing line: {state}")
        return "\n".join(lines)

    def render(self, k: int) -> np.ndarray:
        """The frame of decision step ``k``: RGB ``(height, width, 3)`` uint8."""
        run = self.run
        t_log = run.log["t_s"][: k + 1]
        for who in ("hv", "av"):
            x, y = _vehicle_xy(run, who, np.arange(k + 1))
            self.paths[who].set_data(x, y)
            self.cars[who].set_xy(_corners(run, who, k))
            column = belief_column(run, who)
            if column is not None:
                belief = run.log[column][: k + 1]
                self.beliefs[who].set_data(t_log, belief)
                self.now[who].set_data(t_log[-1:], belief[-1:])
        self.text.set_text(self._status(k))
        self.canvas.restore_region(self.background)
        for artist in self.moving:
            self.fig.draw_artist(artist)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()


def animation_frames(run: RunRecord, dpi: float = 120.0, width_in: float = 8.0,
                     height_in: float = 4.0) -> Iterator[np.ndarray]:
    """Render a run as frames: one per decision step (``len(run.log["step"])`` frames).

    Parameters
    ----------
    run : RunRecord
        The run to animate.
    dpi, width_in, height_in : float, optional
        Frame resolution [dots/in] and size [in]; the defaults give 960 x 480 pixels.

    Yields
    ------
    numpy.ndarray
        Frame ``k``: RGB ``(height_px, width_px, 3)`` uint8. Left, the top view of
        :func:`~persuasive.plots.topview.draw_intersection` with both vehicles at state
        ``x_k`` and their paths so far; right, the beliefs of both vehicles that the other
        leads, up to step ``k`` with a dot at the current value (so frame 0 shows the
        initial beliefs), and below them the time, each LFG player's current role, whether
        each vehicle has reached the crossing line, and the key to the top view (vehicle
        colours, crossing lines, safety circle).
    """
    scene = _AnimationScene(run, width_in, height_in, dpi)
    for k in range(len(run.log["step"])):
        yield scene.render(k)


def animate(run: RunRecord, path: str | Path, fps: int = 10, dpi: float = 120.0) -> Path:
    """Write the animation of :func:`animation_frames` as MP4 (H.264) or GIF, by extension.

    Parameters
    ----------
    run : RunRecord
        The run to animate; one frame per decision step.
    path : str or Path
        Target file, ``.mp4`` or ``.gif``, in an existing folder; written to a temporary
        sibling, then renamed.
    fps : int, optional
        Frames per second; default 10, i.e. real time for ``dt = 0.1 s``.
    dpi : float, optional
        Frame resolution [dots/in]; default 120 (960 x 480 pixels).

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    persuasive._files.OutputError
        The target is not a writable animation file
        (:func:`~persuasive.plots.files.check_animation_path`) or writing it failed (the
        encoder's error included); the one-line message names ``path``, and nothing partial
        is left beside it.
    persuasive.config.ConfigError
        ``fps`` is not an integer >= 1.
    """
    check_animation_path(path)
    if isinstance(fps, bool) or not isinstance(fps, (int, np.integer)) or fps < 1:
        raise ConfigError(f"fps = {fps!r} is out of range; allowed: integer >= 1")
    return write_frames(animation_frames(run, dpi=dpi), path, int(fps))
