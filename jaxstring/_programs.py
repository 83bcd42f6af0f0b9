"""Saved solve programs: a later process skips tracing as well as compiling.

JAX's persistent compilation cache (`enable_compilation_cache`) saves the XLA
compilation of a solve, but every new process still traces the solve in Python,
which costs more than the run itself for a small scene (measured:
docs/performance.md, "Compile time").
With a program folder set, `simulate` exports the traced solve once
(`jax.export`) and saves its compilation beside it (XLA's executable, keyed as
well by this machine: its processor, XLA's version and flags); a later process
on the same machine loads the executable and runs it, neither tracing nor
lowering nor compiling. Where only the traced program fits (another machine, a
tiered program's other compilation) it is lowered and compiled from the saved
trace. The process that traces a program compiles the export's own lowering
(`jaxstring._executables.export_with_lowering`), not the exported program's call,
and a saved program's compilation is not written to JAX's compilation cache as
well (`jaxstring._executables.compile_and_save`'s ``jax_cache``).

A saved program is keyed by everything that decides the traced program: the
function's module and name (a function whose result depends on its arguments
alone, as jaxstring's are; a lambda is not saved), the repr of the arguments'
(scene's, solver settings') non-array parts, the structure,
shapes and dtypes of their arrays, the versions of jax, jaxlib, diffrax and
equinox, a digest of jaxstring's own source and one of the files that define any
other class among the arguments (a model or effect of the user's own). A scene
whose non-array parts have no stable repr (a Python function among them) or hold
a class without a source file (defined in a notebook) is not saved, nor a solve
with host callbacks (a progress meter; an equinox runtime check, which jaxstring's
default solves do not hold). A program that cannot be read back is traced again
and rewritten.

The program and the executable are stored with `pickle` (jax's own
serialisation of a program needs the optional `flatbuffers` package): the
exported function's private `_get_vjp` field, which cannot be pickled and is
only needed to differentiate the loaded program, is dropped, so loaded programs
serve forward solves only. The executables: `jaxstring._executables`.
"""

import dataclasses
import functools
import hashlib
import importlib.metadata
import os
import pathlib
import pickle
import sys

import equinox as eqx
import jax
import jax.tree_util as jtu

from . import _executables as executables
from ._config import (
    ensure_compilation_cache,
    program_folder,
    set_program_folder as set_program_folder,
)
from ._jit import (
    Tiers,
    compile_notice,
    cpu_compiler_options,
    cpu_jit,
    cpu_only,
    shown_name,
    split_arrays,
)


