"""Runners of the tandem scenes S0-S4 for ``jaxstring run tandem-...``.

`run_tanker(name, out_dir, quick)` computes the scene's study, prints a
one-screen summary and writes figures (PNG) and a small CSV into `out_dir`.
Returns an exit code: 0 when every check of the spec the run can make passes,
1 otherwise (the numbers are still printed and written).

All simulations with the massless hawser use `tsit5` (explicit, adaptive): the
tandem is not stiff (the fastest mode is the hawser-surge mode at 0.042 rad/s),
and an implicit solver takes about as many steps, each dearer (docs/numerics.md,
"The massless tandem's explicit solver"). With `--hawser line` (fishtail and
controlled scenes) the hawser is a line with mass and drag (`with_line`), whose
axial mode at ~120 rad/s calls for an implicit solver: `rodas5p` at
rtol = atol = 1e-7.
"""

import math
import os
import time


TANKER_SCENES = (
    "tandem-fpso-alone",
    "tandem-equilibria",
    "tandem-fishtail",
    "tandem-hopf",
    "tandem-controlled",
)

SOLVER = "tsit5"
TOL = 1e-8
LINE_SOLVER = "rodas5p"
LINE_TOL = 1e-7
# the scenes that take `--hawser line`
LINE_SCENES = ("tandem-fishtail", "tandem-controlled")


def _solver_of(scene):
    from ..tandem.line import TandemLine

    if isinstance(scene.model, TandemLine):
        return LINE_SOLVER, LINE_TOL
    return SOLVER, TOL


def _tandem(model):
    """The vessels' model (a TandemLine's `tandem`) for the plots."""
    return getattr(model, "tandem", model)


def _sim(scene, n_save, max_steps=2_000_000):
    import jax
    import jax.numpy as jnp

    from .._simulate import simulate

    solver, tol = _solver_of(scene)
    ts = jnp.linspace(float(scene.t0), float(scene.t1), n_save)
    start = time.perf_counter()
    traj = jax.block_until_ready(
        simulate(scene, solver, rtol=tol, atol=tol, ts=ts, max_steps=max_steps)
    )
    return traj, time.perf_counter() - start


def _write_csv(path, header, rows):
    with open(path, "w") as f:
        f.write(",".join(header) + "\n")
        for r in rows:
            f.write(
                ",".join(f"{v:.6g}" if isinstance(v, float) else str(v) for v in r)
                + "\n"
            )


def _fpso_alone(out_dir, quick):
    import numpy as np

    from ..tandem import plot as tp
    from ..tandem.analysis import pitchfork_sweep
    from ..tandem.scenes import tandem_fpso_alone

    xs = np.linspace(0.30, 0.45, 7 if quick else 16)
    xs, lead, x_star = pitchfork_sweep(
        lambda x: tandem_fpso_alone(x_t_over_L=x, psi0_deg=0.0), xs
    )
    i40 = int(np.argmin(np.abs(xs - 0.40)))
    tp.sweep_figure(
        xs,
        lead,
        os.path.join(out_dir, "tandem_fpso_alone_sweep.png"),
        "turret position x_t / L1",
        "S0: FPSO alone, leading eigenvalue",
        marks=[x_star],
    )
    lines = ["S0  FPSO alone on its turret, current 1 m/s (hawser removed)"]
    lines.append(
        f"  pitchfork (real eigenvalue crosses 0) at x_t/L1 = {x_star:.4f}"
        "   [spec 0.355 +- 0.01]"
    )
    lines.append(
        f"  leading eigenvalue at x_t/L1 = {xs[i40]:.3f}: "
        f"{lead[i40].real:.3e} 1/s   [spec -3.4e-4]"
    )
    rows = []
    for frac in (0.40, 0.30):
        sc = tandem_fpso_alone(
            x_t_over_L=frac, psi0_deg=10.0, t1=8000.0 if quick else 20000.0
        )
        traj, wall = _sim(sc, 801)
        psi_end = math.degrees(float(traj.headings[-1, 0]))
        lines.append(
            f"  x_t/L1 = {frac:.2f}, start 10 deg off: heading after "
            f"{float(sc.t1):.0f} s = {psi_end:+.2f} deg  ({traj.status}, "
            f"{wall:.1f} s)"
        )
        rows.append((frac, psi_end))
        tp.trajectories_from_above(traj, sc.model, title=f"S0 x_t/L1={frac:.2f}")
        import matplotlib.pyplot as plt

        plt.gcf().savefig(os.path.join(out_dir, f"tandem_fpso_alone_{frac:.2f}.png"))
        plt.close("all")
    _write_csv(
        os.path.join(out_dir, "tandem_fpso_alone.csv"),
        ["x_t_over_L1", "lead_re", "lead_im"],
        [(float(x), float(e.real), float(e.imag)) for x, e in zip(xs, lead)],
    )
    ok = abs(x_star - 0.355) <= 0.01
    return lines, ok


