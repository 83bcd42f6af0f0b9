"""Figures and animations of the FPSO + shuttle tandem (matplotlib).

Not imported by the core modules, and it leaves matplotlib's backend as the user set
it (the `jaxstring` command selects the file-only Agg backend itself). Earth frame: x
north, y east; plots put east to the right and north up.
"""

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Polygon

from .._animate import canvas, frame_indices, save_figure, write_gif


def hull_outline(x, y, psi, L, B):
    """Plan-view outline (east, north) of a hull: a box with a pointed bow."""
    xb = np.array([-L / 2, 0.35 * L, L / 2, 0.35 * L, -L / 2])
    yb = np.array([-B / 2, -B / 2, 0.0, B / 2, B / 2])
    c, s = np.cos(psi), np.sin(psi)
    xn = x + c * xb - s * yb
    ye = y + s * xb + c * yb
    return np.stack([ye, xn], axis=1)


def _valid(traj):
    return int(np.asarray(traj.n_valid))


def draw_hulls(ax, model, y, alpha=1.0, colors=("tab:blue", "tab:orange")):
    """Draw the hulls of state `y` (6 states per vessel) on `ax`."""
    y = np.asarray(y).reshape(-1, 6)
    hulls = [model.fpso] + ([model.shuttle] if y.shape[0] > 1 else [])
    for i, h in enumerate(hulls):
        poly = hull_outline(y[i, 0], y[i, 1], y[i, 2], float(h.L), float(h.B))
        ax.add_patch(
            Polygon(poly, closed=True, fc=colors[i], ec="k", lw=0.5, alpha=alpha)
        )


