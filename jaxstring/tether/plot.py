"""Figures of a tether Trajectory, like Blintsov (2017) Figs 5-6, and animations.

Not imported by the core modules, and it leaves matplotlib's backend as the user set
it (the `jaxstring` command selects the file-only Agg backend itself).

Panels: (a) cable configurations at chosen times (x-z plane: x north, z up), (b) the
length error (L_r - sum of link lengths)/L_r in percent (and L_r when it changes),
(c) root (inboard) force components, (d) running-end force components (the forces of
the tether on the mounts, N).
"""

import matplotlib.pyplot as plt
import numpy as np

from .._animate import canvas, frame_indices, save_figure, write_gif


PAPER_TIMES = (0.0, 10.0, 22.5, 35.0, 45.0, 57.5, 70.0)  # Fig 5a: t0..t6


def _valid(traj) -> int:
    n = int(np.asarray(traj.n_valid))
    pos = np.asarray(traj.positions)[:n]
    finite = np.all(np.isfinite(pos.reshape(pos.shape[0], -1)), axis=1)
    return n if np.all(finite) else int(np.argmin(finite))


def configurations(traj, ax=None, times=PAPER_TIMES):
    """Plot the cable (mounts included) at the saved times nearest `times` (s)."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 6))
    n = _valid(traj)
    ts = np.asarray(traj.ts)[:n]
    nodes = np.asarray(traj.nodes)[:n]
    if n == 0:
        return ax
    idx = sorted({int(np.abs(ts - t).argmin()) for t in times})
    cmap = plt.get_cmap("viridis")
    for j, i in enumerate(idx):
        c = cmap(j / max(len(idx) - 1, 1))
        ax.plot(
            nodes[i, :, 0], nodes[i, :, 2], color=c, lw=1.0, label=f"t = {ts[i]:.4g} s"
        )
        ax.plot(nodes[i, -1, 0], nodes[i, -1, 2], "o", color=c, ms=3)
    ax.plot(nodes[0, 0, 0], nodes[0, 0, 2], "k^", ms=8, label="root")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (north) [m]")
    ax.set_ylabel("z (up) [m]")
    ax.set_title("(a) cable configurations")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize="x-small", loc="best")
    return ax


def length_error(traj, ax=None):
    """Plot (L_r - sum of link lengths)/L_r in percent over time."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 3))
    n = _valid(traj)
    ts = np.asarray(traj.ts)[:n]
    ax.plot(ts, 100 * np.asarray(traj.length_error)[:n], color="k", lw=1.0)
    ax.set_ylabel("(L_r - L_a)/L_r [%]")
    ax.set_xlabel("t [s]")
    ax.grid(True, lw=0.3, alpha=0.5)
    L_r = np.asarray(traj.released_length)[:n]
    if n and np.ptp(L_r) > 0:
        ax2 = ax.twinx()
        ax2.plot(ts, L_r, color="C2", lw=1.0, ls="--")
        ax2.set_ylabel("L_r [m]", color="C2")
    ax.set_title("(b) length error")
    return ax


def end_force(traj, ax=None, end: str = "root"):
    """Plot the components and magnitude of the force on the `end` mount
    (`"root"` or `"fast"`)."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 3))
    n = _valid(traj)
    ts = np.asarray(traj.ts)[:n]
    F = np.asarray(getattr(traj, f"{end}_force"))[:n]
    for c, name in enumerate("xyz"):
        ax.plot(ts, F[:, c], lw=1.0, label=f"F{name}")
    ax.plot(ts, np.linalg.norm(F, axis=1), color="k", lw=1.2, label="|F|")
    ax.set_ylabel("force [N]")
    ax.set_xlabel("t [s]")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize="x-small", loc="best")
    ax.set_title("(c) root (inboard) end" if end == "root" else "(d) running end")
    return ax


def summary_figure(traj, path, title: str = "", times=PAPER_TIMES):
    """The four panels of the paper's Figs 5-6; save a PNG and return `path`."""
    fig = plt.figure(figsize=(13, 8), layout="constrained")
    grid = fig.add_gridspec(3, 2, width_ratios=(1.0, 1.2))
    configurations(traj, fig.add_subplot(grid[:, 0]), times=times)
    ax_b = fig.add_subplot(grid[0, 1])
    length_error(traj, ax_b)
    end_force(traj, fig.add_subplot(grid[1, 1], sharex=ax_b), "root")
    end_force(traj, fig.add_subplot(grid[2, 1], sharex=ax_b), "fast")
    return save_figure(fig, path, title, tight=False)


def animation_frames(traj, frames: int = 60):
    """(times, cable points `(F, N + 2, 3)`: mounts and elements) of the animation's
    frames: at most `frames` saved states, evenly spaced over the valid rows."""
    idx = frame_indices(traj.ts, _valid(traj), frames)
    return np.asarray(traj.ts)[idx], np.asarray(traj.nodes)[idx]


def animate(traj, path, frames: int = 60, fps: int = 20, title: str = ""):
    """Write the cable's motion in the x-z plane (x north, z up) as a GIF, root mount
    and running end marked, the time in a corner. Returns the path."""
    ts, nodes = animation_frames(traj, frames)
    x, z = nodes[..., 0], nodes[..., 2]
    pad = 0.05 * max(float(np.ptp(x)), float(np.ptp(z)), 1.0)
    xlim = (float(x.min()) - pad, float(x.max()) + pad)
    zlim = (float(z.min()) - pad, float(z.max()) + pad)
    fig, ax, label = canvas(xlim, zlim, "x (north), m", "z (up), m", title, (6, 5))
    (line,) = ax.plot([], [], color="tab:blue", lw=1.0)
    (root,) = ax.plot([], [], "k^", ms=7)
    (end,) = ax.plot([], [], "o", color="tab:red", ms=5)

    def draw(i):
        line.set_data(x[i], z[i])
        root.set_data(x[i, :1], z[i, :1])
        end.set_data(x[i, -1:], z[i, -1:])
        label.set_text(f"t = {ts[i]:.2f} s")

    return write_gif(fig, draw, len(ts), path, fps)
