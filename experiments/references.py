"""External reference integrators on the identical right-hand side, on one scene.

Question: do scipy's Radau, BDF and LSODA and SUNDIALS' CVODE and IDA, driving a
jaxstring scene's JIT-compiled vector field and Jacobian through Python callbacks
(``jaxstring.testing.references``), reproduce jaxstring's Kvaerno5, and at what cost
with each Jacobian variant (dense JAX, banded JAX, the peer's own finite differences,
dense or banded)? The JIT compile of f and its Jacobian is reported apart.

Writes experiments/results/references.{md,csv}.
Run: ``python experiments/references.py [--quick]``.
"""

import argparse

import numpy as np

import jaxstring
from jaxstring.testing.references import JACOBIANS, PEERS, JaxRHS, available, solve


def main(
    quick: bool = False,
    formulation: str = "displacement",
    EA: float = 1e6,
    k: int = 40,
    rtol: float = 1e-7,
):
    """Time every available peer and Jacobian variant on one scene (a sanity table)."""
    from _common import set_quick

    set_quick(quick)
    from _common import end_mass_error, timed, timed_split, write_table

    if quick:
        k, EA = 8, 1e4
    scene = jaxstring.string_pendulum(formulation=formulation, k=k, EA=EA)
    ts = np.linspace(float(scene.t0), float(scene.t1), 41)
    rhs = JaxRHS(scene)
    f_us, j_us = rhs.call_cost_us()
    ref_t, ref = timed(
        lambda: jaxstring.simulate(scene, "kvaerno5", rtol=rtol, atol=rtol, ts=ts),
        repeats=1 if quick else 3,
    )
    ref_end = np.asarray(ref.end_mass)
    rows = [
        {
            "peer": "jaxstring kvaerno5",
            "jac": "jax (in-jit)",
            "ok": ref.ok,
            "compile_s": ref_t.compile_s,
            "run_s": ref_t.run_s,
            "nfev": "-",
            "njev": "-",
            "err_vs_kvaerno5_m": 0.0,
        }
    ]
    ok = available()
    for peer in PEERS:
        if not ok[peer]:
            print(f"skip {peer}: not installed")
            continue
        for jac in JACOBIANS:
            tm, out = timed_split(
                rhs.compile,
                lambda p=peer, j=jac: solve(rhs, p, ts, rtol, rtol, j),
                repeats=1 if quick else 3,
            )
            err = (
                end_mass_error(rhs.end_mass(out["ys"]), ref_end)
                if out["ok"]
                else float("nan")
            )
            rows.append(
                {
                    "peer": peer,
                    "jac": jac,
                    "ok": out["ok"],
                    "compile_s": tm.compile_s,
                    "run_s": tm.run_s,
                    "nfev": out["nfev"],
                    "njev": out["njev"],
                    "err_vs_kvaerno5_m": err,
                }
            )
    write_table(
        "references_quick" if quick else "references",
        rows,
        "peer jac ok compile_s run_s nfev njev err_vs_kvaerno5_m".split(),
        f"External references on the identical RHS: {formulation}, k={k}, EA={EA:g}, "
        f"rtol=atol={rtol:g}",
        notes=[
            f"one JAX f call from NumPy: {f_us:.1f} us; one Jacobian call: "
            f"{j_us:.1f} us (n = {rhs.n}, band l={rhs.lband} u={rhs.uband})",
            f"JIT compile of f + Jacobian: {rhs.compile_s:.2f} s (not in run_s)",
        ],
    )
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--formulation", default="displacement")
    p.add_argument("--EA", type=float, default=1e6)
    p.add_argument("--k", type=int, default=40)
    a = p.parse_args()
    main(quick=a.quick, formulation=a.formulation, EA=a.EA, k=a.k)
