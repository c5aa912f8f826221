"""Classes the size of one idea: no class of the repository's packages over 400 lines (issue 21).

Every ``.py`` file of the package folders is parsed with :mod:`ast`; a class's size is
``end_lineno - lineno + 1`` (decorators excluded, nested classes counted in their parent and
on their own). ``protocols/generated/`` is pymavlink's mavgen output, committed once and
never edited by hand (its ``MAVLink`` class holds one method per message), so it is not
scanned.

The six classes that were split for issue 21 (:data:`SPLIT_HERE`, 501-797 lines before) must
also stay with room under the limit (at most 375 lines), so that the next feature lands in a
new collaborator rather than pushing them back over.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("airframe", "dashboard", "firmware_sim", "gcs", "protocols", "synthesis", "vtolftc")
GENERATED = (Path("protocols") / "generated",)
"""Folders of generated code (mavgen), not scanned."""
MAX_CLASS_LINES = 400

SPLIT_HERE = {
    "firmware_sim/autopilot/gcs_endpoint.py:GcsEndpoint",
    "gcs/client.py:GroundStation",
    "firmware_sim/autopilot/navigator.py:Navigator",
    "firmware_sim/autopilot/autopilot.py:Autopilot",
    "vtolftc/telemetry/recording.py:RerunRecorder",
    "firmware_sim/vehicle/process.py:VehicleProcess",
}
"""Classes split for issue 21 (``path:Class``)."""


def class_sizes(source: str, rel: str) -> dict[str, int]:
    """``{"rel:Class": lines}`` of every class (nested ones too) defined in ``source``."""
    tree = ast.parse(source, filename=rel)
    out: dict[str, int] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            assert node.end_lineno is not None
            key = f"{rel}:{node.name}"
            out[key] = max(out.get(key, 0), node.end_lineno - node.lineno + 1)
    return out


def _python_files() -> list[Path]:
    files = []
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            rel = f.relative_to(ROOT)
            if "__pycache__" in rel.parts or any(rel.is_relative_to(g) for g in GENERATED):
                continue
            files.append(f)
    return files


@functools.cache
def _all_sizes() -> dict[str, int]:
    out: dict[str, int] = {}
    for f in _python_files():
        out.update(class_sizes(f.read_text(encoding="utf-8"), f.relative_to(ROOT).as_posix()))
    return out


def oversized(limit: int = MAX_CLASS_LINES) -> dict[str, int]:
    """Every class of the packages over ``limit`` lines, ``{"path:Class": lines}``."""
    return {k: n for k, n in _all_sizes().items() if n > limit}


def test_scan_sees_the_packages():
    files = _python_files()
    assert len(files) > 100
    assert ROOT / "firmware_sim" / "autopilot" / "gcs_endpoint.py" in files
    assert ROOT / "gcs" / "client.py" in files
    assert not any("generated" in f.relative_to(ROOT).parts for f in files)


def test_class_size_is_measured_from_its_first_to_its_last_line():
    body = "\n".join(f"    x{i} = {i}" for i in range(400))
    src = f"import os\n\n\nclass Big:\n{body}\n\n\nclass Small:\n    class Inner:\n        y = 1\n"
    sizes = class_sizes(src, "m.py")
    assert sizes == {"m.py:Big": 401, "m.py:Small": 3, "m.py:Inner": 2}


def test_no_class_over_400_lines():
    over = oversized()
    assert not over, "classes over 400 lines (split them along their seams): " + ", ".join(
        f"{k} ({n} lines)" for k, n in sorted(over.items()))


def test_split_classes_stay_well_under_the_limit():
    sizes = oversized(limit=375)
    assert not {k: sizes[k] for k in SPLIT_HERE if k in sizes}
