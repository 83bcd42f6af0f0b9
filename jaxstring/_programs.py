"""Saved solve programs: a later process skips tracing as well as compiling.

JAX's persistent compilation cache (`enable_compilation_cache`) saves the XLA
compilation of a solve, but every new process still traces the solve in Python,
which costs more than the run itself for a small scene (measured:
docs/performance.md, "Compile time").
With a program folder set, `simulate` exports the traced solve once
(`jax.export`) and later processes load it and run it without tracing; the
program's compilation comes from the compilation cache as before.

A saved program is keyed by everything that decides the traced program: the
function's module and name (a function whose result depends on its arguments
alone, as jaxstring's are; a lambda is not saved), the repr of the arguments'
(scene's, solver settings') non-array parts, the structure,
shapes and dtypes of their arrays, the versions of jax, jaxlib, diffrax and
equinox, and a digest of jaxstring's own source. A scene whose non-array parts
have no stable repr (a Python function among them) is not saved, nor a solve
with host callbacks (a progress meter; an equinox runtime check, which jaxstring's
default solves do not hold). A program that cannot be read back is traced again
and rewritten.

The program is stored with `pickle` (jax's own serialisation needs the optional
`flatbuffers` package): the exported function's private `_get_vjp` field, which
cannot be pickled and is only needed to differentiate the loaded program, is
dropped, so loaded programs serve forward solves only.
"""

import dataclasses
import functools
import hashlib
import os
import pathlib
import pickle

import diffrax as dfx
import equinox as eqx
import jax
import jax.tree_util as jtu

from ._config import program_folder, set_program_folder as set_program_folder
from ._jit import compile_notice, cpu_compiler_options


@functools.cache
def source_digest() -> str:
    """A digest of jaxstring's Python source."""
    h = hashlib.sha256()
    root = pathlib.Path(__file__).parent
    for f in sorted(root.rglob("*.py")):
        h.update(str(f.relative_to(root)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def _types(x, out=None) -> str:
    """The module-qualified type of every object in `x` (dataclass fields, static
    ones included, lists, tuples and dict values): two classes of one name, such
    as diffrax's Kvaerno5 and jaxstring's, print alike in a repr."""
    out = [] if out is None else out
    out.append(f"{type(x).__module__}.{type(x).__qualname__}")
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        for f in dataclasses.fields(x):
            _types(getattr(x, f.name, None), out)
    elif isinstance(x, (list, tuple)):
        for y in x:
            _types(y, out)
    elif isinstance(x, dict):
        for y in x.values():
            _types(y, out)
    return ",".join(out)


_KEYS = {}  # _memo(...) -> _key(...), in this process


def _memo(fn, static, treedef, leaves):
    """What decides `_key` in this process, hashable (equal for equal static
    values of equal types: a float by its bits), or None where a static value
    is not hashable: the repr behind `_key` of a large scene takes milliseconds,
    longer than a small solve."""

    def exact(x):
        return (type(x), x.hex() if isinstance(x, float) else x)

    static_leaves, static_def = jtu.tree_flatten(static)
    memo = (
        fn,
        static_def,
        tuple(exact(x) for x in static_leaves),
        treedef,
        tuple((x.shape, str(x.dtype)) for x in leaves),
    )
    try:
        hash(memo)
    except TypeError:
        return None
    return memo


def _key(fn, static, treedef, leaves) -> str | None:
    memo = _memo(fn, static, treedef, leaves)
    if memo is not None and memo in _KEYS:
        return _KEYS[memo]
    key = _full_key(fn, static, treedef, leaves)
    if memo is not None:
        _KEYS[memo] = key
    return key


def _full_key(fn, static, treedef, leaves) -> str | None:
    name = f"{fn.__module__}.{fn.__qualname__}"
    if "<lambda>" in name:  # nameless: two lambdas would share one program
        return None
    text = repr(static)
    if " at 0x" in text:  # an object without a stable repr (a function)
        return None
    h = hashlib.sha256()
    for part in (
        name,
        text,
        _types(static),
        str(treedef),
        str([(x.shape, str(x.dtype)) for x in leaves]),
        jax.__version__,
        jax.lib.__version__,
        dfx.__version__,
        eqx.__version__,
        source_digest(),
        repr(cpu_compiler_options()),
    ):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:40]


def usable(args) -> bool:
    """Whether `args` may go through a saved program: a program folder is set and
    every array is a concrete CPU array."""
    if program_folder() is None:
        return False
    for x in jtu.tree_leaves(args):
        if isinstance(x, jax.core.Tracer):
            return False
        if isinstance(x, jax.Array) and any(d.platform != "cpu" for d in x.devices()):
            return False
    return True


_LOADED = {}  # key -> the compiled call of a saved program, in this process
_REFUSED = set()  # keys whose programs cannot be exported (host callbacks)


def call(fn, *args):
    """`fn(*args)` through a saved program, where `fn` returns a pytree of arrays
    in dicts, lists and tuples; None where no program can be saved (no stable key,
    or the traced function holds host callbacks): the caller then runs `fn` its
    usual way."""
    dynamic, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jtu.tree_flatten(dynamic)
    key = _key(fn, static, treedef, leaves)
    if key is None or key in _REFUSED:
        return None
    with compile_notice(fn.__name__.lstrip("_").removesuffix("_fields")):
        if key not in _LOADED:
            exported = _load_or_export(fn, key, static, treedef, leaves)
            if exported is None:
                _REFUSED.add(key)
                return None
            _LOADED[key] = jax.jit(
                exported.call, compiler_options=cpu_compiler_options()
            )
        return _LOADED[key](*leaves)


def call_or_jit(fn, jitted, *args):
    """`fn(*args)` through a saved program where one can be saved (concrete CPU
    arrays, a program folder set), else `jitted(*args)` (`fn` compiled: traced
    arguments, to differentiate, or no program folder)."""
    out = call(fn, *args) if usable(args) else None
    return jitted(*args) if out is None else out


def _load_or_export(fn, key, static, treedef, leaves):
    path = pathlib.Path(program_folder()) / f"{key}.program"
    if path.exists():
        try:
            return pickle.loads(path.read_bytes())
        except Exception:  # unreadable or written by another version: trace again
            pass

    def flat(*xs):
        return fn(*eqx.combine(jtu.tree_unflatten(treedef, xs), static))

    avals = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves]
    try:
        jitted = jax.jit(flat, compiler_options=cpu_compiler_options())
        exported = jax.export.export(jitted, platforms=("cpu",))(*avals)
    except (NotImplementedError, ValueError):  # host callbacks cannot be exported
        return None
    try:
        data = pickle.dumps(dataclasses.replace(exported, _get_vjp=None))
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except (OSError, pickle.PicklingError, TypeError, AttributeError):
        pass  # not saved: this process still runs the program it traced
    return exported
