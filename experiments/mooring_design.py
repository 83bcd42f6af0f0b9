"""Design a spar's catenary mooring by gradient: line length and anchor radius.

Question: how fast does gradient-based design through `jaxstring.lines`' exact
statics find a mooring that meets a stiffness target and a tension limit?

The system is the OC3-Hywind spar on the three chains of lines.txt (0.09 m,
77.7066 kg/m, EA 384.243 MN; 320 m of water; fairleads 5.2 m from the axis,
70 m down): the spar (8066 t with its turbine, centre of gravity 78 m down,
8029 m^3) has its reference point on the axis at the still-water line, its
buoyancy there plus a hydrostatic matrix with OC3's heave waterplane stiffness
(332.9 kN/m) and, in roll and pitch, the moment of its buoyancy about its
centre of buoyancy 62.07 m down, $\\rho g V z_B$. The three anchors lie on the
seabed at radius R, 120 degrees apart; all three lines have the length L.

Design: lines and anchors whose surge stiffness (the coupled 6x6 stiffness of
the spar held at its neutral pose, `coupled_stiffness`, entry (0, 0)) is
`--stiffness` (60 kN/m: OC3's is 41.2 kN/m) with the largest fairlead tension
under a 1 MN surge force (the free spar's equilibrium, `mooring_equilibrium`)
at `--tension-limit` (1.66 MN): two equations in (L, R), solved by
optimistix's Newton method from OC3's design with the exact Jacobian
(derivatives through both equilibria and through the stiffness, by the
implicit-function theorem). Along the stiffness target the tension under the
load is not monotone in L (it peaks near L = 880 m; the notes scan it), so two
designs meet both with equality; Newton from OC3's design finds the shorter.
The shortest laid length under the load is reported: 0 for both designs
(the loaded lines lift off the seabed entirely at 1 MN, OC3's too; a
drag-anchor design would add a laid-length constraint).

Writes ``results/mooring_design.{md,csv}`` (OC3's design and the new one:
L, R, surge stiffness, offset and largest tension at 1 MN; compile and solve
times, iterations) and ``results/mooring_design.png`` (offset and largest
fairlead tension against the surge force, 0 to 2 MN, both designs).

Run: ``python experiments/mooring_design.py [--quick]``.
"""

import argparse
import time


_T0 = time.perf_counter()

import _common  # noqa: F401  (thread and XLA settings first)
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from harness import clock, new_figure, savefig, set_quick, write_table

import jaxstring  # noqa: F401  (float64)
from jaxstring import lines
from jaxstring.lines import Body, MooringPoint, MooringSystem
from jaxstring.lines.statics import STATUS_MESSAGES


RHO, G = 1025.0, 9.80665
VOLUME, Z_B = 8029.21, -62.07
SPAR = dict(mass=8.066e6, cg=[0.0, 0.0, -78.0], volume=VOLUME)
HYDRO = np.diag([0, 0, 332941.0, RHO * G * VOLUME * Z_B, RHO * G * VOLUME * Z_B, 0])
ANGLES = np.deg2rad([0.0, 120.0, 240.0])
DEPTH, FAIRLEAD_R, FAIRLEAD_Z = 320.0, 5.2, -70.0
OC3 = (902.2, 853.87)  # L, anchor radius
SURGE = 1e6  # N


def base_system(kind):
    t = lines.parse_moordyn(lines.case_path("lines.txt")).types["main"]
    body = Body(kind, position=[0.0, 0.0, 0.0], name="spar", **SPAR)
    pts = [
        MooringPoint("fixed", [OC3[1] * np.cos(a), OC3[1] * np.sin(a), -DEPTH])
        for a in ANGLES
    ]
    pts += [
        MooringPoint(
            "body", [FAIRLEAD_R * np.cos(a), FAIRLEAD_R * np.sin(a), FAIRLEAD_Z], body=0
        )  # fmt: skip
        for a in ANGLES
    ]
    return MooringSystem((body,), pts, [(i, 3 + i) for i in range(3)], OC3[0],
                         t["d"], t["w"], t["EA"], depth=DEPTH, g=G, rho=RHO,
                         hydrostatics=HYDRO[None])  # fmt: skip


