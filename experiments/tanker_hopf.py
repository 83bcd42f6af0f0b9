"""S3: fishtailing limit cycles and the Hopf bifurcation in the astern pull.

Continuation of the aligned equilibrium over F_ast (leading eigenvalue pair from
the jacfwd Jacobian), the Hopf point where Re crosses 0, and limit cycles
simulated from a perturbed equilibrium at F_ast = 40, 35, 20, 0 kN (period,
shuttle/FPSO yaw amplitude, span, tension), against the spec's [P] table.
Writes results/tanker_hopf.{png,csv,md}.

    python experiments/tanker_hopf.py [--quick]
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import math

import jax
import jax.numpy as jnp
import numpy as np
from _common import (
    clock,
    results_dir,
    results_file,
    set_quick,
    stamp_file,
    stamp_markdown,
)

import jaxstring as js
from jaxstring.tandem import plot as tp
from jaxstring.tandem.analysis import hopf_sweep, measure_limit_cycle
from jaxstring.tandem.scenes import tandem_hopf


SPEC = {40e3: (2074, 7.8), 35e3: (2345, 11.5), 20e3: (3065, 15.3), 0.0: (3400, 18.0)}


def main(quick=False):
    set_quick(quick)
    sfx = "_quick" if quick else ""
    Fs = np.linspace(0.0, 60e3, 7 if quick else 25)
    (Fs, _, lead, F_star), sweep_s, _ = clock(
        lambda: hopf_sweep(lambda F: tandem_hopf(F_ast=F), Fs)
    )
    w_star = float(np.interp(F_star, Fs, np.abs(lead.imag)))
    png = results_dir() / f"tanker_hopf_sweep{sfx}.png"
    tp.sweep_figure(
        Fs / 1e3,
        lead,
        str(png),
        "astern pull F_ast, kN",
        "S3b: fishtail pair of the aligned equilibrium",
        marks=[F_star / 1e3],
    )
    stamp_file(png)
    lines = [
        f"Hopf point F_ast* = {F_star / 1e3:.2f} kN (spec 43 kN), frequency "
        f"{w_star:.4e} rad/s (spec 3.34e-3), period {2 * math.pi / w_star:.0f} s "
        f"(spec 1880 s); sweep of {len(Fs)} points {sweep_s:.1f} s incl. compile",
        "",
        "| F_ast kN | period s (spec) | shuttle yaw +-deg (spec) | FPSO yaw "
        "+-deg | span min-max m | T min-max kN | steps | run s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    csv = ["F_ast,period,shuttle_yaw,fpso_yaw,span_min,span_max,T_min,T_max"]
    t1 = 30000.0 if quick else 60000.0
    cases = (40e3, 0.0) if quick else (40e3, 35e3, 20e3, 0.0)
    for F in cases:
        sc = tandem_hopf(F_ast=F, t1=t1, perturbation_deg=5.0)
        ts = jnp.linspace(0.0, t1, int(t1 / 10) + 1)
        walls = []
        for _ in range(2):
            traj, wall, _ = clock(
                lambda: jax.block_until_ready(
                    js.simulate(
                        sc, "tsit5", rtol=1e-8, atol=1e-8, ts=ts, max_steps=10**6
                    )
                )
            )
            walls.append(wall)
        m = measure_limit_cycle(traj, 0.6 * t1)
        ps, ys = SPEC[F]
        lines.append(
            f"| {F / 1e3:.0f} | {m['period']:.0f} ({ps}) | "
            f"{m['shuttle_yaw']:.1f} ({ys}) | {m['fpso_yaw']:.1f} | "
            f"{m['span_min']:.1f}-{m['span_max']:.1f} | "
            f"{m['tension_min'] / 1e3:.0f}-{m['tension_max'] / 1e3:.0f} | "
            f"{int(traj.stats['num_steps'])} | {walls[1]:.2f} |"
        )
        csv.append(
            ",".join(
                f"{v:.6g}"
                for v in (
                    F,
                    m["period"],
                    m["shuttle_yaw"],
                    m["fpso_yaw"],
                    m["span_min"],
                    m["span_max"],
                    m["tension_min"],
                    m["tension_max"],
                )
            )
        )
        png = results_dir() / f"tanker_hopf_{F / 1e3:.0f}kN{sfx}.png"
        tp.tandem_figure(
            traj, sc.model, str(png), title=f"limit cycle, F_ast = {F / 1e3:.0f} kN"
        )
        stamp_file(png)
    lines.append("")
    lines.append(
        "Measured over the last 40 % of each run; runs start 5 deg off the "
        "equilibrium (run time of the second, compiled call)."
    )
    text = "\n".join(lines)
    print(text)
    with results_file(f"tanker_hopf{sfx}.md") as f:
        f.write(
            "# S3 Hopf sweep and limit cycles\n\n"
            + stamp_markdown()
            + "\n\n"
            + text
            + "\n"
        )
    with results_file(f"tanker_hopf{sfx}.csv") as f:
        f.write("\n".join(csv) + "\n")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    a = p.parse_args()
    main(quick=a.quick)
