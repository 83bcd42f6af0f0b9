"""Animations of a run as GIFs, written with matplotlib's Pillow writer (no ffmpeg).

Each system's `plot.animate` draws its own frames; this module picks the frames and
writes the file. Like the plot modules it is imported on demand, never by the core.
"""

import textwrap

import numpy as np


def wrap_title(title: str, width: int = 56) -> str:
    """A long title on several lines (animations are small)."""
    return textwrap.fill(title, width)


def frame_indices(ts, n_valid: int, frames: int) -> np.ndarray:
    """At most `frames` saved indices, evenly spaced in time over the valid rows."""
    if frames < 2:
        raise ValueError(f"`frames` must be an integer >= 2; got {frames!r}.")
    ts = np.asarray(ts, dtype=float)[:n_valid]
    if ts.size == 0:
        return np.zeros((0,), dtype=int)
    targets = np.linspace(ts[0], ts[-1], min(frames, ts.size))
    return np.unique(np.abs(ts[None, :] - targets[:, None]).argmin(axis=1))


def write_gif(fig, draw, n_frames: int, path: str, fps: int = 20) -> str:
    """Call `draw(i)` for frames i = 0 .. n_frames - 1 of figure `fig` and write them
    to the GIF `path`; returns the path."""
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    draw(0)
    fig.tight_layout()
    anim = FuncAnimation(fig, draw, frames=n_frames, blit=False)
    anim.save(path, writer=PillowWriter(fps=fps))
    plt.close(fig)
    return path
