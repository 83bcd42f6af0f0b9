"""Naming the parameters of a scene: the leaves that `fit`, `least_squares` and
`sweep` select by name, type-qualified name, path or callable."""

from typing import Any

import equinox as eqx
import jax.tree_util as jtu


def _key_name(key) -> str | None:
    return key.name if isinstance(key, jtu.GetAttrKey) else None


def _follow(obj, path):
    for key in path:
        if isinstance(key, jtu.GetAttrKey):
            obj = getattr(obj, key.name)
        elif isinstance(key, jtu.SequenceKey):
            obj = obj[key.idx]
        elif isinstance(key, jtu.DictKey):
            obj = obj[key.key]
        else:  # pragma: no cover - scenes hold only modules, tuples and dicts
            raise ValueError(f"cannot follow path element {key!r}")
    return obj


class _Getter(eqx.Module):
    """`scene -> leaf` along a fixed path (hashable, so usable as a static arg)."""

    path: tuple = eqx.field(static=True)
    label: str = eqx.field(static=True)

    def __call__(self, scene):
        return _follow(scene, self.path)


def parameter_names(scene) -> list[str]:
    """Paths of all array leaves of `scene` that `fit` and `sweep` can select,
    e.g. `"model.EA"`, `"effects[1].alpha"`."""
    leaves = jtu.tree_flatten_with_path(scene)[0]
    return [jtu.keystr(p)[1:] for p, x in leaves if eqx.is_inexact_array(x)]


def resolve(scene, param) -> _Getter:
    """Return a getter `scene -> leaf` for one parameter specification.

    `param` is a callable (`lambda s: s.effects[1].alpha`), a field name (`"alpha"`,
    `"EA"`: must be unique in the scene), a name qualified by the type that holds it
    (`"KelvinVoigt.alpha"`, `"Environment.g"`) or a path (`"model.EA"`,
    `"effects[1].alpha"`). Raises `ValueError` when it names nothing or several leaves.
    """
    leaves = jtu.tree_flatten_with_path(scene)[0]
    entries = []
    for path, leaf in leaves:
        if not eqx.is_inexact_array(leaf):
            continue
        owner = _follow(scene, path[:-1])
        entries.append((path, jtu.keystr(path)[1:], _key_name(path[-1]), owner, leaf))
    if callable(param) and not isinstance(param, str):
        target = param(scene)
        hits = [e for e in entries if e[4] is target]
        if len(hits) != 1:
            raise ValueError(
                "`params`: a callable must return one floating-point array leaf of the "
                f"scene (like `lambda s: s.model.EA`); valid leaves: "
                f"{', '.join(parameter_names(scene))}."
            )
        return _Getter(path=hits[0][0], label=hits[0][2] or hits[0][1])
    if not isinstance(param, str):
        raise ValueError(f"`params` entries must be names or callables; got {param!r}.")
    hits = [e for e in entries if e[1] == param]
    if not hits:
        hits = [e for e in entries if e[2] == param]
    if not hits and "." in param:
        cls, _, field = param.rpartition(".")
        hits = [e for e in entries if e[2] == field and type(e[3]).__name__ == cls]
    if len(hits) == 1:
        return _Getter(path=hits[0][0], label=param)
    names = ", ".join(repr(n) for n in parameter_names(scene))
    if not hits:
        raise ValueError(f"unknown parameter {param!r}; the scene has: {names}.")
    raise ValueError(
        f"parameter {param!r} is ambiguous ({', '.join(e[1] for e in hits)}); "
        f"name it by path or type, e.g. {hits[0][1]!r} or "
        f"'{type(hits[0][3]).__name__}.{param}'."
    )


def filter_spec(scene, getters) -> Any:
    """Boolean tree like `scene`: True at the chosen leaves (for `eqx.partition`)."""
    spec = jtu.tree_map(lambda _: False, scene)
    return eqx.tree_at(
        lambda s: [g(s) for g in getters], spec, replace=[True] * len(getters)
    )
