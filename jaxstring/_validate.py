"""Input checks that raise ``ValueError`` at construction, naming the argument."""

import math

import jax
import numpy as np


def is_concrete(x) -> bool:
    """True when ``x`` holds values (not a tracer inside jit/grad/vmap)."""
    return not isinstance(x, jax.core.Tracer)


def _values(x):
    return np.asarray(x, dtype=float)


def check_positive(name: str, value, unit: str = "") -> None:
    if not is_concrete(value):
        return
    v = _values(value)
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise ValueError(
            f"`{name}` must be a finite number > 0{(' ' + unit) if unit else ''}; "
            f"got {value!r}."
        )


def check_nonnegative(name: str, value, unit: str = "") -> None:
    if not is_concrete(value):
        return
    v = _values(value)
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError(
            f"`{name}` must be a finite number >= 0{(' ' + unit) if unit else ''}; "
            f"got {value!r}."
        )


def check_finite(name: str, value) -> None:
    if not is_concrete(value):
        return
    if not np.all(np.isfinite(_values(value))):
        raise ValueError(f"`{name}` must be finite (no NaN or inf); got {value!r}.")


def check_int(name: str, value, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"`{name}` must be an integer >= {minimum}; got {value!r}.")
    if value < minimum:
        raise ValueError(f"`{name}` must be an integer >= {minimum}; got {value!r}.")


def check_choice(name: str, value, choices) -> None:
    if value not in choices:
        close = [c for c in choices if isinstance(value, str) and value[:3] in str(c)]
        hint = f" Perhaps you meant {close[0]!r}?" if close else ""
        raise ValueError(
            f"unknown {name} {value!r}; valid choices: {', '.join(map(repr, choices))}."
            + hint
        )


def check_angle(name: str, value) -> None:
    if not is_concrete(value):
        return
    if not math.isfinite(float(value)):
        raise ValueError(f"`{name}` must be a finite angle in radians; got {value!r}.")


def check_fields(obj, positive=None, nonnegative=None) -> None:
    """`check_positive` / `check_nonnegative` on fields of `obj`, given as dicts
    field name -> unit."""
    for name, unit in (positive or {}).items():
        check_positive(name, getattr(obj, name), unit)
    for name, unit in (nonnegative or {}).items():
        check_nonnegative(name, getattr(obj, name), unit)
