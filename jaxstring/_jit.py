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

Programs that a user typically runs once per structure (a static equilibrium, a
scene builder's start geometry and initial state, a mooring's coupled stiffness:
`cpu_jit(fun, tiered=True)`, `eager_jit(fun, tiered=True)`) compile first with
``xla_backend_optimization_level = 0`` as well (`QUICK_OPTIONS`): LLVM's
optimisation is about half of such a program's compilation, and the program runs
for milliseconds. Where one of them is called again and again (a loop over
designs), its quickly compiled runs are timed, and once they have taken
`PROMOTE_AFTER_S` in the process, or it has come `PROMOTE_AFTER_CALLS` times, it
is compiled again with the optimisation (`Tiers`). Solves, fits and sweeps are
compiled fully from the start: at level 0 they run 4-6 times slower
(docs/performance.md, "Run-once programs compiled quickly";
`experiments/results/compile_options_run_once.md`).
"""

import contextlib
import functools
import sys
import threading
import time
import types

import jax
import jax.tree_util as jtu
import numpy as np

from ._config import ensure_compilation_cache


CPU_COMPILER_OPTIONS = {
    "xla_cpu_experimental_ynn_fusion_type": "",
    "xla_cpu_use_fusion_emitters": False,
}


QUICK_OPTIONS = {"xla_backend_optimization_level": 0}
"""Added to `CPU_COMPILER_OPTIONS` for the first compilation of a tiered program."""

PROMOTE_AFTER_S = 2.0
"""A tiered program is compiled again with full optimisation once its quickly
compiled runs have taken this long in the process (about what that compilation
costs a mid-sized program; the runs are then several times faster)..."""

PROMOTE_AFTER_CALLS = 16
"""... or once it has been called this many times (a loop of calls: however
short each run, the optimised program serves the rest of the loop)."""


def cpu_compiler_options(quick: bool = False) -> dict:
    """`CPU_COMPILER_OPTIONS` (with `QUICK_OPTIONS` where `quick`) less any option
    this jaxlib's XLA does not know (a newer jaxlib may drop one): each is tried
    once per process, compiling a one-operation program on the CPU."""
    return dict(_known_options(bool(quick)))


@functools.cache
def _known_options(quick: bool) -> dict:
    wanted = dict(CPU_COMPILER_OPTIONS) | (QUICK_OPTIONS if quick else {})
    cpu = jax.local_devices(backend="cpu")[0]
    lowered = jax.jit(lambda x: x + 1.0).lower(
        jax.device_put(np.zeros((), np.float64), cpu)
    )
    try:
        lowered.compile(dict(wanted))
        return wanted
    except Exception:  # noqa: BLE001  (one of them unknown: try each)
        pass
    known = {}
    for name, value in wanted.items():
        try:
            lowered.compile({name: value})
        except Exception:  # noqa: BLE001  (XLA: "No such compile option")
            continue
        known[name] = value
    return known


NOTICE_AFTER_S = 3.0
"""A compiled call still preparing its program after this long says so on stderr."""


class _Notices:
    """The compile notices of the blocks running now, printed by one daemon
    thread when a block's time is up. A block only enters and leaves a dict (a
    `threading.Timer` per block would start a thread at every call, a measurable
    part of a small solve's call). The thread sleeps until the earliest deadline
    (at most `NOTICE_AFTER_S`, so that a block entered meanwhile is seen in time;
    woken early only for a deadline before its wake-up) and ends after a quiet
    interval (the next block starts it again)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._due = {}  # token -> (monotonic deadline, name)
        self._thread = None
        self._wake = threading.Event()
        self._wake_at = 0.0

    def enter(self, name: str):
        token = object()
        deadline = time.monotonic() + NOTICE_AFTER_S
        with self._lock:
            self._due[token] = (deadline, name)
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._watch, name="jaxstring-compile-notice", daemon=True
                )
                self._thread.start()
            elif deadline < self._wake_at:
                self._wake.set()
        return token

    def leave(self, token) -> None:
        self._due.pop(token, None)

    def _watch(self):
        quiet = 0
        while True:
            with self._lock:
                now = time.monotonic()
                due = [t for t, (d, _) in self._due.items() if d <= now]
                names = [self._due.pop(t)[1] for t in due]
                quiet = 0 if self._due or names else quiet + 1
                if quiet > 1:  # nothing ran for a while: start again when needed
                    self._thread = None
                    return
                self._wake_at = min(
                    (d for d, _ in self._due.values()), default=now + NOTICE_AFTER_S
                )
                self._wake.clear()
            for name in names:
                print(
                    f"jaxstring: compiling {name} for this structure (once; later "
                    "calls with new parameter values reuse it) ...",
                    file=sys.stderr,
                    flush=True,
                )
            self._wake.wait(max(self._wake_at - now, 0.0) + 1e-3)


