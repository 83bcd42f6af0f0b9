"""Command line: ``jaxstring run <scene> [options]`` and ``jaxstring sweep <scene>
--vary NAME=LOW:HIGH:COUNT [options]`` (`jaxstring.cli.sweep`).

Each scene has a runner in `SCENES`: a function that adds the scene's options to an
argparse subparser, and one that builds the `Scene` from the parsed options. Runs
print a one-screen summary and write ``<out>/<scene>.png`` and ``<out>/<scene>.npz``.

Exit codes: 0 on success, 1 when the solve failed (the data up to the failure is
still written), 2 on bad input (argparse errors, or a ValueError from the scene).
"""

import argparse
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass


# Interval of the saved data, s.
SAVE_DT = 0.01


@dataclass(frozen=True)
class SceneRunner:
    """How the command line builds one named scene."""

    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    build: Callable[[argparse.Namespace], object]  # -> jaxstring.Scene
    parameters: Callable[[argparse.Namespace], dict]  # scalars for summary and npz
    long_run: Callable[[argparse.Namespace], bool]  # show a progress meter?
    figure: Callable | None = None  # (traj, path, title) -> path; default: pendulum
    solver: str = "kvaerno5"  # default solver of the scene
    animate: Callable | None = None  # (traj, path, frames, title) -> path; pendulum


# ---------------------------------------------------------------------------
# string-pendulum


def _pendulum_arguments(p: argparse.ArgumentParser) -> None:
    from ..pendulum.models import FORMULATIONS

    p.add_argument(
        "--formulation",
        choices=tuple(FORMULATIONS),
        default="displacement",
        help="model variables (default: displacement)",
    )
    p.add_argument("--EA", type=float, default=1e6, help="axial stiffness, N")
    p.add_argument("--alpha", type=float, default=0.01, help="Kelvin-Voigt const, s")
    p.add_argument("--k", type=int, default=40, help="number of elements")
    p.add_argument("--l", type=float, default=1.0, help="unstrained length, m")
    p.add_argument("--mu", type=float, default=1.0, help="mass per length, kg/m")
    p.add_argument("--m-s", dest="m_s", type=float, default=1.0, help="end mass, kg")
    p.add_argument("--g", type=float, default=9.81, help="gravity, m/s^2")
    p.add_argument("--t1", type=float, default=2.0, help="end time, s")
    p.add_argument(
        "--theta0",
        type=float,
        default=math.pi / 2,
        help="release angle from the downward vertical, rad (default: pi/2)",
    )
    p.add_argument(
        "--slack",
        action="store_true",
        help="tension-only string (adds the 'slack' effect)",
    )


def _pendulum_build(a: argparse.Namespace):
    from ..pendulum.scenes import DEFAULT_PENDULUM_EFFECTS, string_pendulum

    p = _pendulum_parameters(a)
    effects = tuple(DEFAULT_PENDULUM_EFFECTS)
    if p.pop("slack"):
        effects = effects + ("slack",)
    return string_pendulum(**p, effects=effects)


_PENDULUM_KEYS = "formulation k EA alpha l mu m_s g theta0 t1 slack".split()


def _pendulum_parameters(a: argparse.Namespace) -> dict:
    return {key: getattr(a, key) for key in _PENDULUM_KEYS}


def _pendulum_long_run(a: argparse.Namespace) -> bool:
    return a.k >= 80 or a.EA >= 1e8 or a.t1 > 5


SCENES = {
    "string-pendulum": SceneRunner(
        help="string pendulum of Poth et al. (viscoelastic string with an end mass)",
        add_arguments=_pendulum_arguments,
        build=_pendulum_build,
        parameters=_pendulum_parameters,
        long_run=_pendulum_long_run,
    ),
}


# ---------------------------------------------------------------------------
# tether-fixed, tether-winch (Blintsov 2017)


