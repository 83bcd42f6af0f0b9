"""S1/S2: all static equilibria of the FPSO + shuttle tandem over wind speed and
direction (spec S1), classified by the eigenvalues of the jacfwd Jacobian (S2).

Newton (optimistix) from a 14 x 14 grid of (psi1, psi2) starts, vmapped over the
starts *and* over the 28 windy cells in one compiled call. Prints the
taut/admissible/stable table next to the spec's [P] numbers, and writes
results/tanker_equilibria.{png,csv,md} (`_quick` suffix with --quick;
$JAXSTRING_RESULTS_DIR overrides the folder). Compile time is reported apart from the
run time (median of repeats).

    python experiments/tanker_equilibria.py [--quick]
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import time

import numpy as np

import jaxstring  # noqa: F401
from jaxstring import tanker_plot as tp
from jaxstring._tanker_analysis import counts, find_equilibria, find_equilibria_map
from jaxstring._tanker_scenes import tandem_equilibria
from jaxstring.tanker_cli import S1_CELLS_FULL, S1_SPEC


HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.environ.get("JAXSTRING_RESULTS_DIR", os.path.join(HERE, "results"))


def main(quick=False, repeats=3):
    os.makedirs(OUT, exist_ok=True)
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
        t = time.perf_counter()
        res = find_equilibria_map(scenes)
        times.append(time.perf_counter() - t)
    compile_s = times[0] - float(np.median(times[1:]))
    calm = find_equilibria(tandem_equilibria())
    results = dict(zip(windy, res))
    results[(0.0, 0.0)] = calm
    ordered = [results[c] for c in cells]
    tp.equilibrium_map(
        cells,
        ordered,
        os.path.join(OUT, f"tanker_equilibria{sfx}.png"),
        title="S1: FPSO + shuttle equilibria, current 1 m/s",
    )
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
    text = "\n".join(lines)
    print(text)
    with open(os.path.join(OUT, f"tanker_equilibria{sfx}.md"), "w") as f:
        f.write("# S1 equilibrium map\n\n" + text + "\n")
    with open(os.path.join(OUT, f"tanker_equilibria{sfx}.csv"), "w") as f:
        f.write("\n".join(csv) + "\n")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    a = p.parse_args()
    main(quick=a.quick)
