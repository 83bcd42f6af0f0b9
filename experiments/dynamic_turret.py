"""The FPSO's turret on lines integrated with the hull against the quasi-static
lines: what the lines' dynamics change and what they cost.

The FPSO alone (spec S0, turret at 0.40 L) turned 10 deg off a 1 m/s current,
600 s, on the packaged turret deck (nine chain/wire/chain legs, 1000 m of water):

- quasi-static: `mooring="lines"` (the catenaries' statics at every evaluation),
  tsit5 at rtol = atol = 1e-8;
- dynamic: `with_dynamic_mooring` with `segments` per line (the deck's 20, and
  fewer), the lines in still water and the same turret damping c_m = 6e5 N s/m,
  Kvaerno5 at rtol = atol = 1e-6 (the hull's row as the border of the lines'
  band).

Per row: the lumped lines' turret force at the start (against the catenaries'),
the largest difference of the hull's position and heading from the quasi-static
run, steps, compile and run time apart. Writes results/dynamic_turret.{md,csv}.

    python experiments/dynamic_turret.py [--quick] [--segments 5,10,20]
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax.numpy as jnp
import numpy as np
from _common import run_study, timed, timing_fields, write_table

import jaxstring as js
from jaxstring.tandem import TurretLines, tandem_fpso_alone, with_dynamic_mooring


T1 = 600.0


def main(quick=False, repeats=None, segments=()):
    segments = list(segments or ()) or ([5] if quick else [5, 10, 20])
    repeats = repeats or 2
    qs = tandem_fpso_alone(mooring="lines", psi0_deg=10.0, t1=T1)
    ts = jnp.linspace(0.0, T1, 61)
    lines_qs = next(e for e in qs.effects if isinstance(e, TurretLines))
    y0 = np.asarray(qs.y0)
    psi = y0[2]
    P0 = y0[:2] + float(qs.model.x_t) * np.array([np.cos(psi), np.sin(psi)])
    F_qs = np.asarray(lines_qs.restoring_force(jnp.asarray(P0)))
    tim, ref = timed(lambda: js.simulate(qs, "tsit5", rtol=1e-8, atol=1e-8, ts=ts),
                     repeats)  # fmt: skip
    yr = np.asarray(ref.ys)
    rows = [
        dict(
            mooring="quasi-static",
            segments="-",
            states="6",
            F_x_kN=F_qs[0] / 1e3,
            **timing_fields(ref, tim.compile_s, tim.run_s),
        )
    ]
    for n in segments:
        dyn = with_dynamic_mooring(qs, segments=n, c_m=6.0e5, current=False)
        obs = dyn.observables(dyn.y0)
        tim, tr = timed(
            lambda: js.simulate(dyn, "kvaerno5", rtol=1e-6, atol=1e-6, ts=ts), repeats
        )
        y = np.asarray(tr.ys)[:, 0]
        rows.append(
            dict(
                mooring="dynamic",
                segments=n,
                states=str(dyn.y0.size),
                F_x_kN=float(obs["turret_force"][0]) / 1e3,
                dx_m=float(np.max(np.abs(y[:, :2] - yr[:, :2]))),
                dpsi_deg=float(np.degrees(np.max(np.abs(y[:, 2] - yr[:, 2])))),
                **timing_fields(tr, tim.compile_s, tim.run_s),
            )
        )
        print(rows[-1], flush=True)
    write_table(
        "dynamic_turret" + ("_quick" if quick else ""),
        rows,
        [
            "mooring",
            "segments",
            "states",
            "F_x_kN",
            "dx_m",
            "dpsi_deg",
            "status",
            "steps",
            "compile_s",
            "run_s",
        ],  # fmt: skip
        "FPSO alone on the turret deck's lines, 600 s: dynamic against quasi-static",
        notes=[
            "F_x_kN: the lines' force on the turret along x at the start (the "
            "quasi-static row: the catenaries').",
            "dx_m, dpsi_deg: largest difference of the hull's position and heading "
            "from the quasi-static run over 61 samples.",
            f"The hull swings {np.degrees(np.ptp(yr[:, 2])):.2f} deg and moves "
            f"{np.max(np.abs(yr[:, :2] - yr[0, :2])):.2f} m in the quasi-static run.",
        ],
    )


if __name__ == "__main__":
    run_study(main, lists={"segments": int})
