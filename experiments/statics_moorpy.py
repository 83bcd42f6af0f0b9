"""Catenary statics of jaxstring against MoorPy: agreement and cost.

Question: on the OC3-Hywind mooring (lines.txt: three 902.2 m chains, 320 m of
water), how close are `jaxstring.lines.mooring_equilibrium` and
`coupled_stiffness` to MoorPy 1.3 (`solveEquilibrium`, `getCoupledStiffness` by
finite differences, `getCoupledStiffnessA` analytic), and what does one
equilibrium + stiffness cost after compilation (compile time apart)? And the
gradient of a design objective with respect to every design parameter: its cost
against one solve, and against MoorPy's finite differences (two re-solved
equilibria per parameter)?

Systems (MoorPy's g = 9.81 in both codes):

- `fairleads held`: the deck as it is, three coupled fairlead points (9 coupled
  degrees of freedom, none free);
- `coupled spar`: the fairleads on one coupled body at the still-water line (6);
- `buoyed spar`: the same with a 10 m^3 buoy on each line, 45 % of the way from
  its anchor (9 free degrees of freedom re-balanced, 6 coupled);
- `free spar`: the OC3 spar (8066 t, CG 78 m down, 8029 m^3, heave waterplane
  stiffness 332.9 kN/m) free under a 1 MN surge force (6 free).

Gradient: d(fairlead tension of line 1)/d(theta) of the free spar under the
surge force, theta = the three line lengths, the three EA, the three masses per
length, the anchors' x and y and the six load components (21 parameters;
the anchors' depth is left out: a jaxstring line's seabed lies at its anchor's
height, MoorPy's stays at the water depth): `jax.grad` of the solve, against
MoorPy's central differences (42 re-solved equilibria, its System changed in
place). Their agreement is reported too.

Times: the median of repeated calls in this process (jaxstring's first call
apart, as `compile_s`); MoorPy's calls each re-solve from the deck's pose.

Run: ``python experiments/statics_moorpy.py [--quick]``. Writes
``results/statics_moorpy.{md,csv}`` and ``results/statics_moorpy_gradient.{md,csv}``.
"""

import argparse
import statistics

import _common  # noqa: F401  (thread and XLA settings first)
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from harness import clock, set_quick, write_table

import jaxstring  # noqa: F401  (float64)
from jaxstring import lines
from jaxstring.lines import Body, MooringPoint, MooringSystem


DECK = lines.case_path("lines.txt")
G = 9.81  # MoorPy's
SPAR = dict(mass=8.066e6, cg=[0.0, 0.0, -78.0], volume=8029.21)
K33 = 332941.0


def systems():
    held = lines.mooring_system(DECK, g=G)
    coupled = lines.mooring_system(
        DECK, g=G, vessel=Body("coupled", position=[0.0, 0.0, 0.0])
    )
    free = lines.mooring_system(
        DECK,
        g=G,
        vessel=Body("free", position=[0.0, 0.0, 0.0], name="spar", **SPAR),
        hydrostatics=np.diag([0.0, 0.0, K33, 0.0, 0.0, 0.0]),
        hydrostatic_pose=np.zeros(6),
    )
    return {
        "fairleads held": (held, None),
        "coupled spar": (coupled, None),
        "buoyed spar": (buoyed(), None),
        "free spar": (free, free.loads(body={0: [1e6, 0, 0, 0, 0, 0]})),
    }


def buoyed():
    deck = lines.parse_moordyn(DECK)
    pos = {p["id"]: np.array(p["position"]) for p in deck.points}
    t = deck.types["main"]
    pts = [MooringPoint("fixed", pos[i + 1]) for i in range(3)]
    for i in range(3):
        c = pos[i + 1] + 0.45 * (pos[i + 4] - pos[i + 1])
        c[2] = -200.0
        pts.append(MooringPoint("free", c, 2e3, 10.0))
    pts += [MooringPoint("body", pos[i + 4], body=0) for i in range(3)]
    attach = [(i, 3 + i) for i in range(3)] + [(3 + i, 6 + i) for i in range(3)]
    body = Body("coupled", position=[0.0, 0.0, 0.0])
    L = [450.0] * 3 + [452.2] * 3
    return MooringSystem((body,), pts, attach, L, t["d"], t["w"], t["EA"],
                         depth=320.0, g=G)  # fmt: skip


def median_time(fn, repeats):
    times = []
    out = None
    for _ in range(repeats):
        out, w, _ = clock(fn)
        times.append(w)
    return out, statistics.median(times)


