"""`cpu_jit`: jaxstring's compiled solves, with XLA:CPU options chosen for them.

Two per-compilation options (the user's own JAX code keeps XLA's defaults), on CPU:

- ``xla_cpu_experimental_ynn_fusion_type = ""``: no YNNPACK fusions. jaxlib 0.10
  hands some fusions to YNNPACK by default. In a string solve these are small
  reductions over 2-4 components with a batch in front (the colour-batched JVPs of
  the banded Jacobian; the members of a vmapped sweep), which YNNPACK runs several
  times slower than XLA's own loop fusions (docs/numerics.md, "BLAS and XLA notes";
  `experiments/results/ynn_fusion.md`).
- ``xla_cpu_use_fusion_emitters = False``: XLA's elemental emitter in place of its
  MLIR fusion emitters. A solve is many small fusions, and the MLIR emitters' fixed
  cost per fusion made most of its compilation time; the run time is the same
  (docs/numerics.md; `experiments/results/compile_options.md`).

`simulate`, `fit`, `sweep` and the statics compile with them
(`cpu_compiler_options`: those of them that this jaxlib's XLA knows, checked once
per process on a one-operation program; XLA refuses an unknown option).
"""

import contextlib
import functools
import sys
import threading
import types

import equinox as eqx
import jax
import jax.tree_util as jtu
import numpy as np

from ._config import ensure_compilation_cache


CPU_COMPILER_OPTIONS = {
    "xla_cpu_experimental_ynn_fusion_type": "",
    "xla_cpu_use_fusion_emitters": False,
}


@functools.cache
def cpu_compiler_options() -> dict:
    """`CPU_COMPILER_OPTIONS` less any option this jaxlib's XLA does not know (a
    newer jaxlib may drop one): each is tried once per process, compiling a
    one-operation program on the CPU."""
    cpu = jax.local_devices(backend="cpu")[0]
    lowered = jax.jit(lambda x: x + 1.0).lower(
        jax.device_put(np.zeros((), np.float64), cpu)
    )
    try:
        lowered.compile(dict(CPU_COMPILER_OPTIONS))
        return dict(CPU_COMPILER_OPTIONS)
    except Exception:  # noqa: BLE001  (one of them unknown: try each)
        pass
    known = {}
    for name, value in CPU_COMPILER_OPTIONS.items():
        try:
            lowered.compile({name: value})
        except Exception:  # noqa: BLE001  (XLA: "No such compile option")
            continue
        known[name] = value
    return known


NOTICE_AFTER_S = 3.0
"""A compiled call still preparing its program after this long says so on stderr."""


@contextlib.contextmanager
def compile_notice(name: str):
    """Print one line on stderr if the block (a jitted call: tracing, compiling and
    dispatching) takes more than `NOTICE_AFTER_S`, so that a first call that
    compiles a large solve is not taken for a hang."""
    timer = threading.Timer(
        NOTICE_AFTER_S,
        lambda: print(
            f"jaxstring: compiling {name} for this structure (once; later calls "
            "with new parameter values reuse it) ...",
            file=sys.stderr,
            flush=True,
        ),
    )
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()


class _SameCode:
    """A Python function among a compiled call's static arguments, equal to any
    function with the same code object, globals, defaults and captured objects
    (compared by identity). A lambda written in a call, such as the summary of a
    sweep or the loss of a fit, is a new function object at every call; keyed by
    identity it would compile the program again each time, keyed by its code it
    reuses it."""

    __slots__ = ("fn", "_key")

    def __init__(self, fn):
        self.fn = fn
        cells = tuple(_contents(c) for c in fn.__closure__ or ())
        kwdefaults = tuple(sorted((fn.__kwdefaults__ or {}).items()))
        self._key = (
            fn.__code__,
            fn.__globals__,
            fn.__defaults__ or (),
            kwdefaults,
            cells,
        )

    def __eq__(self, other):
        if not isinstance(other, _SameCode):
            return NotImplemented
        return len(self._key) == len(other._key) and all(
            _same(a, b) for a, b in zip(self._key, other._key)
        )

    def __hash__(self):
        return hash(self._key[0])


def _contents(cell):
    """What a closure cell holds (the cell itself while it is still empty)."""
    try:
        return cell.cell_contents
    except ValueError:
        return cell


def _same(a, b):
    """Identity, element by element for tuples (defaults, captured objects)."""
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a is b


def _code_keyed(static):
    return jtu.tree_map(
        lambda x: _SameCode(x) if isinstance(x, types.FunctionType) else x, static
    )


def _unwrapped(static):
    return jtu.tree_map(lambda x: x.fn if isinstance(x, _SameCode) else x, static)


def shown_name(fun) -> str:
    """How a compile notice names `fun`: `_solve_fields` and `_solve_values` (a
    solve's program variants) are "solve"."""
    name = getattr(fun, "__name__", "a solve").lstrip("_")
    return name.removesuffix("_fields").removesuffix("_values")


def cpu_jit(fun):
    """Like `eqx.filter_jit` (arrays traced, everything else static and hashable),
    compiled with `CPU_COMPILER_OPTIONS` when every array argument is on the CPU.
    Python functions among the static arguments are keyed by their code
    (`_SameCode`), not by identity."""

    def call(dynamic, static):
        args, items = eqx.combine(dynamic, _unwrapped(static))
        return fun(*args, **dict(items))

    def split(args, kwargs):
        # keyword arguments as sorted (name, value) pairs: hashable when static
        dynamic, static = eqx.partition(
            (args, tuple(sorted(kwargs.items()))), eqx.is_array
        )
        return dynamic, _code_keyed(static)

    jitted = {False: jax.jit(call, static_argnums=1)}

    def cpu_jitted():
        # made at the first call, not at import: the options are checked then
        if True not in jitted:
            jitted[True] = jax.jit(
                call, static_argnums=1, compiler_options=cpu_compiler_options()
            )
        return jitted[True]

    name = shown_name(fun)

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        ensure_compilation_cache()
        dynamic, static = split(args, kwargs)
        leaves = [x for x in jtu.tree_leaves(dynamic) if isinstance(x, jax.Array)]
        # Inside another trace (a caller's jit, vmap or grad) the outer compilation
        # decides the options, and JAX refuses them on a nested jit.
        traced = any(isinstance(x, jax.core.Tracer) for x in leaves)
        on_cpu = not traced and all(
            d.platform == "cpu" for x in leaves for d in x.devices()
        )
        jit = cpu_jitted() if on_cpu else jitted[False]
        if traced:
            return jit(dynamic, static)
        with compile_notice(name):
            return jit(dynamic, static)

    # The CPU compilation, for inspection: `fn.lower_cpu(*args).compile().as_text()`.
    wrapper.lower_cpu = lambda *args, **kwargs: cpu_jitted().lower(*split(args, kwargs))
    # Compiled variants so far (tests check that new parameter values reuse one).
    wrapper.cache_size = lambda: sum(j._cache_size() for j in jitted.values())
    return wrapper


def traced_once(step):
    """A diffrax solver's `step` method as a nested jitted function, inlined where
    it is called, so that JAX keeps its trace.

    diffrax traces the body of its step loop up to three times per solve (twice
    under `eval_shape`, to learn which parts of the loop state stay static, then in
    the loop itself). A jitted function called again with arguments of the same
    structure is not traced again, so the step (stages, Newton iterations,
    Jacobians) is traced once. The compiled program computes the same: the
    inlined trace is the one that would have been made."""
    return eqx.filter_jit(step, inline=True)
