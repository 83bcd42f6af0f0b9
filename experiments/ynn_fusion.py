"""Cost of one Newton matrix at k = 40 ... 1280: XLA's YNNPACK fusions and the
reduced second-order factorisation.

Question: what do the pieces of one implicit step cost on the displacement string
(EA = 1e6) as k grows -- one vector field, the banded Jacobian (12 coloured JVPs),
the factorisation and one solve -- (a) with jaxlib 0.10's YNNPACK library fusions
(XLA's default) and with them off (what `jaxstring._jit.cpu_jit` compiles
simulate, fit and sweep with), and
(b) for the full 4 x 4-block cyclic reduction against the reduced 2 x 2-block
system on the velocities (`jaxstring._linalg.SecondOrderFactor`)? Each XLA setting
runs in its own process, set by XLA_FLAGS (read when the CPU backend starts). Times
are the best of 5 means of 100 calls, in microseconds, after compilation.

Run: ``python experiments/ynn_fusion.py [--quick]``.
"""

import argparse
import json
import os
import subprocess
import sys

from _common import new_figure, savefig, set_quick, write_table


_CHILD = r"""
import json, sys, time
import jaxstring, jax, jax.numpy as jnp
from jaxstring import _linalg
ks = [int(x) for x in sys.argv[1].split(",")]
def best(f, *a, n=100):
    r = f(*a); jax.block_until_ready(r)
    out = []
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(n):
            r = f(*a)
        jax.block_until_ready(r)
        out.append((time.perf_counter() - t) / n * 1e6)
    return min(out)
rows = []
for k in ks:
    sc = jaxstring.string_pendulum(k=k, EA=1e6)
    y = sc.y0 + 0.01
    f = lambda u: sc.vector_field(0.0, u)
    row = {"k": k, "rhs_us": best(jax.jit(f), y)}
    for so, tag in ((0, "full"), (2, "reduced")):
        jac = jax.jit(lambda u: _linalg.jacobian(f, u, 1, second_order=so))
        J = jac(y)
        fac = jax.jit(lambda J: _linalg.factor(J.scale_shift(1.0, -1e-4)))
        F = fac(J)
        sol = jax.jit(lambda F, r: F.solve(r))
        if so == 0:
            row["jacobian_us"] = best(jac, y)
        row[f"factor_{tag}_us"] = best(fac, J)
        row[f"solve_{tag}_us"] = best(sol, F, y)
    rows.append(row)
print(json.dumps({"rows": rows}))
"""


def run(ks, ynn_on):
    env = dict(os.environ)
    flags = env.get("XLA_FLAGS", "").replace(
        "--xla_cpu_experimental_ynn_fusion_type=", ""
    )
    if not ynn_on:
        flags += " --xla_cpu_experimental_ynn_fusion_type="  # what cpu_jit sets
    else:
        # XLA's default fusion types, spelled out.
        flags += (
            " --xla_cpu_experimental_ynn_fusion_type="
            "LIBRARY_FUSION_TYPE_DOT,LIBRARY_FUSION_TYPE_ELTWISE,"
            "LIBRARY_FUSION_TYPE_REDUCE"
        )
    env["XLA_FLAGS"] = flags.strip()
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, ",".join(map(str, ks))],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(quick=False):
    set_quick(quick)
    ks = (40, 160) if quick else (40, 160, 320, 640, 1280)
    rows = []
    for ynn_on in (True, False):
        res = run(ks, ynn_on)
        for r in res["rows"]:
            r.update(ynn_fusions="on (XLA default)" if ynn_on else "off (jaxstring)")
            r["step_full_us"] = (
                r["jacobian_us"] + r["factor_full_us"] + r["solve_full_us"]
            )
            r["step_reduced_us"] = (
                r["jacobian_us"] + r["factor_reduced_us"] + r["solve_reduced_us"]
            )
            rows.append(r)
            print(
                f"k={r['k']} ynn {r['ynn_fusions']}: jac {r['jacobian_us']:.0f} "
                f"factor {r['factor_full_us']:.0f} -> {r['factor_reduced_us']:.0f} us",
                flush=True,
            )
    on = {r["k"]: r for r in rows if r["ynn_fusions"].startswith("on")}
    off = {r["k"]: r for r in rows if r["ynn_fusions"].startswith("off")}
    notes = [
        "Times in microseconds (best of 5 means of 100 calls, after compilation).",
        "step_*: one Jacobian + one factorisation + one solve; full = 4 x 4-block "
        "cyclic reduction, reduced = 2 x 2 blocks on the velocities.",
    ]
    for k in ks:
        jr = off[k]["jacobian_us"] / on[k]["jacobian_us"]
        sr = off[k]["step_reduced_us"] / on[k]["step_full_us"]
        notes.append(
            f"k = {k}: YNNPACK off / on, Jacobian {jr:.2f}x; off + reduced / "
            f"on + full, one step's linear algebra {sr:.2f}x (same run)."
        )
    name = "ynn_fusion" + ("_quick" if quick else "")
    write_table(
        name,
        rows,
        (
            "k ynn_fusions rhs_us jacobian_us factor_full_us factor_reduced_us "
            "solve_full_us solve_reduced_us step_full_us step_reduced_us"
        ).split(),
        "Newton-matrix pieces vs k: YNNPACK fusions, full vs reduced factorisation",
        notes,
    )
    fig, axes = new_figure()
    ax = axes[0, 0]
    for tag, rs, ls in (("YNNPACK on", on, "--"), ("YNNPACK off", off, "-")):
        for col, lab in (
            ("jacobian_us", "Jacobian"),
            ("factor_full_us", "factor 4x4"),
            ("factor_reduced_us", "factor reduced 2x2"),
        ):
            ax.loglog(
                ks, [rs[k][col] for k in ks], ls, marker="o", label=f"{lab}, {tag}"
            )
    ax.set_xlabel("elements k")
    ax.set_ylabel("time per call (us)")
    ax.legend(fontsize=6)
    savefig(fig, name)
    return rows


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    main(**vars(ap.parse_args()))