def compare(name, system, loads, repeats):
    from jaxstring.testing.moorpy_peer import moorpy_system, moorpy_tensions

    has_coupled = system.n_coupled > 0

    def ours():
        if has_coupled:
            K, out = lines.coupled_stiffness(system, loads)
        else:
            out = lines.mooring_equilibrium(system, loads)
            K = None
        return jax.block_until_ready((K, out))

    (_, first_s, _) = clock(ours)
    (K, out), run_s = median_time(ours, repeats)
    ms = moorpy_system(system, loads)

    def theirs_eq():
        for b in ms.bodyList:  # back to the start, so that every call re-solves
            if b.type == 0:
                b.setPosition(np.zeros(6))
        for p, q in zip(ms.pointList, system.points):
            if p.type == 0:
                p.setPosition(np.asarray(q.position))
        ms.solveEquilibrium(tol=1e-6, maxIter=500)

    _, mp_eq_s = median_time(theirs_eq, repeats)
    row = dict(
        system=name,
        n_free=system.n_free,
        n_coupled=system.n_coupled,
        compile_s=first_s - run_s,
        jaxstring_ms=1e3 * run_s,
        moorpy_eq_ms=1e3 * mp_eq_s,
        tension_rel_diff=float(
            np.max(np.abs(np.asarray(out.tension) - moorpy_tensions(ms)))
            / np.max(moorpy_tensions(ms))
        ),
        iterations=int(out.iterations),
        converged=bool(out.converged),
    )
    if has_coupled:
        KF, mp_k_s = median_time(lambda: ms.getCoupledStiffness(dth=0.01), repeats)
        KA, mp_ka_s = median_time(ms.getCoupledStiffnessA, repeats)
        K = np.asarray(K)
        scale = np.abs(KA).max()
        big = np.abs(KA) > 1e-4 * scale
        row.update(
            moorpy_K_fd_ms=1e3 * mp_k_s,
            moorpy_K_analytic_ms=1e3 * mp_ka_s,
            K_vs_analytic=float(np.max(np.abs(K - KA)) / scale),
            K_vs_fd_entry=float(np.max(np.abs(K[big] - KF[big]) / np.abs(KF[big]))),
            speedup_vs_fd=(mp_eq_s + mp_k_s) / run_s,
        )
    else:
        row.update(speedup_vs_fd=mp_eq_s / run_s)
    return row


# ---------------------------------------------------------------------------
# Gradient of a design objective


def design_parameters(system, loads):
    """theta: L (3), EA (3), w (3), anchor x and y (6), body load (6)."""
    anchors = jnp.stack([system.points[i].position[:2] for i in range(3)]).ravel()
    return jnp.concatenate([system.L, system.EA, system.w, anchors, loads.body[0]])


def with_parameters(system, theta):
    s = eqx.tree_at(lambda s: (s.L, s.EA, s.w), system,
                    (theta[0:3], theta[3:6], theta[6:9]))  # fmt: skip
    xy = theta[9:15].reshape(3, 2)
    s = eqx.tree_at(
        lambda s: tuple(s.points[i].position for i in range(3)),
        s,
        tuple(s.points[i].position.at[:2].set(xy[i]) for i in range(3)),
    )
    return s, s.loads(body=theta[15:21][None])


