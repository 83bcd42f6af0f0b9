"""``jaxstring run moordyn DECK [--motion FILE] [--ramp S] [--t1 T] ...``: a MoorDyn
v2 deck.

Reads the deck (`jaxstring.lines.read_moordyn`), solves its static equilibrium,
prints the static end tensions of every line, simulates the span and writes the
MoorDyn-style channels as ``<out>/<deck>.out`` (tab-separated) and
``<out>/<deck>.npz``. Exit codes: 0 on success, 1 when the solve failed (the data
up to the failure is still written), 2 on bad input.
"""

import argparse
import os
import sys
import time


def add_parser(scene_parsers, common_arguments, cache_arguments) -> None:
    """Add the `moordyn` scene to `jaxstring run`."""
    help = "a MoorDyn v2 input deck (lines, points, options)"
    p = scene_parsers.add_parser("moordyn", help=help, description=help)
    p.add_argument("deck", help="path of the MoorDyn v2 input file")
    p.add_argument(
        "--motion",
        default=None,
        help="table of the coupled points' motion: rows 't x y z [0 0 0]' (s, m), "
        "a translation added to every Vessel/Coupled point's deck position",
    )
    p.add_argument("--t0", type=float, default=None, help="start time, s "
                   "(default: the motion table's first time, else 0)")  # fmt: skip
    p.add_argument("--t1", type=float, default=None, help="end time, s "
                   "(default: the motion table's last time, else t0 + 10)")  # fmt: skip
    p.add_argument(
        "--ramp",
        type=float,
        default=None,
        help="ramp the motion table in from rest over its first RAMP seconds "
        "(`jaxstring.lines.ramp_in`), s",
    )
    # `read_moordyn`'s choices; the first is the default
    for option, choices, text in (
        ("axial_drag", ("surface", "diameter"), "area of the line types' CdAx: "
         "'surface' (pi d, MoorDyn's) or 'diameter' (d, DNV's and OrcaFlex's "
         "chain convention)"),
        ("free_points", ("hold", "solve"), "the static equilibrium: free points "
         "held at their deck positions ('hold') or settled with the lines "
         "('solve'; e.g. the free end of MoorDyn's cantilevered beam)"),
    ):  # fmt: skip
        p.add_argument("--" + option.replace("_", "-"), dest=option, choices=choices,
                       default=choices[0],
                       help=f"{text}; default {choices[0]!r}")  # fmt: skip
    p.add_argument(
        "--dt-out", dest="dt_out", type=float, default=0.1, help="output step, s"
    )
    common_arguments(p, "kvaerno5")
    p.set_defaults(rtol=1e-4, atol=1e-4)
    cache_arguments(p)


def run(args: argparse.Namespace) -> int:
    """Run a deck from the parsed arguments; returns the exit code."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from .. import lines
    from .._simulate import simulate
    from .._validate import check_positive

    try:
        check_positive("rtol", args.rtol)
        check_positive("atol", args.atol)
        check_positive("--dt-out", args.dt_out, "s")
        motion = args.motion
        if args.ramp is not None:
            check_positive("--ramp", args.ramp, "s")
            if motion is None:
                raise ValueError("`--ramp` needs a `--motion` table to ramp in.")
            times, offsets = lines.read_motion(motion)
            motion = (times, lines.ramp_in(times, offsets, args.ramp))
        start = time.perf_counter()
        scene = lines.read_moordyn(args.deck, motion=motion, t1=args.t1, t0=args.t0,
                                   axial_drag=args.axial_drag,
                                   free_points=args.free_points)  # fmt: skip
        setup_s = time.perf_counter() - start
        os.makedirs(args.out, exist_ok=True)
    except (ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    t0, t1 = float(scene.t0), float(scene.t1)
    n = max(int(round((t1 - t0) / args.dt_out)) + 1, 2)
    ts = jnp.linspace(t0, t1, n)
    start = time.perf_counter()
    traj = simulate(scene, args.solver, rtol=args.rtol, atol=args.atol, ts=ts,
                    progress=bool(args.progress))  # fmt: skip
    traj = jax.block_until_ready(traj)
    wall = time.perf_counter() - start
    stem = os.path.join(args.out, scene.name)
    out, npz = lines.write_outputs(traj, scene, stem)
    static = lines.static_tensions(scene)
    rows = [f"jaxstring run moordyn {args.deck}"]
    m = scene.model
    rows.append(
        f"  {m.n_lines} lines, {len(m.points)} points, "
        f"{sum(m.segments)} segments; t = {t0:g} .. {t1:g} s"
    )
    rows.append(f"  static equilibrium (jaxstring's own solve): {setup_s:.2f} s")
    for lid, (ta, tb) in static.items():
        rows.append(f"  line {lid}: static tension A {ta / 1e3:.2f} kN, "
                    f"B {tb / 1e3:.2f} kN")  # fmt: skip
    fb = np.asarray(traj.obs["tension_b"])
    rows.append(f"solver: {args.solver}  rtol={args.rtol:g}  atol={args.atol:g}")
    rows.append(f"status: {traj.status}  ({int(traj.stats['num_steps'])} steps)")
    rows.append(f"wall time (first call, incl. compilation): {wall:.2f} s")
    for k, lid in enumerate(m.line_ids or range(1, m.n_lines + 1)):
        lo, hi = np.nanmin(fb[:, k]) / 1e3, np.nanmax(fb[:, k]) / 1e3
        rows.append(f"  line {lid}: fairlead (B) tension {lo:.2f} .. {hi:.2f} kN")
    rows += [f"wrote {out}", f"wrote {npz}"]
    print("\n".join(rows))
    return 0 if traj.ok else 1
