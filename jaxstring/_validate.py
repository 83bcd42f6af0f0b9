"""Input checks that raise ``ValueError`` at construction, naming the argument, the
value it got and the valid range."""

import math

import jax
import numpy as np


def is_concrete(x) -> bool:
    """True when ``x`` holds values (not a tracer inside jit/grad/vmap)."""
    return not isinstance(x, jax.core.Tracer)


def show(value) -> str:
    """A short text for a value in a message: `-1.0`, `nan`, `[0.  0.2 0.1]`,
    `'1e-6'`, `None` (arrays print their values, not their type)."""
    if isinstance(value, (str, bytes, bool)) or value is None:
        return repr(value)
    try:
        a = np.asarray(value)
    except Exception:
        return repr(value)
    if a.dtype.kind not in "biuf":
        return repr(value)
    if a.ndim == 0:
        return repr(a.item())
    return np.array2string(a, threshold=8, edgeitems=3)


def _values(value):
    """`value` as a float array, or None when it is not numbers (a string, None,
    an object)."""
    if isinstance(value, (str, bytes)) or value is None:
        return None
    try:
        a = np.asarray(value)
    except Exception:
        return None
    if a.dtype.kind not in "biuf":
        return None
    return a.astype(float)


def _unit(unit: str) -> str:
    return f" {unit}" if unit else ""


def check_positive(name: str, value, unit: str = "") -> None:
    if not is_concrete(value):
        return
    v = _values(value)
    if v is None or not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise ValueError(
            f"`{name}` must be a finite number > 0{_unit(unit)}; got {show(value)}."
        )


def check_nonnegative(name: str, value, unit: str = "") -> None:
    if not is_concrete(value):
        return
    v = _values(value)
    if v is None or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError(
            f"`{name}` must be a finite number >= 0{_unit(unit)}; got {show(value)}."
        )


def check_finite(name: str, value) -> None:
    if not is_concrete(value):
        return
    v = _values(value)
    if v is None or not np.all(np.isfinite(v)):
        raise ValueError(f"`{name}` must be finite (no NaN or inf); got {show(value)}.")


def check_shape(name: str, value, shape: tuple, unit: str = "") -> None:
    """`value` has exactly `shape` (`()` for a scalar)."""
    got = np.shape(value)
    if tuple(got) != tuple(shape):
        what = "a scalar" if shape == () else f"of shape {tuple(shape)}"
        raise ValueError(
            f"`{name}` must be {what}{_unit(f'({unit})' if unit else '')}; got shape "
            f"{tuple(got)}: {show(value)}."
        )


def check_shape_finite(name: str, value, shape: tuple, unit: str = "") -> None:
    """`value` has exactly `shape` (`check_shape`) and is finite (`check_finite`)."""
    check_shape(name, value, shape, unit)
    check_finite(name, value)


def check_int(name: str, value, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"`{name}` must be an integer >= {minimum}; got {value!r}.")
    if value < minimum:
        raise ValueError(f"`{name}` must be an integer >= {minimum}; got {value!r}.")


def check_bool(name: str, value) -> None:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"`{name}` must be True or False; got {value!r}.")


def check_choice(name: str, value, choices) -> None:
    try:
        known = value in choices
    except TypeError:  # an unhashable value
        known = False
    if not known:
        close = [c for c in choices if isinstance(value, str) and value[:3] in str(c)]
        hint = f" Perhaps you meant {close[0]!r}?" if close else ""
        raise ValueError(
            f"unknown {name} {value!r}; valid choices: {', '.join(map(repr, choices))}."
            + hint
        )


def options_of(func, where: str, options: dict, skip: int = 1) -> dict:
    """The keyword options of `func` (its parameters after the first `skip`) with
    their defaults, replaced by `options`: for a function that takes the same
    options as `func` and hands them on. Raises ValueError naming an unknown
    option and the valid ones."""
    import inspect

    params = list(inspect.signature(func).parameters.values())[skip:]
    unknown = sorted(set(options) - {q.name for q in params})
    if unknown:
        raise ValueError(
            f"`{where}`: unknown option(s) {unknown}; valid: "
            f"{sorted(q.name for q in params)}."
        )
    defaults = {q.name: q.default for q in params if q.default is not q.empty}
    return {**defaults, **options}


def same_signature(func, like, skip: int = 1):
    """Give `func` (whose parameters are its own first ones, then `**options`)
    the signature of its own parameters followed by those of `like` after the
    first `skip`, so that help() and editors show the options `func` hands on to
    `like`; returns `func`."""
    import inspect

    own = [
        q
        for q in inspect.signature(func).parameters.values()
        if q.kind not in (q.VAR_POSITIONAL, q.VAR_KEYWORD)
    ]
    sig = inspect.signature(like)
    params = own + list(sig.parameters.values())[skip:]
    func.__signature__ = sig.replace(
        parameters=params, return_annotation=inspect.signature(func).return_annotation
    )
    return func


def check_angle(name: str, value) -> None:
    if not is_concrete(value):
        return
    v = _values(value)
    if v is None or v.shape != () or not math.isfinite(float(v)):
        raise ValueError(
            f"`{name}` must be a finite angle in radians; got {show(value)}."
        )


def check_times(name: str, ts, t0, t1) -> None:
    """`ts` is a non-empty 1-d array of finite, non-decreasing times inside
    `[t0, t1]` (s; the span's ends may be traced, then only the order is checked)."""
    if not is_concrete(ts):
        return
    v = _values(ts)
    if v is None or v.ndim != 1 or v.size == 0:
        raise ValueError(
            f"`{name}` must be a non-empty 1-d array of save times, s; got "
            f"{show(ts)} (shape {np.shape(ts)})."
        )
    if not np.all(np.isfinite(v)):
        raise ValueError(f"`{name}` must be finite times, s; got {show(ts)}.")
    if np.any(np.diff(v) < 0):
        i = int(np.argmax(np.diff(v) < 0))
        raise ValueError(
            f"`{name}` must be increasing times, s; got {show(ts)} "
            f"({name}[{i + 1}] = {float(v[i + 1])!r} < {name}[{i}] = {float(v[i])!r})."
        )
    if is_concrete(t0) and is_concrete(t1):
        lo, hi = float(t0), float(t1)
        if v[0] < lo or v[-1] > hi:
            raise ValueError(
                f"`{name}` must lie inside the scene's span [t0, t1] = [{lo:g}, "
                f"{hi:g}] s; got {show(ts)}."
            )


def check_fields(obj, positive=None, nonnegative=None) -> None:
    """`check_positive` / `check_nonnegative` on fields of `obj`, given as dicts
    field name -> unit."""
    for name, unit in (positive or {}).items():
        check_positive(name, getattr(obj, name), unit)
    for name, unit in (nonnegative or {}).items():
        check_nonnegative(name, getattr(obj, name), unit)
