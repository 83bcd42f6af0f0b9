"""S1/S2: all static equilibria of the FPSO + shuttle tandem over wind speed and
direction (spec S1), classified by the eigenvalues of the jacfwd Jacobian (S2).

Newton (optimistix) from a 14 x 14 grid of (psi1, psi2) starts, vmapped over the
starts *and* over the 28 windy cells in one compiled call. Prints the
taut/admissible/stable table next to the spec's [P] numbers, and writes
results/tanker_equilibria.{png,csv,md} (--quick: results/quick/, names ending in
`_quick`; $JAXSTRING_RESULTS_DIR overrides the folder). Compile time is reported
apart from the run time (median of repeats).

With --methods it also runs the same search with optimistix Dogleg and
Levenberg-Marquardt (`find_equilibria(method=...)`) and with scipy's MINPACK
hybrd (`scipy.optimize.root(method='hybr')`, a host loop over the starts on the
same jitted residual and jacfwd Jacobian), and writes
results/tanker_equilibria_methods.{md,csv}: the spec's prototype used
"Newton/hybrid" solves, and the counts of non-admissible roots depend on the
search.

    python experiments/tanker_equilibria.py [--quick] [--methods]
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


import numpy as np
from _common import (
    clock,
    results_dir,
    run_study,
    set_quick,
    stamp_file,
    write_report,
)

import jaxstring  # noqa: F401
from jaxstring.cli.tandem import S1_CELLS_FULL, S1_SPEC
from jaxstring.tandem import plot as tp
from jaxstring.tandem.analysis import counts, find_equilibria, find_equilibria_map
from jaxstring.tandem.scenes import tandem_equilibria


def _hybr_cell(scene, factor=1.0):
    """scipy MINPACK hybrd from each S1 start; returns `find_equilibria`'s list."""
    import jax
    import jax.numpy as jnp
    import scipy.optimize as so

    from jaxstring.tandem import analysis as ta

    f = jax.jit(lambda q: ta.residual(q, scene))
    fj = jax.jit(jax.jacfwd(lambda q: ta.residual(q, scene)))
    qs, ok = [], []
    for q0 in np.asarray(ta.grid_starts(scene)):
        sol = so.root(
            lambda x: np.asarray(f(jnp.asarray(x))),
            q0,
            jac=lambda x: np.asarray(fj(jnp.asarray(x))),
            method="hybr",
            options={"factor": factor},
        )
        qs.append(sol.x)
        ok.append(sol.success)
    q = jnp.asarray(np.array(qs))
    res = np.asarray(jax.vmap(lambda q: jnp.max(jnp.abs(ta.residual(q, scene))))(q))
    ys = jax.vmap(lambda q: ta.state_from_q(q, 2))(q)
    hawser = ta._hawser(scene)

    def props(y):
        eta = y.reshape(2, 6)[:, :3]
        T = hawser.tension(scene.model, eta, jnp.zeros((2, 3)))
        return T, ta.hull_clearance(scene.model, eta), ta._jacobian(scene, y)

    T, clr, J = jax.vmap(props)(ys)
    return ta._collect(ys, np.array(ok) & (res < 1e-6), T, clr, J, 1.0)