S1_CELLS_FULL = [(0.0, 0.0)] + [
    (v, d)
    for v in (5.0, 10.0, 15.0, 20.0)
    for d in (0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0)
]
S1_CELLS_QUICK = [(0.0, 0.0), (15.0, 90.0), (15.0, 180.0), (20.0, 120.0)]


def _s1_spec():
    """The tanker specification's table S1 [P]
    (`jaxstring/tandem/spec_S1_equilibria.csv`): {(V_w, Delta_w): (taut,
    admissible, stable)}, the numbers of equilibria."""
    import csv
    import pathlib

    path = pathlib.Path(__file__).parents[1] / "tandem" / "spec_S1_equilibria.csv"
    with path.open() as f:
        rows = csv.DictReader(line for line in f if not line.startswith("#"))
        return {
            (float(r["V_w"]), float(r["Delta_w"])): tuple(
                int(r[k]) for k in ("taut", "admissible", "stable")
            )
            for r in rows
        }


S1_SPEC = _s1_spec()


def equilibrium_table(cells):
    """find_equilibria for each (V_w, Delta_w) cell; one compiled vmapped call
    for the windy cells, one for the current-only cell."""
    from ..tandem.analysis import find_equilibria, find_equilibria_map
    from ..tandem.scenes import tandem_equilibria

    out = {}
    windy = [c for c in cells if c[0] > 0]
    calm = [c for c in cells if c[0] == 0]
    for c in calm:
        out[c] = find_equilibria(tandem_equilibria(V_w=c[0], Delta_w_deg=c[1]))
    if windy:
        res = find_equilibria_map(
            [tandem_equilibria(V_w=v, Delta_w_deg=d) for v, d in windy]
        )
        out.update(zip(windy, res))
    return [out[c] for c in cells]


def _equilibria(out_dir, quick):
    import numpy as np

    from ..tandem import plot as tp
    from ..tandem.analysis import counts, stability
    from ..tandem.scenes import tandem_equilibria

    cells = S1_CELLS_QUICK if quick else S1_CELLS_FULL
    start = time.perf_counter()
    results = equilibrium_table(cells)
    wall = time.perf_counter() - start
    tp.equilibrium_map(
        cells,
        results,
        os.path.join(out_dir, "tandem_equilibria.png"),
        title="S1: tandem equilibria, current 1 m/s",
    )
    lines = [
        f"S1  equilibria from a 14x14 grid of starts ({len(cells)} cells, "
        f"{wall:.1f} s)",
        "  V_w  Delta_w   taut/adm/stab   spec",
    ]
    rows, ok = [], True
    for c, eqs in zip(cells, results):
        got = counts(eqs)
        spec = S1_SPEC[c]
        lines.append(
            f"  {c[0]:4.0f}  {c[1]:6.0f}   {got[0]:3d}/{got[1]}/{got[2]}"
            f"          {spec[0]}/{spec[1]}/{spec[2]}"
        )
        rows.append((c[0], c[1], *got, *spec))
        ok &= got[2] == spec[2]
    _write_csv(
        os.path.join(out_dir, "tandem_equilibria.csv"),
        ["V_w", "Delta_w", "taut", "adm", "stab", "spec_taut", "spec_adm", "spec_stab"],
        rows,
    )
    sc = tandem_equilibria()
    eigs, kind = stability(sc, np.asarray(sc.y0))
    lines.append(
        f"S2  current-only aligned equilibrium: {kind}, T = "
        f"{float(sc.observables(sc.y0)['tension']) / 1e3:.1f} kN"
    )
    lines.append(
        "  eigenvalues: "
        + ", ".join(f"{e.real:.3e}{e.imag:+.3e}i" for e in eigs if e.imag >= 0)
    )
    return lines, ok


def _animate(traj, scene, out_dir, stem, frames, title):
    """Write the run as `<out_dir>/<stem>.gif` when `frames` > 0; the line to print."""
    if not frames:
        return []
    from ..tandem import plot as tp

    path = os.path.join(out_dir, stem + ".gif")
    tp.animate(traj, _tandem(scene.model), path, frames=frames, title=title)
    return [f"  wrote {path}"]


