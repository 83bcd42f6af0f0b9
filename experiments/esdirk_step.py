"""Kvaerno5 written out against diffrax's generic Runge-Kutta loop: steps, time and
XLA kernels per attempted step.

Question: how much of a Kvaerno5 step is diffrax's generic stage loop? The same
tableau runs two ways on the pendulum (k = 40, alpha = 0.01 s, 2 s, rtol = atol =
`--tols`):
- "written out": `jaxstring._solvers.esdirk.ESDIRK`, what `simulate(...,
  "kvaerno5")` runs where one Jacobian per step serves (natural variables);
- "diffrax": `diffrax.Kvaerno5` with jaxstring's `StageNewton` (one Jacobian per
  step; for the displacement string a Jacobian per stage, `registry.Kvaerno5`,
  which `simulate` runs there).
Both under the same `NewtonLimitedController`. Error: the largest end-mass distance
at 0.5, 1, 1.5, 2 s from Rodas5P at rtol = atol = 1e-11. Time: wall, best of
`--repeats`, after compilation (compile apart). Kernels: XLA kernels (thunk events)
per attempted step in a profiler trace of the first 0.4 s, counted as
experiments/step_cost.py counts them.

Run: ``python experiments/esdirk_step.py [--quick]``.
"""

import math
import tempfile

import _common as common
import diffrax as dfx
import harness
import jax
import numpy as np
from step_cost import _kernel_events

import jaxstring
from jaxstring._solvers.esdirk import ESDIRK
from jaxstring._solvers.registry import Kvaerno5 as Kvaerno5PerStage
from jaxstring._solvers.stage_newton import StageNewton


SCENES = (("angle", 1e6), ("angle", 1e9), ("natural", 1e9), ("displacement", 1e6))
COLUMNS = (
    "formulation EA tol solver ok err_m accepted attempts wall_s us_per_attempt "
    "kernels_per_attempt compile_s"
).split()


def _solvers(form, tol):
    newton = StageNewton(rtol=tol, atol=tol, max_iters=10)
    diffrax_cls = Kvaerno5PerStage if form == "displacement" else dfx.Kvaerno5
    out = {"diffrax": diffrax_cls(root_finder=newton, root_find_max_steps=10)}
    if form != "displacement":
        out["written out"] = ESDIRK(method="kvaerno5", rtol=tol, atol=tol)
    return out


def _kernels(scene, solver, tol, t1):
    ts = np.linspace(0.0, t1, 3)
    run = lambda: common.block(
        jaxstring.simulate(scene, solver, rtol=tol, atol=tol, ts=ts, max_steps=10**6)
    )
    traj = run()
    with tempfile.TemporaryDirectory() as d:
        with jax.profiler.trace(d, create_perfetto_trace=True):
            run()
        n = _kernel_events(d)
    return n / int(traj.stats["num_steps"])


def main(quick=False, tols=None, repeats=None):
    common.set_quick(quick)
    tols = tols or ((1e-6,) if quick else (1e-3, 1e-5, 1e-7))
    repeats = repeats or (1 if quick else 3)
    k, t1 = (8, 0.5) if quick else (40, 2.0)
    scenes = SCENES[:1] if quick else SCENES
    ts = np.linspace(0.0, t1, 5)
    rows = []
    for form, EA in scenes:
        scene = jaxstring.string_pendulum(formulation=form, k=k, EA=EA, t1=t1)
        ref, _ = harness.reference(scene, ts, "rodas5p", 1e-11, max_steps=10**6)
        for tol in tols:
            for label, solver in _solvers(form, tol).items():
                code = harness.jaxstring_code(
                    scene, solver, ts, label=label, max_steps=10**6
                )
                # a first call (compile), then the best of `repeats`
                rec = harness.repeat(code, tol, repeats, stat=min, long_run_s=math.inf)
                attempts = rec["num_steps"]
                row = dict(
                    formulation=form,
                    EA=EA,
                    tol=tol,
                    solver=label,
                    ok=rec["ok"],
                    err_m=harness.end_mass_error(
                        rec["end"][1:] if rec["ok"] else None, ref[1:]
                    ),
                    accepted=rec["accepted"],
                    attempts=attempts,
                    wall_s=rec["wall_s"],
                    us_per_attempt=rec["wall_s"] / attempts * 1e6,
                    kernels_per_attempt=_kernels(scene, solver, tol, t1 / 5),
                    compile_s=rec["compile_s"],
                )
                rows.append(row)
                print(row, flush=True)
    notes = [
        "written out: jaxstring's ESDIRK (one Jacobian and factorisation per step, "
        "stages unrolled, one Newton while loop per stage); diffrax: diffrax's "
        "Kvaerno5 with StageNewton (displacement: a Jacobian per stage, as "
        "simulate runs it there). Same tableau, same controller.",
        "kernels_per_attempt: XLA kernel events per attempted step in a profiler "
        "trace of the first t1 / 5 s (rejected attempts and Newton iterations "
        "included; step_cost.py's count).",
    ]
    for form, EA in scenes:
        for tol in tols:
            pair = {
                r["solver"]: r
                for r in rows
                if (r["formulation"], r["EA"], r["tol"]) == (form, EA, tol)
            }
            if len(pair) == 2:
                a, b = pair["written out"], pair["diffrax"]
                kr = a["kernels_per_attempt"] / b["kernels_per_attempt"]
                notes.append(
                    f"{form} EA = {EA:g}, tol {tol:g}: written out / diffrax: "
                    f"wall {a['wall_s'] / b['wall_s']:.2f}x, per attempt "
                    f"{a['us_per_attempt'] / b['us_per_attempt']:.2f}x, kernels "
                    f"per attempt {kr:.2f}x."
                )
    name = "esdirk_step" + ("_quick" if quick else "")
    common.write_table(
        name,
        rows,
        COLUMNS,
        f"Kvaerno5 written out vs diffrax's Runge-Kutta loop (pendulum k = {k}, "
        f"{t1:g} s)",
        notes,
    )
    return rows


if __name__ == "__main__":
    common.run_study(main, lists={"tols": float})
