"""The public API of ``synthesis/`` (the toolbox other code imports) is documented in numpydoc
form, and the examples in those docstrings run.

Every public module-level function and class of ``synthesis/`` (the toolbox and the designs
built on it: ``design.py``, ``robust.py``, ``design_loop.py``, ``scaling.py``), and every public
method of those classes, has a ``Parameters`` section that names each of its parameters (a
class: those of its constructor, i.e. its ``__init__`` or its dataclass fields) and, for a
function that returns something, a ``Returns`` section (a property: a docstring). The
main entry points carry an ``Examples`` section, and every example in the toolbox's
docstrings is run as a doctest.
"""

from __future__ import annotations

import ast
import copy
import doctest
import importlib
import re
from pathlib import Path

import pytest

SYNTHESIS = Path(__file__).resolve().parents[1] / "synthesis"
EXCLUDED = {"__init__.py"}
MODULES = sorted(p for p in SYNTHESIS.glob("*.py") if p.name not in EXCLUDED)

#: The toolbox's main entry points: each shows its use in an ``Examples`` section.
ENTRY_POINTS = {
    "hinfnorm": ("hinf_norm", "frequency_response"),
    "mu": ("mu_bounds", "mu_upper_bound", "mu_sweep"),
    "mu_blocks": ("Block", "BlockStructure"),
    "mixed_mu": ("mixed_mu_lower", "mixed_mu_bounds", "mixed_mu_sweep"),
    "dg_scaling": ("mixed_mu_upper", "certified_value"),
    "structured": ("tune", "pid"),
    "blocks": ("StaticGain", "lft_problem"),
    "lft": ("GeneralizedPlant", "lft"),
    "uncertainty": ("UncertaintyWeight", "fit_weight", "cover"),
    "models": ("axis_coefficients", "rate_model", "attitude_model"),
    "loops": ("SensitivityWeight", "closed_loop"),
    "surfaces": ("SurfaceBasis", "GainSurface", "schedule_from_surfaces"),
    "baselines": ("lqr_axis",),
    "scaling": ("actuator_bandwidth", "transition_speeds", "scaled_design_points"),
    "design_loop": ("point_seed",),
    "design": ("moment_authority", "parameters", "paper_points", "table2_scaled"),
    "robust": ("robust_points", "trim_rotor_thrusts", "rotor_out_moment", "delay_weight"),
    "validation": ("FlownSchedule", "cell_bounds", "loop_margins_classical"),
}


def _section(doc: str, title: str) -> str | None:
    """The body of a numpydoc section (``title`` underlined by dashes), or None."""
    head = rf"^[ \t]*{title}\n[ \t]*-{{{len(title)}}}\n"
    next_head = r"^[ \t]*\S[^\n]*\n[ \t]*-{3,}\n"
    m = re.search(rf"{head}(.*?)(?={next_head}|\Z)", doc, re.M | re.S)
    return None if m is None else m.group(1)


def _documented_names(section: str) -> set[str]:
    """Parameter names of a numpydoc Parameters section: the unindented ``a, b : type`` lines."""
    lines = [ln for ln in section.splitlines() if ln.strip()]
    if not lines:
        return set()
    base = min(len(ln) - len(ln.lstrip()) for ln in lines)
    names: set[str] = set()
    for ln in lines:
        if len(ln) - len(ln.lstrip()) == base:
            names.update(n.strip().lstrip("*") for n in ln.split(" : ")[0].split(","))
    return names


def _is_dataclass(node: ast.ClassDef) -> bool:
    for d in node.decorator_list:
        f = d.func if isinstance(d, ast.Call) else d
        if (isinstance(f, ast.Name) and f.id == "dataclass") or (
            isinstance(f, ast.Attribute) and f.attr == "dataclass"
        ):
            return True
    return False


def _arg_names(fn: ast.FunctionDef) -> list[str]:
    a = fn.args
    names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
    names += [x.arg for x in (a.vararg, a.kwarg) if x is not None]
    return [n for n in names if n not in ("self", "cls")]