def trajectories_from_above(traj, model, ax=None, n_snapshots=6, title=None):
    """Paths of both hull centres seen from above with hull snapshots and the hawser."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 6))
    n = _valid(traj)
    ys = np.asarray(traj.ys)[:n].reshape(n, -1, 6)
    for i, c in enumerate(("tab:blue", "tab:orange")[: ys.shape[1]]):
        ax.plot(ys[:, i, 1], ys[:, i, 0], color=c, lw=0.8)
    idx = np.linspace(0, n - 1, n_snapshots).astype(int)
    for k, j in enumerate(idx):
        a = 0.15 + 0.7 * k / max(len(idx) - 1, 1)
        draw_hulls(ax, model, ys[j].reshape(-1), alpha=a)
        if "fairleads" in traj.obs:
            f = np.asarray(traj.fairleads)[j]
            ax.plot(f[:, 1], f[:, 0], "k-", lw=0.8, alpha=a)
    ax.plot([0], [0], "k+", ms=10)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("east, m")
    ax.set_ylabel("north, m")
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def span_and_tension(traj, axes=None, d_ref=None):
    """Span, tension, headings and actuator output over time (4 axes)."""
    if axes is None:
        _, axes = plt.subplots(4, 1, figsize=(7, 8), sharex=True)
    n = _valid(traj)
    t = np.asarray(traj.ts)[:n]
    axes[0].plot(t, np.asarray(traj.span)[:n])
    if d_ref is not None:
        axes[0].axhline(d_ref, color="k", ls="--", lw=0.6)
    axes[0].set_ylabel("span d, m")
    axes[1].plot(t, np.asarray(traj.tension)[:n] / 1e3)
    axes[1].set_ylabel("tension, kN")
    h = np.degrees(np.asarray(traj.headings)[:n])
    axes[2].plot(t, h[:, 0], label="FPSO")
    axes[2].plot(t, h[:, 1], label="shuttle")
    axes[2].legend(fontsize=8)
    axes[2].set_ylabel("heading, deg")
    c = np.asarray(traj.control)[:n]
    axes[3].plot(t, c[:, 0] / 1e6, label="X_ctl, MN")
    axes[3].plot(t, c[:, 1] / 1e8, label="N_ctl, 1e8 N m")
    axes[3].legend(fontsize=8)
    axes[3].set_ylabel("actuator")
    axes[3].set_xlabel("t, s")
    return axes


def tandem_figure(traj, model, path, title="", d_ref=None):
    """Plan view + time series in one PNG."""
    fig = plt.figure(figsize=(13, 7))
    ax0 = fig.add_subplot(1, 2, 1)
    trajectories_from_above(traj, model, ax=ax0)
    axes = [fig.add_subplot(4, 2, 2 * k + 2) for k in range(4)]
    span_and_tension(traj, axes=axes, d_ref=d_ref)
    return save_figure(fig, path, title)


KIND_STYLE = {
    "stable": ("tab:green", "o"),
    "saddle": ("tab:red", "x"),
    "oscillatory unstable": ("tab:purple", "s"),
}


def equilibrium_map(cells, results, path, title="Tandem equilibria"):
    """Counts table as a heat map over (Delta_w, V_w) and the equilibria in
    (psi1, psi2). `cells`: list of (V_w, Delta_w_deg); `results`: list of lists of
    `Equilibrium`."""
    from .analysis import counts

    Vs = sorted({c[0] for c in cells})
    Ds = sorted({c[1] for c in cells})
    grid = np.full((len(Vs), len(Ds)), np.nan)
    labels = {}
    for (v, d), eqs in zip(cells, results):
        i, j = Vs.index(v), Ds.index(d)
        taut, adm, stab = counts(eqs)
        grid[i, j] = stab
        labels[(i, j)] = f"{taut}/{adm}/{stab}"
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(13, 5))
    im = ax0.imshow(grid, origin="lower", cmap="Greens", vmin=0, vmax=3, aspect="auto")
    for (i, j), s in labels.items():
        ax0.text(j, i, s, ha="center", va="center", fontsize=8)
    ax0.set_xticks(range(len(Ds)), [f"{d:g}" for d in Ds])
    ax0.set_yticks(range(len(Vs)), [f"{v:g}" for v in Vs])
    ax0.set_xlabel("Delta_w, deg (wind vs current, coming-from)")
    ax0.set_ylabel("V_w, m/s")
    ax0.set_title("taut / admissible / stable (colour: stable)", fontsize=9)
    fig.colorbar(im, ax=ax0, label="stable admissible equilibria")
    seen = set()
    for (v, d), eqs in zip(cells, results):
        for e in eqs:
            c, m = KIND_STYLE[e.kind]
            h = e.headings_deg
            lab = e.kind if e.kind not in seen else None
            seen.add(e.kind)
            ax1.scatter(
                h[0],
                h[1],
                c=c,
                marker=m,
                s=18 if e.admissible else 6,
                alpha=1.0 if e.admissible else 0.35,
                label=lab,
            )
    ax1.set_xlabel("FPSO heading psi1, deg")
    ax1.set_ylabel("shuttle heading psi2, deg")
    ax1.set_xlim(-185, 185)
    ax1.set_ylim(-185, 185)
    ax1.legend(fontsize=8)
    ax1.set_title("all equilibria (faint: hulls overlap)", fontsize=9)
    return save_figure(fig, path, title)


def sweep_figure(xs, eigs, path, xlabel, title="", marks=None):
    """Real part (and imaginary part) of the leading eigenvalue over a parameter."""
    eigs = np.asarray(eigs)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(xs, eigs.real, "o-", label="Re lambda")
    if np.any(np.abs(eigs.imag) > 0):
        ax.plot(xs, np.abs(eigs.imag) / 10, "s--", label="|Im lambda| / 10")
    ax.axhline(0, color="k", lw=0.6)
    for x in marks or ():
        ax.axvline(x, color="r", ls=":", lw=0.8)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("leading eigenvalue, 1/s")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=9)
    return save_figure(fig, path)


def animation_frames(traj, frames: int = 60):
    """(times, vessel states `(F, n, 6)`, fairleads `(F, 2, 2)`) of the animation's
    frames: at most `frames` saved states, evenly spaced over the valid rows."""
    idx = frame_indices(traj.ts, _valid(traj), frames)
    ys = np.asarray(traj.ys)[idx]
    n = np.asarray(traj.positions).shape[1]
    fairleads = traj.obs.get("fairleads")
    fairleads = None if fairleads is None else np.asarray(fairleads)[idx]
    return np.asarray(traj.ts)[idx], ys[:, : 6 * n].reshape(len(idx), n, 6), fairleads


def animate(traj, model, path, frames: int = 60, fps: int = 20, title: str = ""):
    """Write the vessels' motion seen from above as a GIF: hulls, the hawser between
    the fairleads, the time in a corner. `model`: the `Tandem` or `MooredFPSO` (hull
    particulars). Returns the path."""
    ts, states, fairleads = animation_frames(traj, frames)
    east, north = states[..., 1], states[..., 0]
    reach = 0.6 * float(model.fpso.L)
    elim = (float(east.min()) - reach, float(east.max()) + reach)
    nlim = (float(north.min()) - reach, float(north.max()) + reach)
    fig, ax, label = canvas(elim, nlim, "east, m", "north, m", title, (6, 6))

    def draw(i):
        for artist in list(ax.patches) + list(ax.lines):
            artist.remove()
        draw_hulls(ax, model, states[i].reshape(-1))
        if fairleads is not None:
            f = fairleads[i]
            ax.plot(f[:, 1], f[:, 0], color="k", lw=1.0)
        label.set_text(f"t = {ts[i]:.0f} s")

    return write_gif(fig, draw, len(ts), path, fps)
