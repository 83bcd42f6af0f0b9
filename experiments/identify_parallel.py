"""Identification over worker processes: `least_squares` on four experiments with
processes=1 against processes=2.

Question: how much wall time does evaluating the experiments of a Levenberg-
Marquardt identification in worker processes save on a small CPU host? Four
experiments of the displacement-variable string pendulum (k = 16, EA = 1e3 N,
alpha = 0.05 s, 2 s, 100 samples) released at 90, 67.5, 45 and 22.5 degrees share
alpha and EA; the data are tight solves (Rodas5P at rtol = atol = 1e-10) of the
true scene with 0.5 mm Gaussian noise. The fit starts 40 % off (alpha = 0.07 s,
EA = 1.4e3 N); Kvaerno5 at rtol = atol = 1e-6, LM tolerance 1e-5 on log p, as in
`identify_least_squares.py`.

One process solves the four experiments (one structure) in one vmap inside the
compiled Levenberg-Marquardt iteration; two worker processes each solve their
experiments one at a time (one exported program, compiled in each worker) and
the iteration's step is taken in the calling process. A third configuration runs
the workers' programs in one thread of the calling process
(`executor=ThreadPoolExecutor(1)`): one experiment at a time, no processes, so
that the gain of the processes themselves is apart from that of solving the
experiments one by one rather than in one vmap. Each configuration is
called once to compile (with the workers' start for processes=2), then `REPEATS`
times on fresh noise (the compiled programs reused): `compile_s` is the first
call minus the median run.

With ``--fit`` the same experiments are fitted by `fit` instead (L-BFGS on the
sum of squared residuals over the noise, at most `FIT_STEPS` steps, forward-mode
gradients): one process solves the experiments one after another inside its
compiled step (no vmap), workers as for `least_squares`.

Run: ``python experiments/identify_parallel.py [--quick] [--fit]`` (quick: k = 4,
0.5 s, two experiments, one repeat). Writes results/identify_parallel.{md,csv}
(``--fit``: identify_parallel_fit.{md,csv}).
"""

import argparse
import concurrent.futures as cf
import os
import statistics
import subprocess
import sys
import tempfile

import _common as common
import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optax

import jaxstring as js


ANGLES = (np.pi / 2, 3 * np.pi / 8, np.pi / 4, np.pi / 8)
TRUTH = dict(EA=1e3, alpha=0.05)
START = dict(EA=1.4e3, alpha=0.07)
NOISE = 5e-4
REPEATS = 2
FIT_STEPS = 25
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


class _Data(eqx.Module):
    """Each experiment against its own data, told apart by its release position."""

    data: jnp.ndarray  # (experiments, samples, 2)
    ends: jnp.ndarray  # (experiments, 2): the end mass at t = 0

    def __call__(self, traj, scene):
        del scene
        start = traj.end_mass[0]
        i = jnp.argmin(jnp.sum((self.ends - start) ** 2, axis=1))
        return (traj.end_mass - self.data[i]).ravel()


class _Squared(eqx.Module):
    """`fit`'s loss: half the sum of squared residuals over the noise (a Module, so
    that new data reuse the compiled fit)."""

    residual: _Data

    def __call__(self, traj, scene):
        return 0.5 * jnp.sum((self.residual(traj, scene) / NOISE) ** 2)


def _scene(k, t1, angle, **values):
    p = TRUTH | values
    return js.pendulum.string_pendulum(
        "displacement", k=k, EA=p["EA"], alpha=p["alpha"], t1=t1, theta0=angle
    )


def _shell(cmd):
    out = subprocess.run(cmd, shell=True, capture_output=True, text=True)
    return out.stdout.strip()


class _Fitted:
    """A `fit` result read as the table reads a `least_squares` one."""

    def __init__(self, res):
        self.values = res.values()
        self.iterations = len(res.losses)
        self.converged, self.message = res.converged, res.message