def gradient_study(system, loads, repeats):
    from jaxstring.testing.moorpy_peer import moorpy_system

    theta0 = design_parameters(system, loads)
    n = theta0.shape[0]

    def objective(theta):
        s, ld = with_parameters(system, theta)
        return lines.mooring_equilibrium(s, ld, tol=1e-12).tension[0, 1]

    grad = jax.jit(jax.grad(objective))
    value = jax.jit(objective)
    _, g_first, _ = clock(lambda: jax.block_until_ready(grad(theta0)))
    g, g_s = median_time(lambda: jax.block_until_ready(grad(theta0)), repeats)
    _, v_first, _ = clock(lambda: jax.block_until_ready(value(theta0)))
    v, v_s = median_time(lambda: jax.block_until_ready(value(theta0)), repeats)

    # MoorPy: central differences of its tension, one System changed in place
    # and re-solved from the start pose per evaluation
    th = np.asarray(theta0)
    steps = np.maximum(1e-6 * np.abs(th), 1e-3)
    steps[15:21] = 1e2  # N, N m
    ms = moorpy_system(system, loads)
    body = ms.bodyList[0]

    def mp_tension(theta):
        for i, ln in enumerate(ms.lineList):
            ln.L = theta[i]
            ln.EA = theta[3 + i]
            ln.type["EA"] = theta[3 + i]
            ln.type["m"] = theta[6 + i]
        for i in range(3):
            r = np.array(ms.pointList[i].r, float)
            r[:2] = theta[9 + 2 * i : 11 + 2 * i]
            ms.pointList[i].setPosition(r)
        body.f6Ext = np.array(theta[15:21], float)
        body.setPosition(np.zeros(6))
        ms.solveEquilibrium(tol=1e-9, maxIter=500)
        return np.linalg.norm(ms.lineList[0].fB)

    t0 = mp_tension(th)

    def mp_fd():
        out = np.zeros_like(th)
        for i, h in enumerate(steps):
            e = np.zeros_like(th)
            e[i] = h
            out[i] = (mp_tension(th + e) - mp_tension(th - e)) / (2 * h)
        return out

    (g_mp, mp_s, _) = clock(mp_fd)
    _, mp1_s = median_time(lambda: mp_tension(th), repeats)
    g = np.asarray(g)
    # each derivative times max(|theta_i|, 1): the tension change for a 100 %
    # (or a unit) change of the parameter, comparable across parameters
    sens = np.abs(g) * np.maximum(np.abs(th), 1.0)
    rel = np.abs(g - g_mp) * np.maximum(np.abs(th), 1.0) / sens.max()
    rows = [
        dict(what="one solve (jax.jit of the value)", wall_ms=1e3 * v_s,
             compile_s=v_first - v_s, ratio_to_solve=1.0),
        dict(what=f"gradient of {n} parameters (jax.grad)", wall_ms=1e3 * g_s,
             compile_s=g_first - g_s, ratio_to_solve=g_s / v_s),
        dict(what="MoorPy: one equilibrium", wall_ms=1e3 * mp1_s,
             compile_s=None, ratio_to_solve=mp1_s / v_s),
        dict(what=f"MoorPy: central differences ({2 * n} equilibria)",
             wall_ms=1e3 * mp_s, compile_s=None, ratio_to_solve=mp_s / v_s),
    ]  # fmt: skip
    notes = [
        f"objective: fairlead tension of line 1 = {float(v) / 1e3:.4f} kN "
        f"(MoorPy {t0 / 1e3:.4f} kN; free spar, 1 MN surge force)",
        "theta: the three line lengths, EA, mass per length, the anchors' x and y, "
        "and the six components of the load on the spar",
        "gradient against MoorPy's central differences: largest difference of "
        "dT/dtheta_i max(|theta_i|, 1) over the largest such term: "
        f"{rel.max():.1e}",
        f"jax.grad is {mp_s / g_s:.0f} x faster than MoorPy's central differences "
        f"and costs {g_s / v_s:.1f} solves",
    ]
    return rows, notes


def main(quick=False, repeats=5):
    set_quick(quick)
    repeats = 2 if quick else repeats
    rows = []
    items = systems()
    if quick:
        items = {k: items[k] for k in ("fairleads held", "free spar")}
    for name, (system, loads) in items.items():
        rows.append(compare(name, system, loads, repeats))
    cols = ["system", "n_free", "n_coupled", "compile_s", "jaxstring_ms",
            "moorpy_eq_ms", "moorpy_K_fd_ms", "moorpy_K_analytic_ms", "speedup_vs_fd",
            "tension_rel_diff", "K_vs_analytic", "K_vs_fd_entry", "iterations",
            "converged"]  # fmt: skip
    write_table(
        "statics_moorpy",
        rows,
        cols,
        "Catenary statics: jaxstring (equilibrium + coupled stiffness) vs MoorPy 1.3",
        notes=[
            "jaxstring_ms: mooring_equilibrium, or coupled_stiffness (equilibrium + "
            "stiffness) where the system has coupled degrees of freedom; median of "
            "repeats after the first call (compile_s apart)",
            "moorpy_eq_ms: solveEquilibrium from the start pose (tol 1e-6); "
            "moorpy_K_fd_ms: getCoupledStiffness(dth=0.01) (its central differences, "
            "each a re-solved equilibrium); moorpy_K_analytic_ms: "
            "getCoupledStiffnessA; speedup_vs_fd: (MoorPy equilibrium + "
            "finite-difference stiffness) / jaxstring",
            "tension_rel_diff: largest |T - T_MoorPy| over the largest tension; "
            "K_vs_analytic: largest entry difference from getCoupledStiffnessA over "
            "its largest entry; K_vs_fd_entry: largest relative difference from "
            "getCoupledStiffness on the entries above 1e-4 of the largest",
        ],
    )
    free, loads = items["free spar"]
    grows, notes = gradient_study(free, loads, repeats)
    write_table(
        "statics_moorpy_gradient",
        grows,
        ["what", "wall_ms", "compile_s", "ratio_to_solve"],
        "Gradient of a fairlead tension w.r.t. 21 design parameters: jax.grad vs "
        "MoorPy finite differences",
        notes=notes,
    )
    return rows, grows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--repeats", type=int, default=5)
    a = p.parse_args()
    main(quick=a.quick, repeats=a.repeats)
