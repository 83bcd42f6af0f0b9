"""The package's shape: an import graph without cycles, systems that use only each
other's public names, and every public name importable flat without collision."""

import ast
import pathlib

import jaxstring as js


ROOT = pathlib.Path(js.__file__).parent
SYSTEMS = ("chain", "pendulum", "tether", "tandem", "lines")


def _module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules():
    return {_module_name(p): p for p in ROOT.rglob("*.py")}


def _imports(name: str, path: pathlib.Path):
    """(imported module, imported names) of every import statement in the module,
    at any depth (function-level imports included), resolved to full names."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, ()
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            yield target, tuple(a.name for a in node.names)


def _graph():
    mods = _modules()
    graph = {m: set() for m in mods}
    for name, path in mods.items():
        for target, names in _imports(name, path):
            subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in mods]
            graph[name].update(subs)  # `from . import chain`: the submodule
            if target in mods and len(subs) < max(len(names), 1):
                graph[name].add(target)
    return graph


def test_import_graph_has_no_cycle():
    graph = _graph()
    state, cycle = {}, []

    def visit(m, stack):
        state[m] = 1
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                cycle.append(stack[stack.index(n) :] + [n])
            elif n not in state:
                visit(n, stack + [n])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not cycle, "import cycles: " + "; ".join(" -> ".join(c) for c in cycle)


def _system(module: str):
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in SYSTEMS else None


def test_no_system_imports_another_systems_private_names():
    bad = []
    for name, path in _modules().items():
        own = _system(name)
        for target, names in _imports(name, path):
            other = _system(target)
            if other is None or other == own:
                continue
            private_module = any(p.startswith("_") for p in target.split(".")[2:])
            private_names = [n for n in names if n.startswith("_")]
            if private_module or private_names:
                bad.append(f"{name}: from {target} import {', '.join(names)}")
    assert not bad, "\n".join(bad)


def test_every_public_name_is_flat_without_collision():
    for ns in SYSTEMS:
        module = getattr(js, ns)
        for n in module.__all__:
            assert getattr(js, n) is getattr(module, n), f"js.{n} is not {ns}.{n}"


def test_each_effect_is_defined_once():
    # Drag, Gravity and Buoyancy are the chain core's, whichever system names them.
    for name in ("Drag", "Gravity", "Buoyancy"):
        defined = {
            getattr(getattr(js, ns), name).__module__
            for ns in SYSTEMS
            if hasattr(getattr(js, ns), name)
        }
        assert defined == {"jaxstring.chain.effects"}, (name, defined)