def _fishtail(out_dir, quick, hawser="massless", frames=0):
    from ..tandem import plot as tp
    from ..tandem.analysis import measure_limit_cycle
    from ..tandem.scenes import tandem_fishtail

    t1 = 30000.0 if quick else 60000.0
    sc = tandem_fishtail(t1=t1, hawser=hawser)
    traj, wall = _sim(sc, int(t1 / 10) + 1)
    m = measure_limit_cycle(traj, 0.6 * t1)
    solver = _solver_of(sc)[0]
    tp.tandem_figure(
        traj,
        _tandem(sc.model),
        os.path.join(out_dir, "tandem_fishtail.png"),
        title=f"S3a fishtailing, current 1 m/s, F_ast = 0, {hawser} hawser "
        f"[{solver}, {traj.status}]",
    )
    lines = [
        f"S3a fishtailing, {hawser} hawser, {t1:.0f} s ({traj.status}, "
        f"{int(traj.stats['num_steps'])} steps, {wall:.1f} s incl. compile)",
        f"  measured over t > {0.6 * t1:.0f} s ({m['n_cycles']} cycles)",
    ]
    spec = {
        "period": "3400-3500 s",
        "shuttle_yaw": "13-18 deg",
        "fpso_yaw": "2-4 deg",
        "lateral_excursion": "150-175 m",
        "span_min": "29-60 m",
        "span_max": "84 m",
        "tension_max": "0.8-0.9 MN",
    }
    for k, s in spec.items():
        lines.append(f"  {k:<20} {m[k]:12.4g}   [spec {s}]")
    lines += _animate(traj, sc, out_dir, "tandem_fishtail", frames, "S3a fishtailing")
    _write_csv(
        os.path.join(out_dir, "tandem_fishtail.csv"), list(m), [tuple(m.values())]
    )
    if hawser == "line":
        # The spec's ranges are for the massless hawser: the line's mass and drag
        # shorten the cycle (experiments/results/tanker_line.md); check the run.
        lines.append("  (spec ranges: massless hawser; the line changes the cycle)")
        return lines, traj.ok
    ok = (
        3300 <= m["period"] <= 3600
        and 13 <= m["shuttle_yaw"] <= 18
        and 2 <= m["fpso_yaw"] <= 4
    )
    return lines, ok and traj.ok


def _hopf(out_dir, quick):
    import numpy as np

    from ..tandem import plot as tp
    from ..tandem.analysis import hopf_sweep, measure_limit_cycle
    from ..tandem.scenes import tandem_hopf

    Fs = np.linspace(0.0, 60e3, 7 if quick else 13)
    Fs, eqs, lead, F_star = hopf_sweep(lambda F: tandem_hopf(F_ast=F), Fs)
    i = int(np.searchsorted(Fs, F_star))
    w_star = float(np.interp(F_star, Fs, np.abs(lead.imag)))
    tp.sweep_figure(
        Fs / 1e3,
        lead,
        os.path.join(out_dir, "tandem_hopf_sweep.png"),
        "astern pull F_ast, kN",
        "S3b: leading pair of the aligned equilibrium",
        marks=[F_star / 1e3],
    )
    lines = [
        "S3b Hopf sweep over the astern pull (current only)",
        f"  Hopf point F_ast* = {F_star / 1e3:.1f} kN, frequency {w_star:.3e} "
        f"rad/s (period {2 * math.pi / w_star:.0f} s)   [spec 43 kN, "
        "3.34e-3 rad/s, 1880 s]",
    ]
    del i
    rows = [(float(F), float(e.real), float(e.imag)) for F, e in zip(Fs, lead)]
    cyc_F = (40e3,) if quick else (40e3, 35e3, 20e3)
    spec = {
        40e3: "2074 s, +-7.8 deg",
        35e3: "2345 s, +-11.5 deg",
        20e3: "3065 s, +-15.3 deg",
    }
    for F in cyc_F:
        t1 = 40000.0 if quick else 60000.0
        sc = tandem_hopf(F_ast=F, t1=t1, perturbation_deg=5.0)
        traj, wall = _sim(sc, int(t1 / 10) + 1)
        m = measure_limit_cycle(traj, 0.6 * t1)
        lines.append(
            f"  F_ast = {F / 1e3:4.0f} kN: period {m['period']:7.0f} s, shuttle "
            f"yaw +-{m['shuttle_yaw']:5.1f} deg, T {m['tension_min'] / 1e3:.0f}-"
            f"{m['tension_max'] / 1e3:.0f} kN   [spec {spec[F]}]"
        )
        tp.tandem_figure(
            traj,
            sc.model,
            os.path.join(out_dir, f"tandem_hopf_{F / 1e3:.0f}kN.png"),
            title=f"S3b limit cycle, F_ast = {F / 1e3:.0f} kN",
        )
    _write_csv(
        os.path.join(out_dir, "tandem_hopf.csv"), ["F_ast", "lead_re", "lead_im"], rows
    )
    return lines, abs(F_star - 43e3) <= 4.3e3