FREE, HELD = base_system("free"), base_system("coupled")


def design(system, L, R):
    """The system with line length L and anchor radius R (traced)."""
    s = eqx.tree_at(lambda s: s.L, system, jnp.full(3, L))
    anchors = tuple(
        jnp.stack([R * np.cos(a), R * np.sin(a), jnp.asarray(-DEPTH)]) for a in ANGLES
    )
    return eqx.tree_at(lambda s: tuple(s.points[i].position for i in range(3)), s,
                       anchors)  # fmt: skip


def surge_stiffness(L, R):
    K, _ = lines.coupled_stiffness(design(HELD, L, R), throw=False)
    return K[0, 0]


def loaded(L, R, force=SURGE):
    s = design(FREE, L, R)
    return lines.mooring_equilibrium(
        s, s.loads(body=jnp.zeros((1, 6)).at[0, 0].set(force)), throw=False
    )


def metrics(y, force=SURGE):
    """(surge stiffness, N/m; offset, m, largest fairlead tension, N, and shortest
    laid length, m, under the surge force), and the equilibrium's status."""
    L, R = y[0], y[1]
    out = loaded(L, R, force)
    m = jnp.stack(
        [surge_stiffness(L, R), out.body_position[0, 0], jnp.max(out.tension[:, 1]),
         jnp.min(out.catenary.LB)]
    )  # fmt: skip
    return m, out.status


@jax.jit
def evaluate(y, force=SURGE):
    """`metrics` and their exact Jacobian w.r.t. (L, R): the one compiled program
    of the study (the design's Newton steps, the scan and the curves call it)."""

    def both(y):
        m, status = metrics(y, force)
        return m, (m, status)

    J, (m, status) = jax.jacfwd(both, has_aux=True)(y)
    return m, J, status


def _checked(y, force=SURGE):
    y, force = (jnp.asarray(v, jnp.float64) for v in (y, force))
    m, J, status = evaluate(y, force)
    if int(status) != 0:
        raise RuntimeError(
            f"no equilibrium at L, R = {np.asarray(y)}: {STATUS_MESSAGES[int(status)]}"
        )
    return np.asarray(m), np.asarray(J)


def solve_design(k_target, t_limit, y0=OC3, rtol=1e-10, atol=1e-10, max_steps=50):
    """Newton's method on (k/k_target - 1, T/t_limit - 1) = 0 in (L, R) from `y0`,
    with the exact Jacobian; stops when a step is within atol + rtol |y| (as
    optimistix's Newton). Returns (L, R), the steps taken and the metrics there."""
    scale = np.array([k_target, 0.0, t_limit, 0.0])
    y = np.asarray(y0, float)
    for step in range(1, max_steps + 1):
        m, J = _checked(y)
        r = np.array([m[0] / scale[0] - 1.0, m[2] / scale[2] - 1.0])
        Jr = np.stack([J[0] / scale[0], J[2] / scale[2]])
        dy = np.linalg.solve(Jr, -r)
        y = y + dy
        if np.all(np.abs(dy) <= atol + rtol * np.abs(y)):
            break
    m, _ = _checked(y)
    return y, step, m


def curve(L, R, forces):
    """Offset, largest fairlead tension and status under each surge force."""
    y = jnp.asarray([L, R], jnp.float64)
    out = [evaluate(y, jnp.asarray(f, jnp.float64)) for f in forces]
    m = np.asarray([o[0] for o in out])
    return m[:, 1], m[:, 2], np.asarray([int(o[2]) for o in out])


