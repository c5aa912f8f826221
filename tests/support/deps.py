"""Which third-party distributions a tree of Python files needs, against what ``pyproject.toml``
declares.

A module is *needed* when a file imports it (``import x``, ``from x import y``,
``pytest.importorskip("x")``, ``importlib.import_module("x")`` with a literal name) and it is
neither in the standard library nor first-party (``vtolftc``, or a module that sits beside the
importing file or in ``tests/``, such as ``support`` and ``conftest``). An import inside a
``try`` whose handler catches ``ImportError`` (or ``ModuleNotFoundError``), and an
``importorskip``, is *optional*.

The module is mapped to the distributions that provide it through
:func:`importlib.metadata.packages_distributions` of the running environment. A needed import is
fine when one of those distributions is declared for the file's scope: named in the
dependencies the scope may use, or pulled in by an extra of one of them
(``dask[distributed]`` declares ``distributed``). An optional import of a module that is not
installed is fine when its name is declared in some extra (``daqp`` in ``bench``). Everything
else is a problem, reported as one line naming the file, the module and what to do.
"""

from __future__ import annotations

import ast
import importlib.metadata as md
import re
import sys
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

_NAME = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[([^\]]*)\])?")


def normalize(name: str) -> str:
    """A distribution name as PEP 503 compares them (``PyYAML`` -> ``pyyaml``)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def requirement_names(reqs: Iterable[str]) -> set[str]:
    """Normalised distribution names of requirement strings, with the distributions their
    extras pull in (read from the installed metadata; an extra of a package that is not
    installed adds nothing)."""
    out: set[str] = set()
    for req in reqs:
        m = _NAME.match(req)
        if m is None:
            continue
        name = normalize(m.group(1))
        out.add(name)
        extras = {normalize(e) for e in (m.group(2) or "").split(",") if e.strip()}
        if not extras:
            continue
        try:
            sub = md.requires(name) or []
        except md.PackageNotFoundError:
            continue
        for r in sub:
            marker = re.search(r"extra\s*==\s*['\"]([^'\"]+)['\"]", r)
            if marker and normalize(marker.group(1)) in extras:
                sm = _NAME.match(r)
                if sm:
                    out.add(normalize(sm.group(1)))
    return out


@dataclass(frozen=True)
class Declared:
    """What a ``pyproject.toml`` declares: the base dependencies and each extra's."""

    base: tuple[str, ...]
    extras: Mapping[str, tuple[str, ...]]

    @classmethod
    def read(cls, pyproject: Path) -> Declared:
        """Parse ``[project] dependencies`` and ``optional-dependencies``."""
        project = tomllib.loads(pyproject.read_text())["project"]
        extras = {k: tuple(v) for k, v in project.get("optional-dependencies", {}).items()}
        return cls(tuple(project.get("dependencies", [])), extras)

    def names(self, extras: Iterable[str] = ()) -> set[str]:
        """Distributions the base and ``extras`` declare (with what their extras pull in)."""
        reqs = list(self.base)
        for e in extras:
            if e not in self.extras:
                raise KeyError(f"pyproject.toml has no extra {e!r}")
            reqs += self.extras[e]
        return requirement_names(reqs)

    def any_extra_names(self) -> set[str]:
        """Distributions named anywhere (base or any extra)."""
        return self.names(self.extras)


@dataclass(frozen=True)
class Import:
    """One third-party import found in a file."""

    path: Path
    line: int
    module: str  # the top-level name
    optional: bool


def _catches_import_error(handler: ast.ExceptHandler) -> bool:
    t = handler.type
    names = [t] if not isinstance(t, ast.Tuple) else list(t.elts)
    return t is None or any(isinstance(n, ast.Name) and n.id in
                            {"ImportError", "ModuleNotFoundError", "Exception"} for n in names)


def _local_names(path: Path, extra_dirs: Iterable[Path]) -> set[str]:
    names: set[str] = set()
    for d in {path.parent, *extra_dirs}:
        if d.is_dir():
            names |= {p.stem for p in d.glob("*.py")}
            names |= {p.name for p in d.iterdir() if (p / "__init__.py").is_file()}
    return names


def imports_of(path: Path, local_dirs: Iterable[Path] = (),
               first_party: Iterable[str] = ("vtolftc",)) -> list[Import]:
    """Third-party top-level imports of one file (standard library and first-party left out)."""
    tree = ast.parse(path.read_text(errors="replace"), filename=str(path))
    skip = set(sys.stdlib_module_names) | set(first_party) | _local_names(path, local_dirs)
    optional_nodes: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try) and any(_catches_import_error(h) for h in node.handlers):
            for stmt in node.body:
                optional_nodes |= {id(n) for n in ast.walk(stmt)}
    found: list[Import] = []

    def add(name: str, node: ast.AST, optional: bool) -> None:
        top = name.split(".")[0]
        if top and top not in skip:
            found.append(Import(path, node.lineno, top, optional or id(node) in optional_nodes))

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                add(a.name, node, False)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            add(node.module, node, False)
        elif (isinstance(node, ast.Call) and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            f = node.func
            fname = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) \
                else ""
            if fname == "importorskip":
                add(node.args[0].value, node, True)
            elif fname == "import_module":
                add(node.args[0].value, node, False)
    return found


def undeclared(imports: Iterable[Import], allowed: set[str], anywhere: set[str],
               providers: Mapping[str, list[str]] | None = None) -> list[str]:
    """One line per import that the declared dependencies do not provide.

    Parameters
    ----------
    imports
        What :func:`imports_of` found.
    allowed
        Normalised distribution names the files' scope may use.
    anywhere
        Normalised names declared in any extra (for optional imports of packages that are not
        installed here).
    providers
        Module name -> distribution names; :func:`importlib.metadata.packages_distributions`
        of the running environment when None.

    Returns
    -------
    list of str
        ``path:line: module 'x' (from distribution D) is not declared ...`` lines; empty when
        every import is provided.
    """
    prov = md.packages_distributions() if providers is None else providers
    problems = []
    for imp in imports:
        dists = {normalize(d) for d in prov.get(imp.module, [])}
        where = f"{imp.path}:{imp.line}"
        if dists & allowed:
            continue
        if imp.optional and (dists | {normalize(imp.module)}) & anywhere:
            continue  # an optional accelerator or comparison, declared in an extra
        if not dists:
            problems.append(f"{where}: module {imp.module!r} is imported but no installed "
                            f"distribution provides it; declare it in pyproject.toml")
            continue
        problems.append(f"{where}: module {imp.module!r} comes from {', '.join(sorted(dists))}, "
                        f"which pyproject.toml does not declare for this code; add it to the "
                        f"dependencies (or the extra this code is run with)")
    return problems