def _tether_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--method", choices=("aceam", "exact", "lms"), default="aceam")
    p.add_argument("--N", type=int, default=101, help="number of elements")
    p.add_argument("--t1", type=float, default=70.0, help="end time, s")
    p.add_argument(
        "--smoothing",
        type=float,
        default=0.0,
        help="velocity ramp at the schedule's corners, s",
    )
    p.add_argument(
        "--k-lms", dest="k_lms", type=float, default=None, help="LMS stiffness, N"
    )


def _tether_build(name: str):
    def build(a: argparse.Namespace):
        from .. import tether

        return getattr(tether, name)(
            method=a.method, N=a.N, t1=a.t1, smoothing=a.smoothing, k_lms=a.k_lms
        )

    return build


def _tether_parameters(a: argparse.Namespace) -> dict:
    return {"method": a.method, "N": a.N, "t1": a.t1, "smoothing": a.smoothing}


def _tether_figure(traj, path, title=""):
    from ..tether import plot as tether_plot

    return tether_plot.summary_figure(traj, path, title=title)


def _tether_animate(traj, path, frames, title=""):
    from ..tether import plot as tether_plot

    return tether_plot.animate(traj, path, frames=frames, title=title)


for _name, _fn, _help in (
    ("tether-fixed", "tether_fixed", "Blintsov 2017 tether, fixed length (Fig 5)"),
    ("tether-winch", "tether_winch", "Blintsov 2017 tether, pay-out/haul-in (Fig 6)"),
):
    SCENES[_name] = SceneRunner(
        help=_help,
        add_arguments=_tether_arguments,
        build=_tether_build(_fn),
        parameters=_tether_parameters,
        long_run=lambda a: True,
        figure=_tether_figure,
        animate=_tether_animate,
        solver="dopri5",  # the paper's integrator; ACEAM is not stiff
    )


# ---------------------------------------------------------------------------


def _common_arguments(p: argparse.ArgumentParser, solver: str = "kvaerno5") -> None:
    from .._solvers.names import SOLVERS

    p.add_argument(
        "--solver", choices=tuple(SOLVERS), default=solver, help="ODE solver"
    )
    p.add_argument("--rtol", type=float, default=1e-6, help="relative tolerance")
    p.add_argument("--atol", type=float, default=1e-6, help="absolute tolerance")
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="text progress meter (default: on for long runs)",
    )
    p.add_argument(
        "--timing",
        action="store_true",
        help="run the scene a second time to report the compiled run's wall time",
    )
    p.add_argument("--out", default="out", help="output directory (default: ./out)")
    _animation_arguments(p)


def _animation_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--animate", action="store_true", help="also write the run as a GIF animation"
    )
    p.add_argument(
        "--frames", type=int, default=60, help="frames of the animation (default 60)"
    )


def _cache_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--cache",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="JAX's persistent compilation cache in $JAXSTRING_CACHE_DIR or "
        "~/.cache/jaxstring/jax: a second run skips compilation (default: on, "
        "unless JAXSTRING_CACHE=off)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxstring",
        description="Simulate strings, tethers and vessels with jaxstring.",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    run = commands.add_parser("run", help="simulate a named scene")
    scene_parsers = run.add_subparsers(
        dest="scene",
        metavar="SCENE",
        required=True,
        help="one of: " + ", ".join(SCENES) + ", tandem-..., moordyn",
    )
    for name, runner in SCENES.items():
        sp = scene_parsers.add_parser(name, help=runner.help, description=runner.help)
        runner.add_arguments(sp)
        _common_arguments(sp, runner.solver)
        _cache_arguments(sp)
    from .tandem import TANKER_SCENES

    for name in TANKER_SCENES:
        sp = scene_parsers.add_parser(name, help=f"FPSO + shuttle tandem ({name})")
        sp.add_argument("--quick", action="store_true", help="shorter runs")
        sp.add_argument("--out", default="out", help="output directory")
        sp.add_argument(
            "--hawser",
            choices=("massless", "line"),
            default="massless",
            help="massless hawser (spec) or a line with mass and drag "
            "(tandem-fishtail, tandem-controlled)",
        )
        _animation_arguments(sp)
        _cache_arguments(sp)
    from . import moordyn, sweep

    moordyn.add_parser(scene_parsers, _common_arguments, _cache_arguments)
    sweep.add_parser(commands, SCENES, _common_arguments)
    return parser


