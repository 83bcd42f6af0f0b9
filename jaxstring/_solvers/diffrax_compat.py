"""Every use of diffrax's private API, in one place, checked against tested versions.

jaxstring's own stiff solvers plug into diffrax at three points that diffrax does not
document as public:

1. `CalculateJacobian` (diffrax._solver.runge_kutta): the Kvaerno methods take a
   Jacobian at every implicit stage's predictor (`every_stage`), not one per step.
2. The argument tuple diffrax hands the root finder of an implicit Runge-Kutta
   stage (`stage_arguments`): the banded stage Newton measures its increments in
   the units of the state and builds the stage Jacobian from the model's own.
3. `RESULTS._index_to_message` and the `_value` of a result (`code_message`,
   `result_code`): the integer code and text of a failure.
4. `diffeqsolve`'s run-time checks of the save times and of the step's direction
   (`equinox.internal.error_if` with three messages of `diffrax._integrate`):
   jaxstring checks both before it traces a solve, and `save_times_checked` leaves
   diffrax's copies out of the program, which otherwise compile to host callbacks
   that JAX neither writes to its persistent compilation cache nor exports to
   worker processes.
5. The run-time check of a lineax linear solve (`equinox._enum`'s
   `branched_error_if`), which the tangent of an implicit stage's root find holds
   in forward mode (optimistix's implicit function theorem solves with
   `throw=True`): `checks_as_nan` traces a program for worker processes with it
   returning NaN instead of raising through a host callback.

6. `WrapTerm` (diffrax._term), the term that `diffeqsolve` hands its solver
   (for the direction of time): `forward_term` wraps a term as `diffeqsolve`
   does for t1 > t0, so that jaxstring's own step loop
   (`jaxstring._solvers.loop`) runs each solver exactly as diffrax's loop does;
   and `use_stepsize_tol` (diffrax._root_finder), the marker of a root finder
   whose tolerances `diffeqsolve` takes from the step-size controller
   (`takes_controller_tolerances`: such a solver stays with `diffeqsolve`).

diffrax versions outside `TESTED` are refused at import with a message that names
the installed and the tested versions, rather than failing deep inside a solve.
"""

import contextlib
import functools
from typing import Any, NamedTuple

import diffrax as dfx
import equinox.internal as eqxi

from .._config import NAN_CHECKS_CONTEXT


TESTED = ((0, 7, 2), (0, 8, 0))  # >= 0.7.2, < 0.8


def _version(text: str) -> tuple[int, ...]:
    parts = []
    for piece in text.split(".")[:3]:
        digits = "".join(ch for ch in piece if ch.isdigit())
        parts.append(int(digits) if digits else 0)
    return tuple(parts + [0] * (3 - len(parts)))


def check_version(version: str) -> None:
    """Raise ImportError unless diffrax `version` lies in the tested range."""
    low, high = TESTED
    if not (low <= _version(version) < high):
        raise ImportError(
            f"jaxstring is tested with diffrax >= {'.'.join(map(str, low))}, "
            f"< {'.'.join(map(str, high))}; diffrax {version} is installed. "
            "Install a tested version: pip install 'diffrax>=0.7.2,<0.8'."
        )


check_version(dfx.__version__)

from diffrax._solver.runge_kutta import CalculateJacobian  # noqa: E402


EVERY_STAGE = CalculateJacobian.every_stage


def takes_controller_tolerances(solver) -> bool:
    """Whether `solver`'s root finder takes its tolerances or norm from the
    step-size controller (diffrax's default implicit solvers), which
    `diffeqsolve` sets."""
    from diffrax._root_finder import use_stepsize_tol

    finder = getattr(solver, "root_finder", None)
    return finder is not None and any(
        getattr(finder, a, None) is use_stepsize_tol for a in ("rtol", "atol", "norm")
    )


def forward_term(term):
    """`term` as `diffeqsolve` hands it to a solver where time runs forward."""
    from diffrax._term import WrapTerm

    return WrapTerm(term, 1)


def result_code(result):
    """The integer code of a diffrax result (0: success); an array under a trace."""
    return result._value