_NOTICES = _Notices()


@contextlib.contextmanager
def compile_notice(name: str):
    """Print one line on stderr if the block (a jitted call: tracing, compiling and
    dispatching) takes more than `NOTICE_AFTER_S`, so that a first call that
    compiles a large solve is not taken for a hang."""
    token = _NOTICES.enter(name)
    try:
        yield
    finally:
        _NOTICES.leave(token)


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


class _Static:
    """The static part of a compiled call's arguments: their tree structure, which
    leaves are arrays, and the other leaves (a function as `_SameCode`). Equal
    and hashed as a structure and a tuple: cheap next to hashing a scene's
    modules field by field at every call."""

    __slots__ = ("treedef", "is_array", "others", "_hash")

    def __init__(self, treedef, is_array, others):
        self.treedef, self.is_array, self.others = treedef, is_array, others
        self._hash = None

    def __eq__(self, other):
        return (
            isinstance(other, _Static)
            and self.treedef == other.treedef
            and self.is_array == other.is_array
            and self.others == other.others
        )

    def __hash__(self):
        # TypeError for an unhashable static value, as for any static argument
        if self._hash is None:
            self._hash = hash((self.treedef, self.is_array, self.others))
        return self._hash

    def tree(self, arrays):
        """The arguments again, from `arrays` (the dynamic leaves)."""
        arrays, others = iter(arrays), iter(self.others)
        leaves = [
            next(arrays) if a else _unwrapped(next(others)) for a in self.is_array
        ]
        return jtu.tree_unflatten(self.treedef, leaves)


def split_arrays(tree):
    """(the array leaves of `tree`, a `_Static` of the rest): what `eqx.partition`
    with `eqx.is_array` separates, in one flattening."""
    # (equinox imported here: a sweep's worker process imports this module for
    # its compiler options and needs nothing of equinox)
    import equinox as eqx

    leaves, treedef = jtu.tree_flatten(tree)
    is_array = tuple(eqx.is_array(x) for x in leaves)
    arrays = [x for x, a in zip(leaves, is_array) if a]
    others = tuple(
        _SameCode(x) if isinstance(x, types.FunctionType) else x
        for x, a in zip(leaves, is_array)
        if not a
    )
    return arrays, _Static(treedef, is_array, others)


def _unwrapped(x):
    return x.fn if isinstance(x, _SameCode) else x


def shown_name(fun) -> str:
    """How a compile notice names `fun`: `_solve_fields` and `_solve_values` (a
    solve's program variants) are "solve"."""
    name = getattr(fun, "__name__", "a solve").lstrip("_")
    return name.removesuffix("_fields").removesuffix("_values")


@functools.cache
def cpu_only() -> bool:
    """Whether JAX has CPU devices only (then every array is on one)."""
    return all(d.platform == "cpu" for d in jax.devices())


