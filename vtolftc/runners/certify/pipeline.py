"""The certify pipeline: stages run in order, each cached by its inputs, with gates.

A stage is a function ``run(ctx) -> dict`` (a JSON-ready record). Its **key** is the sha256 of
the airframe file's sha256, the code digest, the profile and the keys of the stages before it
(plus whatever the stage adds through ``Stage.inputs``): a change of the airframe file, of the
code or of an upstream result re-runs the stage and every stage after it. A finished stage is
written atomically to ``OUT/stages/NAME.json`` (``{"key": ..., "record": ...}``) the moment it
ends, so Ctrl-C or SIGTERM keep every finished stage; ``resume=True`` reuses a stage whose
file holds the same key. A record may carry ``"gate_failures"`` (a list of one-line
messages): the pipeline goes on (the report shows every stage) and the command exits 1.
A stage that raises :class:`StageError` (or another RuntimeError: a solver or SITL failure)
fails its gate and stops the stages that need it; it is not cached.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["PipelineResult", "Stage", "StageContext", "StageError", "code_digest",
           "run_pipeline", "stage_key"]


class StageError(RuntimeError):
    """A stage could not produce its result (its gate fails; stages needing it are skipped)."""


@dataclass
class StageContext:
    """What every stage sees: the airframe file, the output folder, the profile settings,
    the records of the stages run before it (by name) and the job/scheduler options."""

    airframe_path: Path
    airframe_sha256: str
    out_dir: Path
    profile: Mapping[str, Any]
    jobs: int | None = None
    scheduler: str | None = None
    resume: bool = False
    records: dict[str, dict[str, Any]] = field(default_factory=dict)
    log: Callable[[str], None] = print

    def stage_dir(self, name: str) -> Path:
        """``OUT/NAME`` (created): the folder where stage ``name`` writes its files."""
        d = self.out_dir / name
        d.mkdir(parents=True, exist_ok=True)
        return d


@dataclass(frozen=True)
class Stage:
    """One pipeline stage: ``run(ctx)`` returns its record; ``needs`` names the stages whose
    records it reads (a failed one skips it); ``inputs(ctx)`` adds cache-key inputs."""

    name: str
    title: str
    run: Callable[[StageContext], dict[str, Any]]
    needs: tuple[str, ...] = ()
    inputs: Callable[[StageContext], Mapping[str, Any]] | None = None


@dataclass
class PipelineResult:
    """Every stage's record (in order), which came from the cache, and the gate failures."""

    records: dict[str, dict[str, Any]]
    cached: list[str]
    gate_failures: list[str]
    times_s: dict[str, float]

    @property
    def passed(self) -> bool:
        """True when no gate failed."""
        return not self.gate_failures


def code_digest(roots: Sequence[Path] | None = None) -> str:
    """sha256 over the Python sources of the ``vtolftc`` packages (path and bytes of every
    ``.py`` file, sorted): a code change invalidates the cache."""
    if roots is None:
        import vtolftc
        import vtolftc.airframe
        import vtolftc.firmware_sim
        import vtolftc.protocols
        import vtolftc.synthesis

        roots = [Path(p) for m in (vtolftc, vtolftc.airframe, vtolftc.firmware_sim,
                                   vtolftc.protocols, vtolftc.synthesis) for p in m.__path__]
    h = hashlib.sha256()
    for root in sorted(set(roots)):
        for f in sorted(root.rglob("*.py")):
            h.update(str(f.relative_to(root)).encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def stage_key(stage: Stage, ctx: StageContext, code: str, upstream: Sequence[str]) -> str:
    """The cache key of ``stage`` (see the module docstring)."""
    extra = dict(stage.inputs(ctx)) if stage.inputs else {}
    doc = {"stage": stage.name, "airframe_sha256": ctx.airframe_sha256, "code": code,
           "profile": dict(ctx.profile), "upstream": list(upstream), "inputs": extra}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def _write_json(path: Path, doc: Mapping[str, Any]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1, default=str) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _read_cached(path: Path, key: str) -> dict[str, Any] | None:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("key") != key or not isinstance(
            doc.get("record"), dict):
        return None
    return doc["record"]


def run_pipeline(stages: Sequence[Stage], ctx: StageContext, *, code: str | None = None,
                 ) -> PipelineResult:
    """Run ``stages`` in order with the cache (see the module docstring).

    Returns every record; a stage that raised a RuntimeError gets the record
    ``{"verdict": "fail", "error": ..., "gate_failures": [...]}`` (not cached) and the stages
    that need it ``{"verdict": "skipped", ...}``. KeyboardInterrupt propagates after the
    finished stages are on disk.
    """
    code = code_digest() if code is None else code
    sdir = ctx.out_dir / "stages"
    sdir.mkdir(parents=True, exist_ok=True)
    keys: list[str] = []
    cached: list[str] = []
    failures: list[str] = []
    times: dict[str, float] = {}
    bad: set[str] = set()
    for st in stages:
        key = stage_key(st, ctx, code, keys)
        keys.append(key)
        path = sdir / f"{st.name}.json"
        missing = [n for n in st.needs if n in bad]
        if missing:
            rec = {"verdict": "skipped", "error": f"needs {', '.join(missing)}, which failed"}
            ctx.records[st.name] = rec
            bad.add(st.name)
            continue
        rec = _read_cached(path, key) if ctx.resume else None
        if rec is not None:
            ctx.log(f"[{st.name}] reused from {path} (same airframe, code and inputs)")
            cached.append(st.name)
        else:
            ctx.log(f"[{st.name}] {st.title} ...")
            t0 = time.perf_counter()
            try:
                rec = dict(st.run(ctx))
            except RuntimeError as exc:  # StageError, or a domain failure (solver, SITL)
                msg = str(exc) if isinstance(exc, StageError) else (
                    f"{type(exc).__name__}: {exc}")
                rec = {"verdict": "fail", "error": msg, "gate_failures": [f"{st.name}: {msg}"]}
                bad.add(st.name)
            times[st.name] = time.perf_counter() - t0
            rec.setdefault("wall_s", times[st.name])
            if st.name not in bad:
                _write_json(path, {"key": key, "stage": st.name, "record": rec})
            ctx.log(f"[{st.name}] {rec.get('verdict', 'done')} ({times[st.name]:.1f} s)")
        ctx.records[st.name] = rec
        failures += [str(f) for f in rec.get("gate_failures", [])]
    return PipelineResult(dict(ctx.records), cached, failures, times)