def _controlled(out_dir, quick, hawser="massless", frames=0):
    from ..tandem import plot as tp
    from ..tandem.analysis import CONTROLLED_METRICS, controlled_metrics
    from ..tandem.scenes import ENVIRONMENTS, tandem_controlled

    t1 = 4000.0 if quick else 6000.0
    lines = [
        f"S4  law B (nonlinear compensator), {hawser} hawser, {t1:.0f} s; "
        "acceptance after 3000 s",
        "  env          |d-dref| m  |y2| deg  d_min m  clear m  |X|max kN  "
        "|N|max  psi1_end  X_end kN  ok",
    ]
    rows, ok = [], True
    for env in ENVIRONMENTS:
        sc = tandem_controlled(env=env, t1=t1, hawser=hawser)
        ctl = [e for e in sc.effects if hasattr(e, "d_ref")][0]
        traj, wall = _sim(sc, int(t1 / 2) + 1)
        m = controlled_metrics(traj, float(ctl.d_ref), ctl.X_max, ctl.N_max)
        lines.append(
            f"  {env:<12} {m['span_error']:9.2e}  {m['heading_error']:8.2e}"
            f"  {m['span_min']:7.2f}  {m['clearance_min']:7.1f}  "
            f"{m['X_peak'] / 1e3:9.0f}  {m['N_peak']:.2e}  "
            f"{m['psi1_final']:8.2f}  {m['X_final'] / 1e3:8.0f}  {m['ok']}"
        )
        rows.append((env, *[m[k] for k in CONTROLLED_METRICS]))
        ok &= m["ok"]
        tp.tandem_figure(
            traj,
            _tandem(sc.model),
            os.path.join(out_dir, f"tandem_controlled_{env}.png"),
            title=f"S4 law B, {env}, {hawser} hawser "
            f"[{_solver_of(sc)[0]}, {traj.status}]",
            d_ref=float(ctl.d_ref),
        )
        stem = f"tandem_controlled_{env}"
        lines += _animate(traj, sc, out_dir, stem, frames, f"S4 law B, {env}")
    lines.append("  [spec: final psi1 0 / 44.6 / 62.5 deg; X_end -270 to -390 kN]")
    _write_csv(
        os.path.join(out_dir, "tandem_controlled.csv"),
        ["env", *CONTROLLED_METRICS],
        rows,
    )
    return lines, ok


RUNNERS = {
    "tandem-fpso-alone": _fpso_alone,
    "tandem-equilibria": _equilibria,
    "tandem-fishtail": _fishtail,
    "tandem-hopf": _hopf,
    "tandem-controlled": _controlled,
}


def run_tanker(
    name: str, out_dir: str, quick: bool, hawser: str = "massless", frames: int = 0
) -> int:
    """Run the study of one tandem scene (S0-S4), print a one-screen summary and
    write figures and a CSV into `out_dir`. `hawser`: "massless" (the spec's) or
    "line" (mass and drag; the fishtail and controlled scenes). `frames` > 0 also
    writes GIF animations of the runs with that many frames (the fishtail and
    controlled scenes). Returns 0 when the spec checks pass, 1 when one fails, 2 on
    an unknown name or option."""
    import sys

    if name not in RUNNERS:
        print(
            f"error: unknown tandem scene {name!r}; valid: {', '.join(RUNNERS)}",
            file=sys.stderr,
        )
        return 2
    if hawser not in ("massless", "line") or (
        hawser == "line" and name not in LINE_SCENES
    ):
        print(
            f"error: --hawser {hawser!r} for {name}: valid is 'massless', or 'line' "
            f"for {', '.join(LINE_SCENES)}",
            file=sys.stderr,
        )
        return 2
    if frames and name not in LINE_SCENES:
        print(
            f"error: --animate is available for {', '.join(LINE_SCENES)}; "
            f"not for {name}",
            file=sys.stderr,
        )
        return 2
    try:
        os.makedirs(out_dir, exist_ok=True)
    except OSError as e:
        print(
            f"error: --out {out_dir!r}: cannot create the directory ({e}).",
            file=sys.stderr,
        )
        return 2
    start = time.perf_counter()
    if name in LINE_SCENES:
        lines, ok = RUNNERS[name](out_dir, quick, hawser, frames)
    else:
        lines, ok = RUNNERS[name](out_dir, quick)
    lines.insert(0, f"jaxstring run {name}{' (quick)' if quick else ''}")
    lines.append(f"wall time {time.perf_counter() - start:.1f} s; outputs in {out_dir}")
    lines.append("checks: " + ("pass" if ok else "FAIL"))
    print("\n".join(lines))
    return 0 if ok else 1
