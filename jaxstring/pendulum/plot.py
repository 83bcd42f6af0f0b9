"""Figures and animations of a string-pendulum Trajectory (matplotlib).

Not imported by the core modules, and it leaves matplotlib's backend as the user set
it (the `jaxstring` command selects the file-only Agg backend itself).
"""

import numpy as np

from .._animate import canvas, frame_indices, save_figure, write_gif


def _valid_rows(traj) -> int:
    """Number of leading saved rows that hold data (later rows are NaN)."""
    n = int(np.asarray(traj.n_valid))
    pos = np.asarray(traj.positions)[:n]
    finite = np.all(np.isfinite(pos.reshape(pos.shape[0], -1)), axis=1)
    if not np.all(finite):
        n = int(np.argmin(finite))
    return n


def snapshot_indices(ts, n_valid: int, every: float = 0.1) -> np.ndarray:
    """Saved indices closest to the multiples of `every` among the first `n_valid`."""
    ts = np.asarray(ts, dtype=float)[:n_valid]
    if ts.size == 0:
        return np.zeros((0,), dtype=int)
    if not every > 0:
        raise ValueError(f"`every` must be > 0 s; got {every!r}.")
    first = np.ceil((ts[0] - 1e-9) / every)
    last = np.floor((ts[-1] + 1e-9) / every)
    targets = np.arange(first, last + 1) * every
    if targets.size == 0:
        return np.array([0], dtype=int)
    idx = np.abs(ts[None, :] - targets[:, None]).argmin(axis=1)
    return np.unique(idx)


def snapshots(traj, ax=None, every: float = 0.1):
    """Plot string configurations every `every` seconds (Poth et al., Figs 3-8).

    Thin grey lines for the string (pivot included), a dot for the end mass, the
    pivot marked, equal aspect. Rows after a failure (NaN) are skipped.
    Returns the axes.
    """
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6, 6))
    n = _valid_rows(traj)
    pos = np.asarray(traj.positions)
    idx = snapshot_indices(traj.ts, n, every)
    for j, i in enumerate(idx):
        x, y = pos[i, :, 0], pos[i, :, 1]
        ax.plot(x, y, color="0.45", lw=0.7, zorder=1)
        ax.plot(
            x[-1],
            y[-1],
            "o",
            ms=3.5,
            color="C0" if j < len(idx) - 1 else "C3",
            zorder=2,
        )
    if pos.shape[0] > 0:
        px, py = pos[0, 0, 0], pos[0, 0, 1]
        if np.isfinite(px) and np.isfinite(py):
            ax.plot(px, py, "k^", ms=8, zorder=3, label="pivot")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"string every {every:g} s ({len(idx)} snapshots)")
    ax.grid(True, lw=0.3, alpha=0.5)
    return ax


def time_series(traj, axes):
    """Plot tensions at the pivot and at the end, and the total energy, over time.

    `axes`: a pair `(ax_tension, ax_energy)`. Returns `axes`.
    """
    ax_t, ax_e = axes
    n = _valid_rows(traj)
    ts = np.asarray(traj.ts)[:n]
    ten = np.asarray(traj.tension)[:n]
    en = np.asarray(traj.energy)[:n]
    if ten.shape[0] > 0:
        ax_t.plot(ts, ten[:, 0], color="C0", lw=1.0, label="at pivot")
        ax_t.plot(ts, ten[:, -1], color="C3", lw=1.0, label="at end mass")
        ax_t.legend(loc="best", fontsize="small")
    ax_t.set_ylabel("tension [N]")
    ax_t.grid(True, lw=0.3, alpha=0.5)
    ax_e.plot(ts, en, color="k", lw=1.0)
    ax_e.set_ylabel("total energy [J]")
    ax_e.set_xlabel("t [s]")
    ax_e.grid(True, lw=0.3, alpha=0.5)
    return axes


def summary_figure(traj, path, title: str = ""):
    """Snapshots (left, large) with tension and energy panels (right); save a PNG.

    Returns `path`.
    """
    # A bare Figure (not pyplot's): no backend or figure manager to set up, and
    # nothing for pyplot to keep open after the file is written.
    from matplotlib.figure import Figure

    # Fixed margins: a constrained layout draws the figure once more to place it.
    fig = Figure(figsize=(12, 6))
    grid = fig.add_gridspec(
        2, 2, width_ratios=(1.25, 1.0), left=0.06, right=0.98, bottom=0.08,
        top=0.86, wspace=0.18, hspace=0.12,
    )  # fmt: skip
    ax_s = fig.add_subplot(grid[:, 0])
    ax_t = fig.add_subplot(grid[0, 1])
    ax_e = fig.add_subplot(grid[1, 1], sharex=ax_t)
    snapshots(traj, ax=ax_s)
    time_series(traj, (ax_t, ax_e))
    return save_figure(fig, path, title, dpi=120, tight=False)


def animation_frames(traj, frames: int = 60):
    """(times, node positions `(F, k + 1, dim)`) of the animation's frames: at most
    `frames` saved states, evenly spaced over the valid rows."""
    idx = frame_indices(traj.ts, _valid_rows(traj), frames)
    return np.asarray(traj.ts)[idx], np.asarray(traj.positions)[idx]


def animate(traj, path, frames: int = 60, fps: int = 20, title: str = ""):
    """Write the string's motion as a GIF: the string through its nodes, the end mass
    as a dot, the fixed pivot, equal axes, the time in a corner. Returns the path."""
    ts, pos = animation_frames(traj, frames)
    reach = max(float(np.nanmax(np.abs(pos[..., :2]))), 1e-9) * 1.1
    lim = (-reach, reach)
    fig, ax, label = canvas(lim, lim, "x, m", "y, m", title)
    ax.plot(0.0, 0.0, "k^", ms=8)
    (line,) = ax.plot([], [], color="0.3", lw=1.2)
    (mass,) = ax.plot([], [], "o", color="tab:red", ms=7)

    def draw(i):
        line.set_data(pos[i, :, 0], pos[i, :, 1])
        mass.set_data(pos[i, -1:, 0], pos[i, -1:, 1])
        label.set_text(f"t = {ts[i]:.3f} s")

    return write_gif(fig, draw, len(ts), path, fps)