def main(quick=False, use_fit=False):
    common.set_quick(quick)
    # A fresh persistent compilation cache: the first calls compile cold (the
    # configuration run after two processes finds their program there).
    os.environ.setdefault("JAXSTRING_CACHE_DIR", tempfile.mkdtemp(prefix="jax_cache_"))
    k, t1, n_samples = (4, 0.5, 26) if quick else (16, 2.0, 100)
    angles = ANGLES[:2] if quick else ANGLES
    repeats = 1 if quick else REPEATS
    ts = jnp.linspace(0.0, t1, n_samples)
    clean, ends = [], []
    for a in angles:
        traj = js.simulate(_scene(k, t1, a), "rodas5p", rtol=1e-10, atol=1e-10, ts=ts)
        clean.append(np.asarray(traj.end_mass))
        ends.append(np.asarray(traj.end_mass[0]))
    clean, ends = np.stack(clean), jnp.asarray(np.stack(ends))
    starts = [_scene(k, t1, a, **START) for a in angles]
    uptime_before = _shell("uptime")

    def fit(processes, seed):
        noisy = clean + NOISE * np.random.default_rng(seed).standard_normal(clean.shape)
        how = dict(processes=processes)
        if processes == "thread":
            how = dict(executor=one_thread)
        data = _Data(jnp.asarray(noisy), ends)
        if use_fit:
            res, wall, _ = common.clock(
                lambda: _Fitted(
                    js.fit(
                        starts,
                        _Squared(data),
                        ["alpha", "EA"],
                        steps=FIT_STEPS,
                        optimizer=optax.lbfgs(),
                        gtol=1e-3,
                        print_every=None,
                        ts=ts,
                        rtol=1e-6,
                        atol=1e-6,
                        adjoint="forward",
                        **how,
                    )
                )
            )
        else:
            res, wall, _ = common.clock(
                lambda: js.least_squares(
                    starts,
                    data,
                    ["alpha", "EA"],
                    ts=ts,
                    rtol=1e-6,
                    atol=1e-6,
                    tol=1e-5,
                    **how,
                )
            )
        print(
            f"processes={processes} seed={seed}: {wall:.2f} s, {res.iterations} "
            f"iterations, {res.message}, {res.values}",
            flush=True,
        )
        return res, wall

    runs = {}
    one_thread = cf.ThreadPoolExecutor(1)
    for p in (1, 2, "thread"):
        first, first_wall = fit(p, 0)
        later = [fit(p, seed) for seed in range(1, repeats + 1)]
        runs[p] = (first, first_wall, later)
    rows = []
    for p, (first, first_wall, later) in runs.items():
        run_s = statistics.median(w for _, w in later)
        rows.append(
            dict(
                processes=p,
                experiments=len(angles),
                k=k,
                iterations=first.iterations,
                converged=first.converged,
                alpha=first.values["alpha"],
                EA=first.values["EA"],
                first_call_s=first_wall,
                compile_s=first_wall - run_s,
                run_s=run_s,
                runs_s=" ".join(f"{w:.2f}" for _, w in later),
            )
        )
    one_thread.shutdown()
    run_s = {r["processes"]: r["run_s"] for r in rows}
    speedup, parallel = run_s[1] / run_s[2], run_s["thread"] / run_s[2]
    rel = max(
        abs(runs[2][0].values[n] / runs[1][0].values[n] - 1) for n in ("alpha", "EA")
    )
    same = max(
        abs(runs[2][0].values[n] / runs["thread"][0].values[n] - 1)
        for n in ("alpha", "EA")
    )
    notes = [
        f"{len(angles)} experiments (release angles "
        f"{', '.join(f'{np.degrees(a):g}' for a in angles)} deg), string pendulum "
        f"k = {k}, {t1} s, {n_samples} samples, noise {NOISE * 1e3} mm; alpha and EA "
        f"from a start 40 % off; Kvaerno5 at rtol = atol = 1e-6, "
        + (
            f"fit: L-BFGS, at most {FIT_STEPS} steps, gtol 1e-3, forward mode."
            if use_fit
            else "LM tol 1e-5."
        ),
        "first_call_s: the first call (tracing, compilation; for processes=2 also "
        "starting the two workers and compiling in each, from a cold persistent "
        "compilation cache; processes=thread, run last, loads the same program "
        "from that cache); run_s: median of "
        f"{repeats} later calls on fresh noise; compile_s = first_call_s - run_s.",
        "processes=thread: `executor=ThreadPoolExecutor(1)`, the workers' programs "
        "run one experiment at a time in this process (what two processes share "
        "out); processes=1: the experiments "
        + (
            "one after another inside the compiled step"
            if use_fit
            else "in one vmap inside the compiled iteration"
        )
        + " (the default path of one process).",
        f"Compiled run: processes=1 over processes=2 {speedup:.2f}x; one thread over "
        f"two processes {parallel:.2f}x.",
        f"Largest relative difference of the fitted values (seed 0): two processes "
        f"against one thread {same:.1e} (the same programs), against processes=1 "
        f"{rel:.1e}"
        + (
            "."
            if use_fit
            else " (the vmapped solves differ from separate ones by "
            "about the solver's tolerance)."
        ),
        f"Machine: `{_shell('uname -a')}`; nproc: {_shell('nproc')}.",
        f"Load (`uptime`) before: {uptime_before}; after: {_shell('uptime')}. The "
        "machine is shared with other jobs.",
        "Command: `python "
        + " ".join([os.path.relpath(os.path.abspath(sys.argv[0]), ROOT)] + sys.argv[1:])
        + "`.",
    ]
    columns = list(rows[0])
    common.write_table(
        "identify_parallel_fit" if use_fit else "identify_parallel",
        rows,
        columns,
        f"{'fit' if use_fit else 'least_squares'} over worker processes: "
        f"{len(angles)} experiments, processes=1 vs 2",
        notes,
    )
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--fit", action="store_true", help="fit instead of LM")
    args = parser.parse_args()
    main(quick=args.quick, use_fit=args.fit)
