"""Classes the size of one idea: no class of the repository's packages over 400 lines (issue 21).

Every ``.py`` file of the package folders is parsed with :mod:`ast`; a class's size is
``end_lineno - lineno + 1`` (decorators excluded, nested classes counted in their parent and
on their own). ``protocols/generated/`` is pymavlink's mavgen output, committed once and
never edited by hand (its ``MAVLink`` class holds one method per message), so it is not
scanned.

Classes other branches are splitting now are listed in :data:`PENDING_SPLIT`: the main test
skips them and a separate, non-strict xfail test keeps reporting them until they are split.
The list is emptied when those branches are merged.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("airframe", "dashboard", "firmware_sim", "gcs", "protocols", "synthesis", "vtolftc")
GENERATED = (Path("protocols") / "generated",)
"""Folders of generated code (mavgen), not scanned."""
MAX_CLASS_LINES = 400

PENDING_SPLIT = {
    "firmware_sim/vehicle/process.py:VehicleProcess",
}
"""Classes over the limit that other branches are splitting right now (``path:Class``); the
lead empties this set on merge."""

SPLIT_HERE = {
    "firmware_sim/autopilot/gcs_endpoint.py:GcsEndpoint",
    "gcs/client.py:GroundStation",
    "firmware_sim/autopilot/navigator.py:Navigator",
    "firmware_sim/autopilot/autopilot.py:Autopilot",
    "vtolftc/telemetry/recording.py:RerunRecorder",
}
"""Classes split already (they must never come back into :data:`PENDING_SPLIT`)."""


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
    over = {k: n for k, n in oversized().items() if k not in PENDING_SPLIT}
    assert not over, "classes over 400 lines (split them along their seams): " + ", ".join(
        f"{k} ({n} lines)" for k, n in sorted(over.items()))


def test_split_classes_are_not_pending_and_stay_well_under_the_limit():
    assert not PENDING_SPLIT & SPLIT_HERE
    sizes = oversized(limit=350)
    assert not {k: sizes[k] for k in SPLIT_HERE if k in sizes}


@pytest.mark.xfail(strict=False, reason="classes being split on other branches this hour "
                   "(PENDING_SPLIT; the lead empties it on merge)")
def test_pending_splits_are_done():
    over = {k: n for k, n in oversized().items() if k in PENDING_SPLIT}
    assert not over, "still over 400 lines: " + ", ".join(
        f"{k} ({n} lines)" for k, n in sorted(over.items()))
