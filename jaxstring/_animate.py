"""Writing figures and animations (GIFs through matplotlib's Pillow writer: no ffmpeg).

Each system's `plot.animate` draws its own frames; this module picks the frames and
writes the files. Like the plot modules it is imported on demand, never by the core.
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


def save_figure(fig, path, title: str = "", dpi: int = 110, tight: bool = True):
    """Give `fig` its title, write it to `path` and close it; returns the path."""
    import sys

    if title:
        fig.suptitle(title, fontsize=10)
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt = sys.modules.get("matplotlib.pyplot")  # a bare Figure needs no closing
    if plt is not None:
        plt.close(fig)
    return path


def canvas(xlim, ylim, xlabel: str, ylabel: str, title: str = "", size=(5, 5)):
    """A figure with one equal-aspect axes for an animation, and its time label."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(wrap_title(title), fontsize=8)
    label = ax.text(0.02, 0.96, "", transform=ax.transAxes, va="top")
    return fig, ax, label


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
