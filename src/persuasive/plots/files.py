"""Figure and animation files: known extensions, checks before any work, atomic writes.

:func:`check_figure_path` and :func:`check_animation_path` check a target before anything is
computed (:func:`persuasive._files.check_output_file`): a known extension, an existing parent
that is a folder (missing folders are *not* created), and no folder in the way.
:func:`save_figure` (and :func:`~persuasive.plots.animation.animate`) write through
:func:`persuasive._files.atomic_write`: a temporary sibling, renamed into place once complete.
Every failure is a :class:`persuasive._files.OutputError` (a
:class:`~persuasive.config.ConfigError`) with a one-line message naming the user's path;
nothing partial is left beside the target.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import TYPE_CHECKING, Iterable

import numpy as np

from .._files import atomic_write, check_output_file

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: File extensions :func:`save_figure` writes, and those
#: :func:`~persuasive.plots.animation.animate` writes.
FIGURE_EXTENSIONS = (".png", ".svg", ".pdf")
ANIMATION_EXTENSIONS = (".mp4", ".gif")


def check_figure_path(path: str | Path) -> str:
    """The lower-case extension of ``path`` if :func:`save_figure` can write it.

    Raises :class:`~persuasive._files.OutputError` for an unknown extension, a missing parent
    folder, a parent that is not a folder, or a target that is a folder.
    """
    return check_output_file(path, FIGURE_EXTENSIONS, "figure")


def check_animation_path(path: str | Path) -> str:
    """The lower-case extension of ``path`` if :func:`~persuasive.plots.animation.animate` can
    write it; raises :class:`~persuasive._files.OutputError` as :func:`check_figure_path`."""
    return check_output_file(path, ANIMATION_EXTENSIONS, "animation")


def save_figure(fig: Figure, path: str | Path, dpi: float = 300.0) -> Path:
    """Save ``fig`` as PNG, SVG or PDF, chosen by the extension of ``path``, atomically.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or Path
        Target file; ``.png``, ``.svg`` or ``.pdf`` (case-insensitive). Its parent folder
        must exist.
    dpi : float, optional
        Resolution of PNG output [dots/in]; default 300.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    persuasive._files.OutputError
        The target is not a writable figure file (:func:`check_figure_path`) or writing it
        failed; the one-line message names ``path``, and ``path`` is left as it was.
    """
    path = Path(path)
    ext = check_figure_path(path)
    atomic_write(path, lambda tmp: fig.savefig(tmp, format=ext[1:], dpi=dpi,
                                                facecolor="white"))
    return path


def even_frame(frame: np.ndarray) -> np.ndarray:
    """Pad an RGB frame with white to even height and width (H.264 in yuv420p needs them)."""
    h, w = frame.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return frame
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), constant_values=255)


def write_frames(frames: Iterable[np.ndarray], path: str | Path, fps: int) -> Path:
    """Write RGB frames ``(h, w, 3)`` uint8 as ``.mp4`` (H.264) or ``.gif``, by extension,
    atomically; frames are padded to even sizes and consumed one at a time for MP4.

    The caller checks ``path`` (:func:`check_animation_path`) and ``fps`` before computing
    the frames. Raises :class:`~persuasive._files.OutputError` naming ``path`` when writing
    fails (the encoder's error included); nothing partial is left beside it.
    """
    import imageio.v2 as iio2
    import imageio.v3 as iio3

    path = Path(path)
    ext = check_animation_path(path)
    frames = (even_frame(f) for f in frames)

    def write(tmp: Path) -> None:
        if ext == ".mp4":
            writer = iio2.get_writer(tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                                     pixelformat="yuv420p", macro_block_size=2,
                                     ffmpeg_log_level="error")
            # Not a with block: on an error imageio's writer leaves ffmpeg running, and it
            # would write the temporary file again after atomic_write has removed it.
            try:
                for frame in frames:
                    writer.append_data(frame)
            except BaseException:
                with contextlib.suppress(Exception):
                    writer.close()
                raise
            writer.close()
        else:
            iio3.imwrite(tmp, np.stack(list(frames)), extension=".gif", plugin="pillow",
                         duration=1000.0 / fps, loop=0)

    atomic_write(path, write)
    return path