def compare_methods(cells, newton, sfx):
    """Counts per cell for Newton (given), Dogleg, LM and scipy hybr."""
    windy = [c for c in cells if c[0] > 0]
    scenes = {c: tandem_equilibria(V_w=c[0], Delta_w_deg=c[1]) for c in cells}
    found = {"newton": newton}
    for m in ("dogleg", "lm"):

        def solve(m=m):
            res = dict(
                zip(windy, find_equilibria_map([scenes[c] for c in windy], method=m))
            )
            res[(0.0, 0.0)] = find_equilibria(scenes[(0.0, 0.0)], method=m)
            return res

        found[m], wall, _ = clock(solve)
        print(f"{m}: {wall:.0f} s (incl. compile)", flush=True)
    found["hybr"], wall, _ = clock(lambda: {c: _hybr_cell(scenes[c]) for c in cells})
    print(f"hybr: {wall:.0f} s", flush=True)
    names = list(found)
    off = dict.fromkeys(names, 0)
    lines = [
        "| V_w m/s | Delta_w deg | spec [P] | " + " | ".join(names) + " |",
        "|---|---|---|" + "---|" * len(names),
    ]
    csv = [
        "V_w,Delta_w,spec_taut,spec_adm,spec_stab,"
        + ",".join(f"{n}_{k}" for n in names for k in ("taut", "adm", "stab"))
    ]
    for c in cells:
        spec = S1_SPEC[c]
        row, vals = [], []
        for n in names:
            got = counts(found[n][c])
            good = all(abs(g - w) <= 1 for g, w in zip(got, spec)) and got[2] == spec[2]
            off[n] += not good
            row.append(f"{got[0]}/{got[1]}/{got[2]}" + ("" if good else " **"))
            vals += list(got)
        lines.append(
            f"| {c[0]:g} | {c[1]:g} | {spec[0]}/{spec[1]}/{spec[2]} | "
            + " | ".join(row)
            + " |"
        )
        csv.append(",".join(str(x) for x in (*c, *spec, *vals)))
    lines.append(
        "| cells off (** = a count off by > 1 or stable count different) | | | "
        + " | ".join(str(off[n]) for n in names)
        + " |"
    )
    lines += [
        "",
        "taut/adm/stab from the same 14 x 14 grid of starts, taut filter (T > 1 N),",
        "de-duplication (1 m, 0.01 rad) and classification; a start counts when its",
        "max |scaled residual| < 1e-6. newton/dogleg/lm: optimistix (rtol = atol =",
        "1e-10, 200 steps) under vmap; hybr: scipy.optimize.root(method='hybr',",
        "factor=1) with the jacfwd Jacobian, success flag required.",
    ]
    write_report(
        f"tanker_equilibria_methods{sfx}",
        "S1 equilibrium counts by solver",
        "\n".join(lines),
        csv,
    )


def main(quick=False, repeats=None, methods=False):
    repeats = repeats or 3
    set_quick(quick)
    sfx = "_quick" if quick else ""
    cells = S1_CELLS_FULL
    if quick:
        cells = [(0.0, 0.0)] + [
            (v, d) for v in (10.0, 15.0) for d in (0.0, 90.0, 180.0)
        ]
        repeats = 1
    windy = [c for c in cells if c[0] > 0]
    scenes = [tandem_equilibria(V_w=v, Delta_w_deg=d) for v, d in windy]
    times = []
    for _ in range(repeats + 1):
        res, wall, _ = clock(lambda: find_equilibria_map(scenes))
        times.append(wall)
    compile_s = times[0] - float(np.median(times[1:]))
    calm = find_equilibria(tandem_equilibria())
    results = dict(zip(windy, res))
    results[(0.0, 0.0)] = calm
    ordered = [results[c] for c in cells]
    png = results_dir() / f"tanker_equilibria{sfx}.png"
    tp.equilibrium_map(
        cells,
        ordered,
        str(png),
        title="S1: FPSO + shuttle equilibria, current 1 m/s",
    )
    stamp_file(png)
    lines = [
        "| V_w m/s | Delta_w deg | taut/adm/stab (ours) | spec [P] | stable "
        "admissible headings (psi1, psi2) deg |",
        "|---|---|---|---|---|",
    ]
    csv = ["V_w,Delta_w,taut,adm,stab,spec_taut,spec_adm,spec_stab"]
    for c, eqs in zip(cells, ordered):
        got, spec = counts(eqs), S1_SPEC[c]
        st = "; ".join(
            f"({e.headings_deg[0]:.1f}, {e.headings_deg[1]:.1f}) "
            f"T={e.tension / 1e3:.0f} kN"
            for e in eqs
            if e.stable and e.admissible
        )
        lines.append(
            f"| {c[0]:g} | {c[1]:g} | {got[0]}/{got[1]}/{got[2]} | "
            f"{spec[0]}/{spec[1]}/{spec[2]} | {st} |"
        )
        csv.append(",".join(str(x) for x in (*c, *got, *spec)))
    lines.append("")
    lines.append(
        f"{len(windy)} windy cells x 196 starts in one vmapped call: compile "
        f"{compile_s:.1f} s, run {np.median(times[1:]):.2f} s (median of "
        f"{max(len(times) - 1, 1)})"
    )
    write_report(f"tanker_equilibria{sfx}", "S1 equilibrium map", "\n".join(lines), csv)
    if methods:
        compare_methods(cells, results, sfx)


if __name__ == "__main__":
    run_study(main, methods=dict(action="store_true", help="compare solvers"))