def code_message(code: int) -> str:
    """'success' or diffrax's message for an integer result code."""
    message = dfx.RESULTS._index_to_message[int(code)]
    return message or ("success" if code == 0 else "failure")


class StageArguments(NamedTuple):
    """The parts of diffrax's root-finder arguments for an implicit stage.

    `kind`: `"esdirk_f"` (an ESDIRK stage in f-space: Kvaerno), `"esdirk_k"` (in
    k-space), `"implicit_euler_k"`, or None (a layout this module does not know).
    The other fields are None where the layout has no such part.
    """

    kind: str | None
    diagonal: Any = None
    vf: Any = None
    prod: Any = None
    ti: Any = None
    yi_partial: Any = None
    args: Any = None
    control: Any = None
    y0: Any = None


def stage_arguments(args) -> StageArguments:
    """Name the parts of the `args` diffrax passes to an implicit stage's root finder
    (diffrax 0.7: `_implicit_stage` tuples of 8 (f-space) and 7 (k-space) items for
    ESDIRKs, 5 for implicit Euler)."""
    if not isinstance(args, tuple):
        return StageArguments(None)
    if len(args) == 8:
        # (stage_index, diagonal, vf, prod, ti, yi_partial, args, control)
        _, diagonal, vf, prod, ti, yi_partial, inner, control = args
        return StageArguments(
            "esdirk_f", diagonal, vf, prod, ti, yi_partial, inner, control
        )
    if len(args) == 7:
        # (stage_index, diagonal, vf_prod, ti, yi_partial, args, control)
        _, diagonal, vf_prod, ti, yi_partial, inner, control = args
        return StageArguments(
            "esdirk_k", diagonal, vf_prod, None, ti, yi_partial, inner, control
        )
    if len(args) == 5:
        # (vf_prod, t1, y0, args, control)
        vf_prod, t1, y0, inner, control = args
        return StageArguments(
            "implicit_euler_k", None, vf_prod, None, t1, None, inner, control, y0
        )
    return StageArguments(None)


# diffrax._integrate's checks of `SaveAt(ts=...)`: the only run-time checks (host
# callbacks under equinox's default EQX_ON_ERROR=raise) in jaxstring's solves.
SAVE_TIMES_CHECKS = (
    "saveat.ts must be increasing or decreasing.",
    "saveat.ts must lie between t0 and t1.",
)
# ... and of the step's direction (t1 - t0) * dt0 >= 0, a host callback where t0,
# t1 are traced (a scene's span is a leaf); jaxstring requires t1 > t0, dt0 > 0.
DT0_CHECK = "Must have (t1 - t0) * dt0 >= 0"


@contextlib.contextmanager
def save_times_checked():
    """While tracing a `diffeqsolve` whose save times jaxstring has checked, leave
    out diffrax's run-time check of them (and only that check: every other
    `error_if` stays as equinox makes it)."""
    original = eqxi.error_if

    def error_if(x, pred, msg, *args, **kwargs):
        if msg in SAVE_TIMES_CHECKS or str(msg).startswith(DT0_CHECK):
            return x
        return original(x, pred, msg, *args, **kwargs)

    eqxi.error_if = error_if
    try:
        yield
    finally:
        eqxi.error_if = original


# A jit cache context of its own for programs traced by `checks_as_nan`, so that
# no part traced before with host callbacks is reused (created on `import
# jaxstring`: see `jaxstring._config`).
_NAN_CHECKS = NAN_CHECKS_CONTEXT


@contextlib.contextmanager
def checks_as_nan():
    """While tracing a program that `jax.export` saves for worker processes, let a
    failed lineax linear solve return NaN instead of raising through a host
    callback (which `jax.export` cannot save): the program then reports the
    failure in its values (a Levenberg-Marquardt step on NaN residuals fails)."""
    import equinox._enum as eqx_enum

    original = eqx_enum.branched_error_if
    eqx_enum.branched_error_if = functools.partial(original, on_error="nan")
    try:
        with _NAN_CHECKS(True):
            yield
    finally:
        eqx_enum.branched_error_if = original