@functools.cache
def source_digest() -> str:
    """A digest of jaxstring's Python source."""
    h = hashlib.sha256()
    root = pathlib.Path(__file__).parent
    for f in sorted(root.rglob("*.py")):
        h.update(str(f.relative_to(root)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


@functools.cache
def _library_versions() -> str:
    """The versions of the libraries whose code a solve's program holds, read from
    their installed metadata (diffrax and optimistix are not imported by a process
    that only runs saved programs: `jaxstring._lazy`)."""
    return ",".join(
        importlib.metadata.version(name)
        for name in ("diffrax", "equinox", "optimistix", "lineax")
    )


def _classes(x, out=None) -> list:
    """The type of every object in `x` (dataclass fields, static ones included,
    lists, tuples and dict values)."""
    out = [] if out is None else out
    out.append(type(x))
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        for f in dataclasses.fields(x):
            _classes(getattr(x, f.name, None), out)
    elif isinstance(x, (list, tuple)):
        for y in x:
            _classes(y, out)
    elif isinstance(x, dict):
        for y in x.values():
            _classes(y, out)
    return out


def _types(classes) -> str:
    """The classes, module-qualified: two classes of one name, such as diffrax's
    Kvaerno5 and jaxstring's, print alike in a repr."""
    return ",".join(f"{c.__module__}.{c.__qualname__}" for c in classes)


# Packages whose code is keyed by their versions (or, jaxstring's, its digest).
_VERSIONED = {"jaxstring", "jax", "jaxlib", "diffrax", "equinox", "lineax",
              "optimistix", "optax", "numpy"}  # fmt: skip


def _outside_source(classes) -> str | None:
    """A digest of the source files that define `classes` (or functions) outside
    jaxstring, its dependencies and the standard library (a model or an effect of
    the user's own: a program saved before its code changed is not run after);
    None where one has no source file (a class defined in a notebook or at the
    prompt)."""
    h = hashlib.sha256()
    for name in sorted({c.__module__ for c in classes}):
        top = name.split(".")[0]
        if top in _VERSIONED or top in sys.stdlib_module_names:
            continue
        path = getattr(sys.modules.get(name), "__file__", None)
        try:
            h.update(name.encode() + b"\0" + pathlib.Path(path).read_bytes())
        except (TypeError, OSError):
            return None
    return h.hexdigest()


_KEYS = {}  # _memo(...) -> _key(...), in this process


def _memo(fn, parts, leaves):
    """What decides `_key` in this process, hashable (equal for equal static
    values of equal types: a float by its bits), or None where a static value
    is not hashable: the repr behind `_key` of a large scene takes milliseconds,
    longer than a small solve. `parts`: the `split_arrays` structure of the
    arguments; `leaves`: their arrays."""

    def exact(x):
        return (type(x), x.hex() if isinstance(x, float) else x)

    memo = (
        fn,
        parts.treedef,
        parts.is_array,
        tuple(exact(x) for x in parts.others),
        tuple((x.shape, x.dtype) for x in leaves),
    )
    try:
        hash(memo)
    except TypeError:
        return None
    return memo


def _key(fn, args):
    """(the saved-program key of `fn(*args)`, or None where it has no stable one;
    the array leaves of `args`, in the order of the program's parameters)."""
    leaves, parts = split_arrays(args)
    memo = _memo(fn, parts, leaves)
    if memo is not None and memo in _KEYS:
        return _KEYS[memo], leaves
    dynamic, static = eqx.partition(args, eqx.is_array)
    key = _full_key(fn, static, jtu.tree_structure(dynamic), leaves)
    if memo is not None:
        _KEYS[memo] = key
    return key, leaves


class _Named:
    """A module-level function of jaxstring's own in a key, by its name (its
    source is in the key's digest)."""

    def __init__(self, fn):
        self.name = f"{fn.__module__}.{fn.__qualname__}"

    def __repr__(self):
        return self.name


def _named(x):
    own = getattr(x, "__module__", None) or ""
    if (
        callable(x)
        and hasattr(x, "__qualname__")
        and (own == "jaxstring" or own.startswith("jaxstring."))
        and "<" not in x.__qualname__
    ):
        return _Named(x)
    return x


def _full_key(fn, static, treedef, leaves) -> str | None:
    name = f"{fn.__module__}.{fn.__qualname__}"
    if "<lambda>" in name:  # nameless: two lambdas would share one program
        return None
    # A function among the arguments is keyed by its name where it is one of
    # jaxstring's (a sweep's default output); another function has no stable key.
    static = jtu.tree_map(_named, static)
    text = repr(static)
    if " at 0x" in text:  # an object without a stable repr (a function)
        return None
    classes = _classes(static)
    outside = _outside_source(classes + [fn])
    if outside is None:
        return None
    h = hashlib.sha256()
    for part in (
        name,
        text,
        _types(classes),
        outside,
        str(treedef),
        str([(x.shape, str(x.dtype)) for x in leaves]),
        jax.__version__,
        jax.lib.__version__,
        _library_versions(),
        # (the compiler options too: jaxstring's, which XLA of this jaxlib knows)
        source_digest(),
    ):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:40]


def usable(args) -> bool:
    """Whether `args` may go through a saved program: a program folder is set and
    every array is a concrete CPU array."""
    if program_folder() is None:
        return False
    only_cpu = cpu_only()
    for x in jtu.tree_leaves(args):
        if isinstance(x, jax.core.Tracer):
            return False
        if (
            not only_cpu
            and isinstance(x, jax.Array)
            and any(d.platform != "cpu" for d in x.devices())
        ):
            return False
    return True


_LOADED = {}  # key -> the `_Program` of a saved program, in this process
_REFUSED = set()  # keys whose programs cannot be exported (host callbacks)
_COMPILED = {}  # key -> its loaded program, once called (compiled) in this process


class _Refused(Exception):
    """The program cannot be exported (host callbacks)."""


class _Program:
    """A saved program's compilations in this process: each (the optimised one;
    for a tiered program the quick one first, `jaxstring._jit.Tiers`) read from
    the program folder where a process on this machine saved it
    (`jaxstring._executables`), else lowered and compiled from the traced program
    (read or traced: `_exported`) and saved there for the next process."""

    def __init__(self, fn, key, static, treedef, tiered, name):
        self._fn, self._key, self._static, self._treedef = fn, key, static, treedef
        self._compilations = {}  # quick -> jax.stages.Compiled
        self._jits = {}  # quick -> `jax.jit` of the traced program
        self._read = {}  # quick -> whether its executable was read from the folder
        self._exported = None
        # A tiered program that an earlier process optimised starts optimised.
        self._tiers = (
            Tiers(name)
            if tiered and not executables.path(program_folder(), key, "full").exists()
            else None
        )

    def _export(self, leaves):
        """The traced program, read or traced and saved; the lowering it was
        traced with where it was traced now (else None)."""
        lowered = None
        if self._exported is None:
            self._exported, lowered = _exported(
                self._fn, self._key, self._static, self._treedef, leaves
            )
            if self._exported is None:
                raise _Refused
        return lowered

    def _jitted(self, quick, leaves):
        """The traced program (read, or traced and saved), compiled by `jax.jit`."""
        if quick not in self._jits:
            self._export(leaves)
            self._jits[quick] = jax.jit(
                executables.named_call(self._exported, self._key, _tier(quick)),
                compiler_options=cpu_compiler_options(quick),
            )
        return self._jits[quick]

    def _compiled(self, quick, leaves):
        """The executable: read, or compiled and saved."""
        compiled = self._compilations.get(quick)
        if compiled is None:
            folder, tier = program_folder(), _tier(quick)
            compiled = executables.read(folder, self._key, tier)
            self._read[quick] = compiled is not None
            if compiled is None:
                # Traced in this process: its own lowering is compiled (the saved
                # program's call would lower it again, around a copy of it).
                fresh = self._export(leaves) if quick not in self._jits else None
                lapack = executables.uses_lapack(self._exported)
                if fresh is not None:
                    options = cpu_compiler_options(quick)
                    lowered, compiler = fresh, lambda low: low.compile(options)
                else:
                    lowered = self._jitted(quick, leaves).lower(*leaves)
                    compiler = None
                # (saved here: not in JAX's compilation cache as well)
                compiled = executables.compile_and_save(
                    lowered, folder, self._key, tier, lapack, compiler, jax_cache=False
                )
            self._compilations[quick] = compiled
        return compiled

    def run(self, quick, *leaves):
        # An executable runs on the first CPU device (the default one); arrays
        # placed on another go through `jax.jit`, which follows them.
        if not _on_first_device(leaves):
            return self._jitted(quick, leaves)(*leaves)
        fresh = quick not in self._compilations
        compiled = self._compiled(quick, leaves)
        if not (fresh and self._read.get(quick)):
            return compiled(*leaves)
        try:  # the first run of a read executable, to its end
            return jax.block_until_ready(compiled(*leaves))
        except jax.errors.JaxRuntimeError:  # it does not run here: compile anew
            executables.path(program_folder(), self._key, _tier(quick)).unlink(
                missing_ok=True
            )
            del self._compilations[quick]
            return self._compiled(quick, leaves)(*leaves)

    def __call__(self, *leaves):
        if self._tiers is None:
            return self.run(False, *leaves)
        return self._tiers(
            (),
            functools.partial(self.run, True),
            functools.partial(self.run, False),
            *leaves,
        )


def _tier(quick: bool) -> str:
    return "quick" if quick else "full"


@functools.cache
def _first_cpu():
    return jax.devices("cpu")[0]


def _on_first_device(leaves) -> bool:
    first = _first_cpu()
    return all(not isinstance(x, jax.Array) or x.devices() == {first} for x in leaves)


def call(fn, *args, tiered: bool = False):
    """`fn(*args)` through a saved program, where `fn` returns a pytree of arrays
    in dicts, lists and tuples; None where no program can be saved (no stable key,
    or the traced function holds host callbacks): the caller then runs `fn` its
    usual way. `tiered`: compiled quickly first (`cpu_jit`'s ``tiered``)."""
    key, leaves = _key(fn, args)
    if key is None or key in _REFUSED:
        return None
    loaded = _LOADED.get(key)
    if loaded is not None and _COMPILED.get(key) is loaded:  # nothing to announce
        return loaded(*leaves)
    with compile_notice(shown_name(fn)):
        if key not in _LOADED:
            dynamic, static = eqx.partition(args, eqx.is_array)
            treedef = jtu.tree_structure(dynamic)
            _LOADED[key] = _Program(fn, key, static, treedef, tiered, shown_name(fn))
        try:
            out = _LOADED[key](*leaves)
        except _Refused:
            del _LOADED[key]
            return None
    _COMPILED[key] = _LOADED[key]
    return out


def call_or_jit(fn, jitted, *args, tiered: bool = False):
    """`fn(*args)` through a saved program where one can be saved (concrete CPU
    arrays, a program folder set), else `jitted(*args)` (`fn` compiled: traced
    arguments, to differentiate, or no program folder). `tiered`: as `call`'s,
    for a `jitted` made with `cpu_jit(fn, tiered=True)`."""
    out = call(fn, *args, tiered=tiered) if usable(args) else None
    return jitted(*args) if out is None else out


def saved_key(fn, args) -> str | None:
    """The key of the traced program of `fn(*args)` where it is in the program
    folder (a process that reads it traces nothing), else None."""
    folder = program_folder()
    if folder is None:
        return None
    key = _key(fn, args)[0]
    if key is None or not (pathlib.Path(folder) / f"{key}.program").exists():
        return None
    return key


def saved_export(fn, static, treedef, leaves):
    """`fn` traced and exported for arrays of the shapes and dtypes of `leaves`
    (the arrays of its arguments; `static` and `treedef` the rest): read from the
    program folder where an earlier process saved it, else traced and saved there.
    None where no program folder is set, `fn` has no stable key or it cannot be
    exported (host callbacks)."""
    ensure_compilation_cache()
    if program_folder() is None:
        return None
    args = eqx.combine(jtu.tree_unflatten(treedef, leaves), static)
    return _exported(fn, _key(fn, args)[0], static, treedef, leaves)[0]


def _exported(fn, key, static, treedef, leaves):
    """(the program of `key`, read or traced and saved, or None where there is no
    key or it cannot be exported (then remembered); the lowering it was traced
    with, where it was traced now, else None): `_load_or_export`."""
    if key is None or key in _REFUSED:
        return None, None
    exported, lowered = _load_or_export(fn, key, static, treedef, leaves)
    if exported is None:
        _REFUSED.add(key)
    return exported, lowered


def _load_or_export(fn, key, static, treedef, leaves):
    path = pathlib.Path(program_folder()) / f"{key}.program"
    if path.exists():
        try:
            return pickle.loads(path.read_bytes()), None
        except Exception:  # unreadable or written by another version: trace again
            pass

    def flat(*xs):
        return fn(*eqx.combine(jtu.tree_unflatten(treedef, xs), static))

    # Named after its key: the name is part of its key in JAX's compilation cache
    # (`jaxstring._executables`).
    flat.__name__ = flat.__qualname__ = f"saved_{key[:16]}"
    avals = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves]
    try:
        jitted = jax.jit(flat, compiler_options=cpu_compiler_options())
        exported, lowered = executables.export_with_lowering(jitted, avals)
    except (NotImplementedError, ValueError):  # host callbacks cannot be exported
        return None, None
    try:
        data = pickle.dumps(dataclasses.replace(exported, _get_vjp=None))
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except (OSError, pickle.PicklingError, TypeError, AttributeError):
        pass  # not saved: this process still runs the program it traced
    return exported, lowered


