"""Measured numbers behind the string-pendulum tests, in one table.

Question: how close is each formulation to the analytic limits, how well is energy
conserved, at what order do the formulations converge to each other, and do the hard
cases integrate? Runtime: ~3 min on a 2-core machine (--quick: ~1 min).
Output: experiments/results/pendulum_checks.md
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import math
import sys

import numpy as np


sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
import jax.numpy as jnp  # noqa: E402

import jaxstring as js  # noqa: E402
from tests.helpers import FORMULATIONS, fitted_order, run, zero_crossings  # noqa: E402
from tests.pendulum.test_physics import HARD_CASES, G, _axial_mode_scene  # noqa: E402


def main(quick: bool = False) -> str:
    from _common import set_quick, stamp_markdown, write_text

    set_quick(quick)
    rows = []
    for f in FORMULATIONS:
        scene, omega = _axial_mode_scene(f, k=40, EA=1e4, V=1e-3, t1=0.25)
        ts = jnp.linspace(0.0, 0.25, 2501)
        traj = js.simulate(scene, "kvaerno5", rtol=1e-10, atol=1e-12, ts=ts)
        c = zero_crossings(ts, np.asarray(traj.end_mass[:, 1]) + 1.0)[1:]
        w = 2 * math.pi / (2 * np.mean(np.diff(c)))
        rows.append(
            ("axial frequency, k=40 (rel. error)", f, f"{(w - omega) / omega:+.2e}")
        )
    mu, m_s, l, EA, th = 1e-3, 1.0, 1.0, 1e6, 0.05
    L = l * (1 + m_s * G / EA)
    T0 = (
        2
        * math.pi
        * math.sqrt((m_s * L**2 + mu * L**3 / 3) / (G * (m_s * L + mu * L**2 / 2)))
    )
    Tx = T0 * (1 + th**2 / 16)
    for f in FORMULATIONS:
        traj = run(f, k=10, EA=EA, mu=mu, m_s=m_s, theta0=th, t1=3.9, n_save=401)
        c = zero_crossings(traj.ts, traj.end_mass[:, 0])
        T = 2 * np.mean(np.diff(c))
        rows.append(("small-amplitude period (rel. error)", f, f"{(T - Tx) / Tx:+.2e}"))
    for f in FORMULATIONS:
        tr = run(f, alpha=0.0, t1=2.0, rtol=1e-9, atol=1e-9, n_save=401)
        e = np.asarray(tr.energy)
        rows.append(
            (
                "energy drift, alpha=0, 2 s (rel. to m g l)",
                f,
                f"{np.max(np.abs(e - e[0])) / (2 * G):.2e}",
            )
        )
        tr = run(f, alpha=0.01, t1=2.0, rtol=1e-9, atol=1e-9, n_save=401)
        e = np.asarray(tr.energy)
        rows.append(
            ("largest energy increase, alpha=0.01 (J)", f, f"{np.max(np.diff(e)):.2e}")
        )
    ks = (10, 20) if quick else (10, 20, 40)
    diffs = []
    for k in ks:
        d, a = run("displacement", k=k, n_save=101), run("angle", k=k, n_save=101)
        diffs.append(float(np.max(np.linalg.norm(d.end_mass - a.end_mass, axis=1))))
    rows.append(
        (
            "|displacement - angle| end mass (m), k=" + ",".join(map(str, ks)),
            "both",
            ", ".join(f"{x:.2e}" for x in diffs),
        )
    )
    rows.append(
        (
            "fitted order in 1/k",
            "both",
            f"{fitted_order([1 / k for k in ks], diffs):.2f}",
        )
    )
    for k in (10, 20):
        n, a = run("natural", k=k, n_save=101), run("angle", k=k, n_save=101)
        rows.append(
            (
                f"|natural - angle| end mass (m), k={k}",
                "natural/angle",
                f"{float(np.max(np.abs(n.end_mass - a.end_mass))):.1e}",
            )
        )
    for case, kw in HARD_CASES.items():
        for f in FORMULATIONS:
            tr = run(f, k=10, t1=1.0, rtol=1e-6, atol=1e-6, n_save=101, **kw)
            rows.append(
                (
                    f"hard case {case}: status, steps (rejected), max |t|-1",
                    f,
                    f"{tr.status}, {int(tr.stats['num_steps'])} "
                    f"({int(tr.stats['num_rejected_steps'])}), "
                    f"{float(np.max(tr.constraint_error)):.1e}",
                )
            )
    lines = [
        "# String pendulum checks (measured)",
        "",
        stamp_markdown(),
        "",
        "| check | formulation | value |",
        "|---|---|---|",
    ] + [f"| {a} | {b} | {c} |" for a, b, c in rows]
    text = "\n".join(lines) + "\n"
    write_text("pendulum_checks" + ("_quick" if quick else "") + ".md", text)
    print(text)
    return text


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--quick", action="store_true")
    main(quick=p.parse_args().quick)