def _constructor_params(node: ast.ClassDef) -> list[str]:
    for sub in node.body:
        if isinstance(sub, ast.FunctionDef) and sub.name == "__init__":
            return _arg_names(sub)
    if _is_dataclass(node):
        return [s.target.id for s in node.body
                if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)
                and "ClassVar" not in ast.unparse(s.annotation)]
    return []


def _returns_value(fn: ast.FunctionDef) -> bool:
    r = fn.returns
    return not (r is None or (isinstance(r, ast.Constant) and r.value is None))


def _public_definitions() -> list[tuple[str, ast.FunctionDef | ast.ClassDef]]:
    """(module, node) of every public function and class; methods named ``Class.method``."""
    out = []
    for path in MODULES:
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef | ast.ClassDef) and not node.name.startswith("_"):
                out.append((path.stem, node))
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                for sub in node.body:
                    if isinstance(sub, ast.FunctionDef) and not sub.name.startswith("_"):
                        method = copy.copy(sub)
                        method.name = f"{node.name}.{sub.name}"
                        out.append((path.stem, method))
    return out


def _is_property(node: ast.FunctionDef) -> bool:
    return any("property" in ast.unparse(d) for d in node.decorator_list)


def _doc_problems(node: ast.FunctionDef | ast.ClassDef) -> list[str]:
    doc = ast.get_docstring(node) or ""
    if not doc:
        return ["no docstring"]
    if isinstance(node, ast.FunctionDef) and _is_property(node):
        return []
    params = _constructor_params(node) if isinstance(node, ast.ClassDef) else _arg_names(node)
    problems = []
    if params:
        section = _section(doc, "Parameters")
        if section is None:
            problems.append("no Parameters section")
        else:
            missing = [p for p in params if p not in _documented_names(section)]
            if missing:
                problems.append(f"Parameters does not name {missing}")
    if isinstance(node, ast.FunctionDef) and _returns_value(node) and _section(
        doc, "Returns"
    ) is None:
        problems.append("no Returns section")
    return problems


def test_every_public_synthesis_definition_has_numpydoc_parameters_and_returns() -> None:
    defs = _public_definitions()
    assert len(defs) > 100  # the toolbox, not an empty glob
    bad = [f"{mod}.{node.name}: {', '.join(p)}" for mod, node in defs
           if (p := _doc_problems(node))]
    assert not bad, "undocumented public API:\n" + "\n".join(bad)


def test_the_docstring_checker_catches_what_it_should() -> None:
    """The check above fails on a missing section and on an unnamed parameter."""
    src = '''
def f(a, b, *, c=1) -> int:
    """Sum.

    Parameters
    ----------
    a, b : int
        Terms.

    Returns
    -------
    int
        The sum.
    """

def g(a) -> int:
    """No sections."""

@dataclass(frozen=True)
class C:
    """A class.

    Parameters
    ----------
    x : float
        Documented.
    """
    x: float
    y: float

def h(x) -> None:
    """Nothing returned.

    Parameters
    ----------
    x : int
        Input.
    """
'''
    nodes = {n.name: n for n in ast.parse(src).body}
    assert _doc_problems(nodes["f"]) == ["Parameters does not name ['c']"]
    assert _doc_problems(nodes["g"]) == ["no Parameters section", "no Returns section"]
    assert _doc_problems(nodes["C"]) == ["Parameters does not name ['y']"]
    assert _doc_problems(nodes["h"]) == []


def test_the_main_entry_points_have_examples() -> None:
    defs = {(mod, node.name): node for mod, node in _public_definitions()}
    missing = [f"{mod}.{name}" for mod, names in ENTRY_POINTS.items() for name in names
               if ">>>" not in (_section(ast.get_docstring(defs[(mod, name)]) or "", "Examples")
                                or "")]
    assert not missing, f"no Examples section with a doctest: {missing}"


@pytest.mark.parametrize("module", sorted(ENTRY_POINTS))
def test_docstring_examples_run(module: str) -> None:
    """Every example of the module's docstrings passes."""
    mod = importlib.import_module(f"vtolftc.synthesis.{module}")
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = [t for t in finder.find(mod) if t.examples]
    assert tests, f"{module}: no doctest found"
    report: list[str] = []
    for t in tests:
        runner.run(t, out=report.append)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, "".join(report)