def main(quick=False, stiffness=60e3, tension_limit=1.66e6):
    set_quick(quick)
    # the first call traces and compiles the study's one program
    (base, _), first_s, _ = clock(lambda: _checked(OC3))
    _, again_s, _ = clock(lambda: _checked(OC3))
    (y, steps, m), solve_s, _ = clock(lambda: solve_design(stiffness, tension_limit))
    L, R = (float(v) for v in y)
    scan = []
    if not quick:
        # the tension under the load along the stiffness target
        from scipy.optimize import brentq

        for Ls in (L - 20.0, L, L + 20.0, 880.0, 900.0, 920.0):
            Rs = brentq(lambda r: _checked((Ls, r))[0][0] / stiffness - 1.0,
                        Ls - 80.0, Ls - 10.0, xtol=1e-9)  # fmt: skip
            t = _checked((Ls, Rs))[0][2]
            scan.append(f"L = {Ls:.1f} m, R = {Rs:.1f} m: {t / 1e3:.1f} kN")
    forces = np.linspace(0.0, 2e6, 9 if quick else 41)
    curves = {
        name: curve(Lc, Rc, forces)
        for name, (Lc, Rc) in (("OC3-Hywind", OC3), ("designed", (L, R)))
    }
    total_s = time.perf_counter() - _T0
    rows = [
        dict(design="OC3-Hywind", L_m=OC3[0], anchor_radius_m=OC3[1],
             surge_stiffness_kN_m=base[0] / 1e3, offset_1MN_m=base[1],
             max_tension_1MN_kN=base[2] / 1e3, min_laid_length_1MN_m=base[3],
             newton_steps=None, compile_s=None, solve_s=None),
        dict(design="designed", L_m=L, anchor_radius_m=R,
             surge_stiffness_kN_m=m[0] / 1e3, offset_1MN_m=m[1],
             max_tension_1MN_kN=m[2] / 1e3, min_laid_length_1MN_m=m[3],
             newton_steps=int(steps), compile_s=first_s - again_s,
             solve_s=solve_s),
    ]  # fmt: skip
    notes = [
        f"targets: surge stiffness {stiffness / 1e3:g} kN/m, largest fairlead "
        f"tension under a {SURGE / 1e6:g} MN surge force {tension_limit / 1e3:g} kN",
        "solve_s: Newton from OC3's design to the new one, compiled (each step: "
        "the free spar's equilibrium, the held spar's stiffness, and the exact "
        "Jacobian of both w.r.t. (L, R), one call of the compiled program); "
        "compile_s: its first call less a second one",
        f"the study from the start of the script to the curves (imports, "
        f"compilation, design, scan, {2 * len(forces)} equilibria of the curves): "
        f"{total_s:.1f} s",
    ]
    if scan:
        notes.append("on the stiffness target: " + "; ".join(scan))
    write_table(
        "mooring_design",
        rows,
        [
            "design",
            "L_m",
            "anchor_radius_m",
            "surge_stiffness_kN_m",
            "offset_1MN_m",
            "max_tension_1MN_kN",
            "min_laid_length_1MN_m",
            "newton_steps",
            "compile_s",
            "solve_s",
        ],  # fmt: skip
        "Mooring design by gradient: line length and anchor radius for a "
        "surge-stiffness target and a tension limit",
        notes=notes,
    )
    fig, axes = new_figure(ncols=2, w=5.0, h=3.8)
    a1, a2 = axes[0]
    for name, (Lc, Rc), style in (("OC3-Hywind", OC3, "--"), ("designed", (L, R), "-")):
        x, t, st = curves[name]
        ok = st == 0
        a1.plot(forces[ok] / 1e6, x[ok], style,
                label=f"{name}: L = {Lc:.1f} m, R = {Rc:.1f} m")  # fmt: skip
        a2.plot(x[ok], t[ok] / 1e6, style, label=name)
    a2.axhline(tension_limit / 1e6, color="k", lw=0.8, ls=":")
    a2.axvline(m[1], color="0.5", lw=0.8, ls=":")
    a1.set_xlabel("surge force, MN")
    a1.set_ylabel("surge offset, m")
    a2.set_xlabel("surge offset, m")
    a2.set_ylabel("largest fairlead tension, MN")
    a1.legend(fontsize=8)
    a2.legend(fontsize=8)
    a1.grid(alpha=0.3)
    a2.grid(alpha=0.3)
    savefig(fig, "mooring_design")
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--stiffness", type=float, default=60e3, help="N/m")
    p.add_argument("--tension-limit", type=float, default=1.66e6, help="N")
    a = p.parse_args()
    main(quick=a.quick, stiffness=a.stiffness, tension_limit=a.tension_limit)
