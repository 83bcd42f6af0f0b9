"""Fast stiff integration: the variable-order BDF solver against CVODE.

Question: on the benchmark of ``bench_solvers.py`` (string pendulum in displacement
variables, k = 40, alpha = 0.01, 2 s, rtol = atol = 1e-6, EA in {1e4, 1e6, 1e9}),
how fast is ``simulate(scene, "bdf")`` after compilation, with how many steps and
rejections, at what end-mass error, next to Rodas5P, CVODE (scikit-sundae, BDF, band
solver, JAX RHS and banded JAX Jacobian through callbacks) and scipy's BDF (the
algorithm ported; sparse JAX Jacobian) -- all in the same run.

Error: max over 201 save times of the end-mass distance to Rodas5P at
rtol = atol = 1e-10. Times: median of repeats after compile; compile separately.

Writes experiments/results/bench_bdf.{md,csv}.
Run: ``python experiments/bench_bdf.py [--quick]`` (quick: k = 10, 0.5 s,
EA in {1e4, 1e6}; about a minute).
"""

import argparse
import importlib.util
import os

import _common as common
import harness
import numpy as np
from bench_solvers import NAMES, solver_block


def scipy_bdf_code(scene, ts):
    """scipy.integrate.solve_ivp(method="BDF") with the sparse JAX Jacobian; step
    count from its own step sequence (no t_eval), save times from dense output."""
    from scipy.integrate import solve_ivp

    from jaxstring.testing.references import JaxRHS

    rhs = JaxRHS(scene)

    def call(tol):
        rhs.reset()
        sol = solve_ivp(
            rhs.f,
            (rhs.t0, rhs.t1),
            rhs.y0,
            method="BDF",
            rtol=tol,
            atol=tol,
            jac=rhs.jac_sparse,
            dense_output=True,
        )
        return {
            "ok": bool(sol.success),
            "status": str(sol.message)[:60],
            "accepted": len(sol.t) - 1,
            "nfev": int(sol.nfev),
            "njev": int(sol.njev),
            "nlu": int(sol.nlu),
            "end": (
                np.asarray(rhs.end_mass(sol.sol(np.asarray(ts)).T))
                if sol.success
                else None
            ),
        }

    return harness.Code("scipy BDF (sparse JAX Jacobian)", "scipy", call, rhs.compile)


def run_scipy_bdf(scene, ts, rtol, atol, repeats):
    """scipy's BDF row: the JIT compile apart, then the median of `repeats`."""
    r = harness.repeat(scipy_bdf_code(scene, ts), rtol, repeats, first=False)
    return harness.rows([r], NAMES, drop=())[0]  # scored later


def main(quick=False, repeats=3, EAs=None, k=None, scipy_bdf=True):
    common.set_quick(quick)
    tag = "_quick" if quick else ""
    k = k or (10 if quick else 40)
    t1 = 0.5 if quick else 2.0
    EAs = EAs or ((1e4, 1e6) if quick else (1e4, 1e6, 1e9))
    rtol = atol = 1e-6
    have_cvode = importlib.util.find_spec("sksundae") is not None
    print(f"CVODE (scikit-sundae): {'yes' if have_cvode else 'not installed'}")
    rows = []
    for EA in EAs:
        extra = None
        if scipy_bdf:
            reps = 1 if EA > 1e7 else 2
            extra = lambda scene, ts: run_scipy_bdf(scene, ts, rtol, atol, reps)
        block, ref_end = solver_block(
            EA, k, t1, ("bdf", "rodas5p"), rtol, atol, repeats, extra
        )
        bdf = next(r for r in block if r["solver"] == "bdf")
        for r in block:
            r["vs_bdf"] = (
                (r["run_s"] / bdf["run_s"]) if (bdf.get("ok") and r.get("ok")) else None
            )
        common.score_rows(block, ref_end, block[0] if have_cvode else None, EA=EA)
        rows.extend(block)
    cols = (
        "EA solver ok run_s compile_s repeats steps rejected us_per_attempt nfev "
        "njev error_m vs_cvode vs_bdf status"
    ).split()
    notes = [
        f"String pendulum, displacement variables, k = {k}, alpha = 0.01, {t1} s, "
        "rtol = atol = 1e-6.",
        "error_m: max over 201 save times of the end-mass distance to Rodas5P at "
        "rtol = atol = 1e-10. run_s: median after compile (compile_s separately); "
        "vs_cvode, vs_bdf: run-time ratios measured in the same run.",
        "bdf: jaxstring.simulate(scene, 'bdf') -- variable-order BDF/NDF (scipy's "
        "algorithm), banded Jacobian reused across steps, block cyclic reduction.",
        "scipy BDF: steps from its own step sequence; nfev/njev count JAX calls "
        "(rejected steps are not reported by scipy).",
    ]
    if not have_cvode:
        notes.append("CVODE not measured: scikit-sundae is not installed here.")
    common.write_table(
        f"bench_bdf{tag}", rows, cols, "BDF on the stiff string pendulum", notes
    )
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--EA", default=None, help="comma-separated EA values, N")
    p.add_argument("--k", type=int, default=None, help="number of elements")
    p.add_argument("--no-scipy", action="store_true", help="skip scipy's BDF")
    a = p.parse_args()
    main(
        quick=a.quick or bool(os.environ.get("SMOKE_TEST")),
        repeats=a.repeats,
        EAs=tuple(float(x) for x in a.EA.split(",")) if a.EA else None,
        k=a.k,
        scipy_bdf=not a.no_scipy,
    )
