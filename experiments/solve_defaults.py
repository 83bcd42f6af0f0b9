"""What the identification defaults cost: least squares at rtol = atol = 1e-6 ... 1e-8.

Question: which tolerance should `SolveConfig.default("identify")` carry? A fit is
many solves of one scene, and a newcomer's first fit includes compilation. For the
problem of `identify_least_squares.py` (string pendulum in displacement variables,
k = 16, EA = 1e3 N, alpha = 0.05 s, 2 s, 100 samples of the end mass with 0.5 mm
noise, data from an independent NumPy/scipy Radau implementation; the fit starts
40 % off), each tolerance is fitted, with `jaxstring.least_squares`'s other
defaults (Kvaerno5), in a fresh process: the first fit's wall time includes
compilation, then `seeds` noise seeds are fitted with the compiled fit. Reported:
the estimates' largest error in units of their reported standard deviation, and
the estimates' change against the tightest tolerance in those units (an estimate
that moves by much less than its standard deviation is as good).

Run: ``python experiments/solve_defaults.py [--quick]``. Writes
results/solve_defaults.{md,csv}.
"""

import argparse
import json
import os
import subprocess
import sys

import _common as common


TOLERANCES = (1e-6, 1e-7, 1e-8)

_CHILD = r"""
import json, sys, time
t_start = time.perf_counter()
import jax.numpy as jnp
import numpy as np
import jaxstring as js
import identify_least_squares as ils
rtol, seeds = float(sys.argv[1]), int(sys.argv[2])
ts = jnp.linspace(0.0, ils.T1, ils.N_SAMPLES)
clean = ils.reference_end_mass(ts)
start = js.string_pendulum(
    "displacement", k=ils.K, EA=ils.START["EA"], alpha=ils.START["alpha"], t1=ils.T1
)
rows = []
for seed in range(seeds):
    data = clean + ils.NOISE * np.random.default_rng(seed).standard_normal(clean.shape)
    t0 = time.perf_counter()
    res = js.least_squares(
        start, js.Misfit(jnp.asarray(data)), ["alpha", "EA"], ts=ts,
        rtol=rtol, atol=rtol, tol=1e-5,
    )
    wall = time.perf_counter() - t0
    rows.append(dict(seed=seed, wall_s=wall, iterations=res.iterations,
                     converged=res.converged, **res.values,
                     alpha_std=res.std["alpha"], EA_std=res.std["EA"]))
print(json.dumps(rows))
"""


def run_tolerance(rtol, seeds):
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, repr(rtol), str(seeds)],
        capture_output=True,
        text=True,
        check=True,
        cwd=os.path.dirname(os.path.abspath(__file__)),
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(quick=False):
    common.set_quick(quick)
    seeds = 2 if quick else 5
    import identify_least_squares as ils

    runs = {rtol: run_tolerance(rtol, seeds) for rtol in TOLERANCES}
    tight = runs[min(TOLERANCES)]
    rows = []
    for rtol, fits in runs.items():
        truth = {"alpha": ils.ALPHA, "EA": ils.EA}
        err_sd = max(
            abs(f[k] - v) / f[f"{k}_std"] for f in fits for k, v in truth.items()
        )
        pairs = list(zip(fits, tight))
        shift_sd = max(
            max(abs(f[k] - g[k]) / g[f"{k}_std"] for f, g in pairs)
            for k in ("alpha", "EA")
        )
        later = [f["wall_s"] for f in fits[1:]]
        rows.append(
            dict(
                rtol=rtol,
                first_fit_s=fits[0]["wall_s"],
                later_fit_s=sum(later) / len(later) if later else float("nan"),
                iterations=fits[0]["iterations"],
                converged=all(f["converged"] for f in fits),
                largest_error_in_std=err_sd,
                shift_from_tightest_in_std=shift_sd,
            )
        )
    notes = [
        f"{seeds} noise seeds per tolerance, each tolerance in its own process; the "
        "first fit's wall time includes compilation (the tracing and XLA "
        "compilation of the forward solve with its JVPs), the later fits reuse it.",
        "largest_error_in_std: the largest |estimate - truth| / reported std over "
        "the seeds and both parameters; shift_from_tightest_in_std: the largest change "
        "of an estimate against the fit at rtol 1e-8 of the same seed, in units of "
        "the reported std.",
    ]
    common.write_table(
        "solve_defaults",
        rows,
        list(rows[0]),
        "Identification defaults: least squares of (alpha, EA) against tolerance",
        notes,
    )
    for r in rows:
        print(r)
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    main(quick=parser.parse_args().quick)
