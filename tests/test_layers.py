"""The import layers of DESIGN.md, enforced: every arrow points down, and none runs in a circle.

The layer table below is the one place the layers are written down. Every module of the
``vtolftc`` namespace must be in it; a module may import only modules of its own group or of a
lower layer. Groups of one layer are siblings that never import each other (the autopilot never
imports the vehicle nor the synthesis: passive FTC, and the gains reach it as files). Every
import counts, also those inside functions and under ``TYPE_CHECKING``, and so does a module
loaded by name: a string that is exactly the name of one of the namespace's modules
(``importlib.import_module("vtolftc.cli.cmd_fly")``, a table of command modules, ``python -m
vtolftc.runners.processes.vehicle``).

No module takes a private name (``_x``) from another module: what another module needs is
public, or it is not needed.
"""

from __future__ import annotations

import ast
import fnmatch
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Bottom up: (layer, group, module patterns). Patterns match a module and its sub-modules.
LAYERS: list[tuple[int, str, tuple[str, ...]]] = [
    (0, "base", ("vtolftc", "vtolftc.base", "vtolftc.airframe")),
    (1, "protocols", ("vtolftc.protocols",)),
    (2, "telemetry", ("vtolftc.telemetry",)),
    (3, "autopilot", ("vtolftc.firmware_sim", "vtolftc.firmware_sim.autopilot")),
    (3, "vehicle", ("vtolftc.firmware_sim.vehicle",)),
    (3, "synthesis", ("vtolftc.synthesis",)),
    (3, "gcs", ("vtolftc.gcs",)),
    (4, "runners", ("vtolftc.runners",)),
    (5, "top", ("vtolftc.cli", "vtolftc.dashboard", "vtolftc.__main__")),
]


def _package_dirs() -> dict[str, Path]:
    py = tomllib.loads((ROOT / "pyproject.toml").read_text())
    return {pkg: ROOT / d for pkg, d in py["tool"]["setuptools"]["package-dir"].items()}


def _modules() -> dict[str, Path]:
    """Every module of the namespace -> its file, following the package-dir mapping."""
    mods: dict[str, Path] = {}
    for pkg, d in _package_dirs().items():
        for f in d.rglob("*.py"):
            rel = f.relative_to(d).with_suffix("")
            if "generated" in rel.parts or "__pycache__" in rel.parts:
                continue
            parts = [p for p in rel.parts if p != "__init__"]
            name = ".".join([pkg, *parts])
            if pkg == "vtolftc" and parts and f"vtolftc.{parts[0]}" in _package_dirs():
                continue  # a folder of its own, mapped above
            mods[name] = f
    return mods


def _group(module: str) -> tuple[int, str] | None:
    best: tuple[int, tuple[int, str]] | None = None
    for layer, group, patterns in LAYERS:
        for pat in patterns:
            hit = (fnmatch.fnmatchcase(module, pat) or fnmatch.fnmatchcase(module, pat + ".*")
                   if "*" in pat else module == pat or module.startswith(pat + "."))
            if hit and (best is None or len(pat) > best[0]):
                best = (len(pat), (layer, group))
    return None if best is None else best[1]


def _imports(path: Path, module: str, known: set[str]) -> set[str]:
    """The namespace modules ``path`` imports (resolving ``from pkg import submodule``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out: set[str] = set()
    is_pkg = path.name == "__init__.py"
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = module.split(".") if is_pkg else module.split(".")[:-1]
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            out.add(base)
            out |= {f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in known}
    out |= {n.value for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and n.value in known}
    return {m for m in out if m == "vtolftc" or m.startswith("vtolftc.")}


def _private_imports(path: Path, module: str, known: set[str]) -> list[str]:
    """``from other import _name`` and ``other_module._name`` in ``path``: private names taken
    from another module of the namespace (a sub-module named ``_x`` is a module, not a name)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_pkg = path.name == "__init__.py"
    out: list[str] = []
    aliases: dict[str, str] = {}

    def private(name: str) -> bool:
        return name.startswith("_") and not name.startswith("__")

    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = module.split(".") if is_pkg else module.split(".")[:-1]
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            if not (base == "vtolftc" or base.startswith("vtolftc.")) or base == module:
                continue
            for a in node.names:
                if f"{base}.{a.name}" in known:
                    aliases[a.asname or a.name] = f"{base}.{a.name}"
                elif private(a.name):
                    out.append(f"{module}:{node.lineno} takes {base}.{a.name}")
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name in known and a.asname:
                    aliases[a.asname] = a.name
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in aliases and private(node.attr)
                and aliases[node.value.id] != module):
            out.append(f"{module}:{node.lineno} takes {aliases[node.value.id]}.{node.attr}")
    return out


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    graph: dict[str, set[str]] = {}
    for name, f in mods.items():
        deps = set()
        for imp in _imports(f, name, known):
            while imp not in known and "." in imp:  # an attribute: its module
                imp = imp.rsplit(".", 1)[0]
            if imp in known and imp != name:
                deps.add(imp)
        graph[name] = deps
    return graph