class Tiers:
    """Which compilation serves each argument signature of a tiered program.

    A signature's first call goes to the quickly compiled program (`QUICK_OPTIONS`:
    its compilation is in that call), and so do the next ones, each timed to its
    result, until they have run for `PROMOTE_AFTER_S` in all or the signature has
    come `PROMOTE_AFTER_CALLS` times; from then on its calls go to the fully
    optimised program, compiled at the first of them (under a compile notice
    naming `name`, unless None: the caller's own notice covers the call)."""

    _PROMOTING = "promoting"  # the next call compiles the optimised program

    def __init__(self, name: str | None = None):
        self._name = name
        self._seen = {}  # signature -> (calls, seconds run quickly); None: promoted

    def __call__(self, signature, quick, full, *args):
        seen = self._seen.get(signature, (0, 0.0))
        if seen is None:
            return full(*args)
        if seen is self._PROMOTING:
            if self._name is None:
                out = full(*args)
            else:
                with compile_notice(self._name):
                    out = full(*args)
            self._seen[signature] = None
            return out
        calls, spent = seen
        if calls == 0:  # the first call: its time is mostly the compilation
            out = quick(*args)
        else:
            start = time.perf_counter()
            out = jax.block_until_ready(quick(*args))
            spent += time.perf_counter() - start
        calls += 1
        promote = calls > 1 and (
            spent >= PROMOTE_AFTER_S or calls >= PROMOTE_AFTER_CALLS
        )
        self._seen[signature] = self._PROMOTING if promote else (calls, spent)
        return out

    def promoted(self, signature) -> bool:
        """Whether the signature's calls go to the optimised program now."""
        return signature in self._seen and not isinstance(self._seen[signature], tuple)


def cpu_jit(fun=None, *, tiered: bool = False):
    """Like `eqx.filter_jit` (arrays traced, everything else static and hashable),
    compiled with `CPU_COMPILER_OPTIONS` when every array argument is on the CPU.
    Python functions among the static arguments are keyed by their code
    (`_SameCode`), not by identity.

    `tiered`: for a program typically run once per structure; on the CPU it is
    compiled quickly first and optimised once its runs add up (`Tiers`). Usable
    as ``@cpu_jit`` or ``@cpu_jit(tiered=True)``."""
    if fun is None:
        return functools.partial(cpu_jit, tiered=tiered)

    def call(dynamic, static):
        args, items = static.tree(dynamic)
        return fun(*args, **dict(items))

    def split(args, kwargs):
        # keyword arguments as sorted (name, value) pairs
        return split_arrays((args, tuple(sorted(kwargs.items()))))

    jitted = {None: jax.jit(call, static_argnums=1)}

    def cpu_jitted(quick=False):
        # made at the first call, not at import: the options are checked then
        if quick not in jitted:
            jitted[quick] = jax.jit(
                call, static_argnums=1, compiler_options=cpu_compiler_options(quick)
            )
        return jitted[quick]

    name = shown_name(fun)
    tiers = Tiers()  # (every CPU call runs under the wrapper's compile notice)

    def cpu_call(dynamic, static):
        if not tiered:
            return cpu_jitted()(dynamic, static)
        signature = (static, tuple((x.shape, x.dtype) for x in dynamic))
        return tiers(signature, cpu_jitted(True), cpu_jitted(), dynamic, static)

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        ensure_compilation_cache()
        dynamic, static = split(args, kwargs)
        # Inside another trace (a caller's jit, vmap or grad) the outer compilation
        # decides the options, and JAX refuses them on a nested jit.
        traced = any(isinstance(x, jax.core.Tracer) for x in dynamic)
        on_cpu = not traced and (
            cpu_only()
            or all(
                d.platform == "cpu"
                for x in dynamic
                if isinstance(x, jax.Array)
                for d in x.devices()
            )
        )
        if traced:
            return jitted[None](dynamic, static)
        with compile_notice(name):
            if on_cpu:
                return cpu_call(dynamic, static)
            return jitted[None](dynamic, static)

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
    import equinox as eqx

    return eqx.filter_jit(step, inline=True)