def eager_jit(fun=None, *, tiered: bool = False):
    """`fun` compiled as one program (`cpu_jit`) when called on concrete arrays,
    and traced inline when called inside another trace.

    For functions that users and scene builders call outside any trace (the
    observables of a state, an initial state): run eagerly, each of their many
    small operations would be dispatched, and compiled, one by one (a fresh
    process compiles every distinct operation and shape once). Python numbers
    among the arguments are structure (a new value compiles anew): pass arrays.
    Called with positional arguments and a program folder set, the traced
    program is saved there for later processes, as `simulate`'s solves are.
    `tiered`: compiled quickly first (`cpu_jit`'s ``tiered``), for a scene
    builder's programs, run once per scene. Usable as ``@eager_jit`` or
    ``@eager_jit(tiered=True)``."""
    if fun is None:
        return functools.partial(eager_jit, tiered=tiered)
    jitted = cpu_jit(fun, tiered=tiered)

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        leaves = jtu.tree_leaves((args, kwargs))
        if any(isinstance(x, jax.core.Tracer) for x in leaves):
            return fun(*args, **kwargs)
        # A saved program (this module): a later process skips the trace.
        ensure_compilation_cache()
        if not kwargs and usable(args):
            out = call(fun, *args, tiered=tiered)
            if out is not None:
                return out
        return jitted(*args, **kwargs)

    return wrapper
