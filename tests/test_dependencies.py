"""Every third-party module the package, the tests and the benchmarks import is declared in
``pyproject.toml``, for the command that runs it: the package's imports by the base
dependencies, the tests' by the extras of the README's test command, the benchmarks' and the
docs' scripts by the base and every extra. A machine that happens to have a package installed
by hand can no longer hide a missing install step (the README's promise: two commands on a
fresh machine).

The scanner itself is tested on synthetic modules, so that this test can fail.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from support.deps import Declared, Import, imports_of, undeclared

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIRS = ("vtolftc", "airframe", "synthesis", "firmware_sim", "protocols", "gcs",
                "dashboard")
# mavgen's output: its `import fastcrc` is pymavlink's optional accelerator with a pure-Python
# fallback written by mavgen, not ours to declare
GENERATED = ROOT / "protocols" / "generated"


def _readme_commands() -> tuple[str, str]:
    """The README's first two commands (the first code block's first two lines)."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"```(?:bash|sh)?\n(.*?)```", text, re.S)
    assert block, "README.md has no code block with its two commands"
    lines = [ln.split("#")[0].strip() for ln in block.group(1).splitlines() if ln.strip()]
    assert len(lines) >= 2, "README.md's first code block has fewer than two commands"
    return lines[0], lines[1]


def _extras(command: str) -> list[str]:
    m = re.search(r"pip install (?:-e )?\"?\.(?:\[([^\]]*)\])?\"?", command)
    assert m, f"no `pip install .` in {command!r}"
    return [e.strip() for e in (m.group(1) or "").split(",") if e.strip()]


def _files(*dirs: str) -> list[Path]:
    out = []
    for d in dirs:
        out += [p for p in (ROOT / d).rglob("*.py")
                if GENERATED not in p.parents and "__pycache__" not in p.parts]
    return sorted(out)


def _scan(files: list[Path], extras: list[str]) -> list[str]:
    declared = Declared.read(ROOT / "pyproject.toml")
    found: list[Import] = []
    for f in files:
        found += imports_of(f, local_dirs=[ROOT / "tests", ROOT / "benchmarks"])
    return undeclared(found, declared.names(extras), declared.any_extra_names())


def test_readme_commands_are_the_install_and_test_commands():
    install, test = _readme_commands()
    assert _extras(install) == [] and "vtolftc" in install
    assert _extras(test) == ["test"] and "python -m pytest" in test
    ci = (ROOT / ".ci" / "run").read_text()
    assert test.split("&&")[0].strip() in ci and "python -m pytest" in ci
    # CI runs them in a virtual environment of its own, not the machine's Python
    assert "-m venv" in ci and "--system-site-packages" not in ci


def test_package_imports_are_base_dependencies():
    problems = _scan(_files(*PACKAGE_DIRS), [])
    assert not problems, "\n".join(problems)


def test_test_imports_are_in_the_readme_test_command_extras():
    problems = _scan(_files("tests"), _extras(_readme_commands()[1]))
    assert not problems, "\n".join(problems)


def test_benchmark_and_docs_script_imports_are_declared():
    declared = Declared.read(ROOT / "pyproject.toml")
    problems = _scan(_files("benchmarks", "docs"), sorted(declared.extras))
    assert not problems, "\n".join(problems)


# ------------------------------------------------------------ the scanner on synthetic modules
def _module(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "synthetic_mod.py"
    p.write_text(text)
    return p


PROVIDERS = {"numpy": ["numpy"], "yaml": ["PyYAML"], "distributed": ["distributed"],
             "daqp": ["daqp"]}


def test_scanner_flags_an_undeclared_import(tmp_path):
    f = _module(tmp_path, "import os\nimport numpy as np\nfrom yaml import safe_load\n")
    found = imports_of(f)
    assert [i.module for i in found] == ["numpy", "yaml"]
    problems = undeclared(found, {"numpy"}, {"numpy"}, PROVIDERS)
    assert len(problems) == 1 and "'yaml'" in problems[0] and "pyyaml" in problems[0]
    assert problems[0].startswith(f"{f}:3:")
    assert undeclared(found, {"numpy", "pyyaml"}, set(), PROVIDERS) == []


def test_scanner_flags_an_import_nothing_provides(tmp_path):
    f = _module(tmp_path, "import surely_not_a_real_package_xyz\n")
    problems = undeclared(imports_of(f), {"numpy"}, {"numpy"}, PROVIDERS)
    assert len(problems) == 1 and "no installed distribution" in problems[0]


def test_scanner_sees_importorskip_and_import_module(tmp_path):
    f = _module(tmp_path, "import importlib\nimport pytest\n"
                          "yaml = pytest.importorskip('yaml')\n"
                          "np = importlib.import_module('numpy.linalg')\n")
    found = {i.module: i.optional for i in imports_of(f)}
    assert found == {"pytest": False, "yaml": True, "numpy": False}


def test_scanner_optional_imports_need_an_extra(tmp_path):
    f = _module(tmp_path, "try:\n    import daqp\nexcept ImportError:\n    daqp = None\n")
    (imp,) = imports_of(f)
    assert imp.optional
    assert undeclared([imp], {"numpy"}, {"daqp"}, PROVIDERS) == []       # declared in an extra
    assert len(undeclared([imp], {"numpy"}, {"numpy"}, PROVIDERS)) == 1  # declared nowhere
    assert len(undeclared([imp], {"numpy"}, {"daqp"}, {})) == 0           # not installed here


def test_scanner_leaves_out_stdlib_first_party_and_neighbours(tmp_path):
    (tmp_path / "helper_mod.py").write_text("")
    f = _module(tmp_path, "import json\nimport vtolftc.base.rotation\nimport helper_mod\n"
                          "from . import x\n")
    assert imports_of(f) == []


def test_declared_extras_pull_in_their_distributions():
    declared = Declared.read(ROOT / "pyproject.toml")
    names = declared.names([])
    assert {"numpy", "dask"} <= names
    # dask[distributed] declares the `distributed` distribution (when dask is installed)
    pytest.importorskip("dask")
    assert "distributed" in names
    with pytest.raises(KeyError):
        declared.names(["no-such-extra"])


def test_the_flight_software_runs_without_the_optional_osqp():
    """OSQP is an extra: without it the autopilot builds and steps (its allocator is the
    active-set solver) and only the OSQP comparison allocator refuses, with the install hint."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['osqp'] = None\n"
            "from vtolftc.firmware_sim.autopilot.autopilot import Autopilot\n"
            "from vtolftc.firmware_sim.autopilot.allocation import QPAllocator\n"
            "import numpy as np\n"
            "ap = Autopilot()\n"
            "try:\n"
            "    QPAllocator(5, np.zeros(3), np.ones(3))\n"
            "except ImportError as e:\n"
            "    print('refused:', e)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "refused: QPAllocator needs OSQP" in r.stdout and "vtol-ftc[osqp]" in r.stdout