def _fmt(x, spec: str = ".6g") -> str:
    return "n/a" if x is None or not math.isfinite(x) else format(x, spec)


def _nanmax(x):
    import numpy as np

    x = np.asarray(x, dtype=float)
    if x.size == 0 or not np.any(np.isfinite(x)):
        return None
    return float(np.nanmax(x))


def _run_scene(args: argparse.Namespace) -> int:
    runner = SCENES[args.scene]
    from .._validate import check_positive

    try:
        check_positive("rtol", args.rtol)
        check_positive("atol", args.atol)
        scene = runner.build(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as e:
        print(f"error: --out {args.out!r}: cannot create the directory ({e}).",
              file=sys.stderr)  # fmt: skip
        return 2

    import jax
    import numpy as np

    from .._executables import imports_while_compiling
    from .._simulate import simulate

    t0, t1 = float(scene.t0), float(scene.t1)
    n_save = max(int(round((t1 - t0) / SAVE_DT)) + 1, 2)
    ts = np.linspace(t0, t1, n_save)  # on the host: no program to compile
    progress = runner.long_run(args) if args.progress is None else args.progress

    def call():
        start = time.perf_counter()
        traj = simulate(
            scene,
            solver=args.solver,
            rtol=args.rtol,
            atol=args.atol,
            ts=ts,
            progress=progress,
        )
        traj = jax.block_until_ready(traj)
        return traj, time.perf_counter() - start

    # the figure's modules, imported while XLA compiles the solve
    plots = (
        "jaxstring.pendulum.plot" if runner.figure is None else "jaxstring.tether.plot"
    )
    figure_modules = ("matplotlib.figure", "matplotlib.backends.backend_agg", plots)
    try:
        with imports_while_compiling(*figure_modules):
            traj, wall_first = call()
        wall_second = None
        if args.timing:
            traj, wall_second = call()
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    params = runner.parameters(args)
    n_valid = int(traj.n_valid)
    energy = np.asarray(traj.energy)
    last = n_valid - 1
    e_start = float(energy[0]) if n_valid > 0 else None
    e_end = float(energy[last]) if n_valid > 0 else None
    end_mass = np.asarray(traj.end_mass)[last] if n_valid > 0 else None
    stats = {k: int(v) for k, v in traj.stats.items()}

    # -- outputs
    stem = args.scene.replace("-", "_")
    png = os.path.join(args.out, stem + ".png")
    npz = os.path.join(args.out, stem + ".npz")
    title = (
        f"{scene.name}: "
        + ", ".join(f"{k}={v:g}" for k, v in params.items() if _is_number(v))
        + f"  [{args.solver}, {traj.status}]"
    )
    from ..pendulum import plot

    (runner.figure or plot.summary_figure)(traj, png, title=title)
    gif = None
    if args.animate:
        gif = os.path.join(args.out, stem + ".gif")
        if runner.animate is None:
            plot.animate(traj, gif, frames=args.frames, title=title)
        else:
            runner.animate(traj, gif, args.frames, title=title)
    np.savez(
        npz,
        ts=np.asarray(traj.ts),
        positions=np.asarray(traj.positions),
        velocities=np.asarray(traj.velocities),
        tension=np.asarray(traj.tension),
        strain=np.asarray(traj.strain),
        energy=energy,
        constraint_error=np.asarray(traj.constraint_error),
        n_valid=n_valid,
        t_end=float(traj.t_end),
        ok=traj.ok,
        status=traj.status,
        solver=args.solver,
        rtol=args.rtol,
        atol=args.atol,
        wall_first=wall_first,
        wall_second=np.nan if wall_second is None else wall_second,
        **{k: np.asarray(v) for k, v in params.items()},
        **stats,
    )

    # -- summary
    width = 42
    lines = [f"jaxstring run {args.scene}  ({scene.name})"]
    lines.append("scene:")
    for k, v in params.items():
        lines.append(
            f"  {k:<{width - 2}} {v:g}" if _is_number(v) else f"  {k:<{width - 2}} {v}"
        )
    effects = ", ".join(type(e).__name__ for e in scene.effects)
    lines.append(f"  {'effects':<{width - 2}} {effects}")
    lines.append(
        f"solver: {args.solver}  rtol={args.rtol:g}  atol={args.atol:g}  "
        f"saved every {SAVE_DT:g} s ({n_save} points)"
    )
    lines.append(f"{'status':<{width}} {traj.status}")
    lines.append(
        f"{'steps':<{width}} {stats['num_accepted_steps']} accepted, "
        f"{stats['num_rejected_steps']} rejected"
    )
    if not traj.ok:
        lines.append(
            f"{'last valid save':<{width}} t = {float(traj.t_end):.6g} s "
            f"({n_valid} of {n_save} saved points)"
        )
    lines.append(
        f"{'wall time (first call, incl. compilation)':<{width}} {wall_first:.3f} s"
    )
    if wall_second is not None:
        lines.append(
            f"{'wall time (compiled, second call)':<{width}} {wall_second:.3f} s"
        )
    lines.append(f"{'energy at start':<{width}} {_fmt(e_start)} J")
    t_last = float(np.asarray(traj.ts)[last]) if n_valid > 0 else t0
    lines.append(f"{f'energy at t = {t_last:.6g} s':<{width}} {_fmt(e_end)} J")
    if end_mass is not None:
        xs = ", ".join(f"{float(c):.6g}" for c in end_mass)
        lines.append(f"{f'end mass at t = {t_last:.6g} s':<{width}} ({xs}) m")
    lines.append(f"{'max strain':<{width}} {_fmt(_nanmax(traj.strain))}")
    lines.append(f"{'max tension':<{width}} {_fmt(_nanmax(traj.tension))} N")
    lines.append(
        f"{'max constraint error':<{width}} {_fmt(_nanmax(traj.constraint_error))}"
    )
    lines.append(f"wrote {png}")
    lines.append(f"wrote {npz}")
    if gif is not None:
        lines.append(f"wrote {gif}")
    print("\n".join(lines))
    return 0 if traj.ok else 1


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def main(argv=None) -> int:
    """Entry point of the ``jaxstring`` command; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "run":
        # The command only writes files: matplotlib's file backend, whatever the
        # machine has for a display.
        import matplotlib

        matplotlib.use("Agg")
        if args.frames < 2:
            print(f"error: --frames must be an integer >= 2; got {args.frames}.",
                  file=sys.stderr)  # fmt: skip
            return 2
        from .._config import (
            cache_off_by_environment,
            disable_compilation_cache,
            enable_compilation_cache,
        )

        if args.cache is None:
            args.cache = not cache_off_by_environment()
        if args.cache:
            enable_compilation_cache(min_compile_s=0.0)
        else:
            disable_compilation_cache()
        if args.scene == "moordyn":
            from . import moordyn

            return moordyn.run(args)
        from .tandem import TANKER_SCENES, run_tanker

        if args.scene in TANKER_SCENES:
            frames = args.frames if args.animate else 0
            return run_tanker(args.scene, args.out, args.quick, args.hawser, frames)
        return _run_scene(args)
    if args.command == "sweep":
        import matplotlib

        matplotlib.use("Agg")
        from . import sweep

        return sweep.run(args, SCENES[args.scene])
    parser.error(f"unknown command {args.command!r}")  # pragma: no cover
    return 2  # pragma: no cover


if __name__ == "__main__":
    raise SystemExit(main())