def test_every_module_has_a_layer():
    missing = sorted(m for m in _modules() if _group(m) is None)
    assert not missing, f"add these modules to LAYERS in tests/test_layers.py: {missing}"
    assert len(_modules()) > 60


def test_imports_only_point_down():
    bad = []
    for mod, deps in _graph().items():
        layer, group = _group(mod)
        for dep in deps:
            if dep == "vtolftc" or mod == dep:
                continue
            dlayer, dgroup = _group(dep)
            if dlayer > layer or (dlayer == layer and dgroup != group):
                bad.append(f"{mod} ({group}, layer {layer}) imports {dep} "
                           f"({dgroup}, layer {dlayer})")
    assert not bad, "imports that run back up or sideways:\n" + "\n".join(sorted(bad))


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    graph = _graph()
    # a package's __init__ re-exporting its own modules is not a cycle of design
    for mod in list(graph):
        graph[mod] = {d for d in graph[mod] if not (mod.startswith(d + ".") and
                                                    _modules()[d].name == "__init__.py")}
    assert _cycles(graph) == []


@pytest.mark.parametrize("src, expect", [
    ("from vtolftc.firmware_sim.vehicle.model import Vehicle\n", "imports"),
    ("def f():\n    import vtolftc.synthesis.mu\n", "imports"),
    ("from vtolftc.dashboard import web\n", "imports"),
])
def test_the_check_catches_a_forbidden_import(tmp_path, src, expect):
    """The scan sees module-level, function-level and package-relative imports."""
    f = tmp_path / "x.py"
    f.write_text(src)
    known = set(_modules())
    deps = _imports(f, "vtolftc.firmware_sim.autopilot.x", known)
    assert deps and all(_group(d) is not None for d in deps)
    layer, group = _group("vtolftc.firmware_sim.autopilot.x")
    assert any(_group(d)[0] > layer or _group(d)[1] != group for d in deps)


def test_no_private_name_crosses_a_module():
    mods = _modules()
    known = set(mods)
    bad = [hit for name, f in mods.items() for hit in _private_imports(f, name, known)]
    assert not bad, "private names taken from other modules:\n" + "\n".join(sorted(bad))


@pytest.mark.parametrize("src, hits", [
    ("from vtolftc.firmware_sim.autopilot.pid import _TWO_PI, CascadedPPID\n", 1),
    ("def f():\n    from .pid import _x\n", 1),
    ("from vtolftc.firmware_sim.autopilot import pid\nY = pid._e_prev\n", 1),
    ("import vtolftc.firmware_sim.autopilot.pid as p\nY = p._x\n", 1),
    ("from vtolftc.firmware_sim.autopilot.pid import CascadedPPID\nz = CascadedPPID()._a\n", 0),
    ("from vtolftc.firmware_sim.autopilot.x import _own\n", 0),  # its own module
])
def test_the_check_catches_a_private_name(tmp_path, src, hits):
    f = tmp_path / "x.py"
    f.write_text(src)
    known = set(_modules())
    assert len(_private_imports(f, "vtolftc.firmware_sim.autopilot.x", known)) == hits


def test_a_module_loaded_by_name_is_an_import(tmp_path):
    f = tmp_path / "x.py"
    f.write_text('import importlib\nMODS = ("vtolftc.dashboard.web",)\n'
                 'def f():\n    return importlib.import_module(MODS[0])\n')
    deps = _imports(f, "vtolftc.firmware_sim.autopilot.x", set(_modules()))
    assert "vtolftc.dashboard.web" in deps


def test_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_every_package_is_in_the_wheel():
    """pyproject lists packages explicitly (the package-dir mapping needs it): a package
    folder missing from the list would be missing from a wheel install."""
    py = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(py["tool"]["setuptools"]["packages"])
    found = set()
    for pkg, d in _package_dirs().items():
        for init in d.rglob("__init__.py"):
            rel = init.parent.relative_to(d)
            if "__pycache__" in rel.parts:
                continue
            name = ".".join([pkg, *rel.parts])
            if pkg == "vtolftc" and rel.parts and f"vtolftc.{rel.parts[0]}" in _package_dirs():
                continue
            found.add(name)
    assert found - listed == set(), "add to [tool.setuptools] packages in pyproject.toml"
    assert listed - found == set()
