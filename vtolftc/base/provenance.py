"""Provenance stamps of shipped results files: what made them, from which inputs.

A results folder (for example ``docs/ds1-claims/``) keeps a sidecar ``PROVENANCE.json``
with one stamp per results file::

    {"format": "vtolftc-provenance/1",
     "files": {"robust.json": {"command": "python benchmarks/regen_docs.py ...",
                               "inputs": {"firmware_sim/autopilot/gains/gs-shif.json": "<sha256>",
                                          ...},
                               "results_sha256": "<sha256 of the records>",
                               "flights_sha256": "<sha256 over the records' command digests>",
                               "records": 34, ...}}}

``inputs`` are the gain files (and the airframe file) the results were computed from, by
path relative to the repository root, with their sha256. ``results_sha256`` is the digest of
the file's records in a canonical JSON form (sorted keys, no whitespace), so it does not
change when the file is only re-indented, and does change with any number in it.
``flights_sha256`` is the sha256 over the ``commands_sha256`` of each record in order
(``benchmarks/command_digest.py``'s digest of every control step's actuator commands): it
changes exactly when one of the flights the file reports flew differently.

:func:`check_folder` says what no longer matches (a gain file re-synthesised, a results file
edited or regenerated without its stamp); :func:`compare_records` compares freshly computed
records with stored ones to the last digit.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["FORMAT", "SIDECAR", "canonical_sha256", "check_folder", "compare_records",
           "file_sha256", "flights_sha256", "make_file_stamp", "make_stamp", "results_sha256"]

#: Format tag of the sidecar.
FORMAT = "vtolftc-provenance/1"
#: Name of the sidecar in a results folder.
SIDECAR = "PROVENANCE.json"


def file_sha256(path: str | Path) -> str:
    """Hex sha256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def canonical_sha256(doc: Any) -> str:
    """Hex sha256 of ``doc`` as canonical JSON (sorted keys, compact separators).

    Python writes every float with the shortest repr that reads back to the same double, so
    a document read from a file and written again digests the same; any changed digit does
    not.
    """
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def results_sha256(path: str | Path) -> str:
    """The results digest of a file: :func:`canonical_sha256` of a ``.json`` file's document,
    the sha256 of the bytes of any other file (a report, a figure)."""
    path = Path(path)
    if path.suffix == ".json":
        return canonical_sha256(json.loads(path.read_text()))
    return file_sha256(path)


def flights_sha256(records: Iterable[Mapping[str, Any]]) -> str | None:
    """sha256 over the records' ``commands_sha256`` in order; None if a record has none."""
    h = hashlib.sha256()
    for r in records:
        d = r.get("commands_sha256")
        if not isinstance(d, str):
            return None
        h.update(d.encode())
    return h.hexdigest()


def make_stamp(doc: Any, *, command: str, inputs: Sequence[str | Path], root: str | Path,
               **extra: Any) -> dict[str, Any]:
    """The stamp of one results document.

    Parameters
    ----------
    doc : object
        The document as written to the results file (a list of records, or a mapping).
    command : str
        The command that wrote it, as typed from the repository root.
    inputs : sequence of path
        The gain files (and other input files) the results were computed from.
    root : path
        The repository root; input paths are stored relative to it (POSIX form).
    **extra
        Further fields stored as they are (e.g. the code commit, informative only).

    Returns
    -------
    dict
        ``command``, ``inputs`` (relative path -> sha256), ``results_sha256``, ``records``
        and, for a list of flight records with command digests, ``flights_sha256``.
    """
    root = Path(root).resolve()
    ins = {}
    for p in inputs:
        p = Path(p).resolve()
        ins[p.relative_to(root).as_posix()] = file_sha256(p)
    stamp: dict[str, Any] = {"command": command, "inputs": dict(sorted(ins.items())),
                             "results_sha256": canonical_sha256(doc)}
    if isinstance(doc, list):
        stamp["records"] = len(doc)
        fl = flights_sha256(doc)
        if fl is not None:
            stamp["flights_sha256"] = fl
    stamp.update(extra)
    return stamp


def make_file_stamp(path: str | Path, *, command: str, inputs: Sequence[str | Path],
                    root: str | Path, **extra: Any) -> dict[str, Any]:
    """The stamp of a results file as it is on disk (see :func:`make_stamp`); for a file
    that is not JSON (a report, a figure) the digest is that of its bytes."""
    path = Path(path)
    if path.suffix == ".json":
        return make_stamp(json.loads(path.read_text()), command=command, inputs=inputs,
                          root=root, **extra)
    stamp = make_stamp(None, command=command, inputs=inputs, root=root, **extra)
    stamp["results_sha256"] = file_sha256(path)
    return stamp


def check_folder(folder: str | Path, root: str | Path, *,
                 pattern: str = "*.json") -> list[str]:
    """Every way the results files of ``folder`` disagree with their stamps.

    Parameters
    ----------
    folder : path
        The results folder holding ``PROVENANCE.json``.
    root : path
        The repository root the stamps' input paths are relative to.
    pattern : str
        Glob of the results files that must each carry a stamp (JSON files are compared by
        their records, other files by their bytes).

    Returns
    -------
    list of str
        One line per problem (empty when everything matches): a results file without a
        stamp, a stamp without its file, an input file missing or with another sha256 than
        the one the results were made from, a results file whose records or flight digests
        are not the ones stamped.
    """
    folder, root = Path(folder), Path(root)
    side = folder / SIDECAR
    if not side.is_file():
        return [f"{side}: missing"]
    prov = json.loads(side.read_text())
    if prov.get("format") != FORMAT:
        return [f"{side}: format {prov.get('format')!r}, expected {FORMAT!r}"]
    stamps: dict[str, dict[str, Any]] = prov.get("files", {})
    problems = []
    shipped = sorted(p.name for p in folder.glob(pattern) if p.name != SIDECAR)
    problems += [f"{n}: no stamp in {SIDECAR}" for n in shipped if n not in stamps]
    for name, st in sorted(stamps.items()):
        path = folder / name
        if not path.is_file():
            problems.append(f"{name}: stamped but missing")
            continue
        for rel, sha in st.get("inputs", {}).items():
            ip = root / rel
            if not ip.is_file():
                problems.append(f"{name}: input {rel} missing")
            elif file_sha256(ip) != sha:
                problems.append(f"{name}: input {rel} changed since the results were made "
                                f"(sha256 {file_sha256(ip)[:12]}, made from {sha[:12]}); "
                                f"regenerate: {st.get('command')}")
        if results_sha256(path) != st.get("results_sha256"):
            problems.append(f"{name}: records differ from the stamped results "
                            f"(edited, or regenerated without its stamp): {st.get('command')}")
        if "flights_sha256" in st and flights_sha256(
                json.loads(path.read_text())) != st["flights_sha256"]:
            problems.append(f"{name}: flight digests differ from the stamped flights")
    return problems


def _same(a: Any, b: Any, rel: float = 0.0) -> bool:
    """Equal, with NaN equal to NaN (a crashed flight's metrics); floats within ``rel``
    (relative) when ``rel`` > 0."""
    if isinstance(a, float) and isinstance(b, float):
        if math.isnan(a) and math.isnan(b):
            return True
        if rel > 0.0:
            return abs(a - b) <= rel * max(abs(a), abs(b))
    return bool(a == b)


def compare_records(stored: Sequence[Mapping[str, Any]], fresh: Sequence[Mapping[str, Any]],
                    key: Sequence[str] = ("label", "controller"), *,
                    rel: float = 0.0) -> list[str]:
    """Differences between stored records and freshly computed ones.

    Each fresh record is matched to the stored record with the same ``key`` fields; every
    field of the fresh record must be present and equal (floats to the last digit unless
    ``rel`` > 0; NaN equals NaN).

    Parameters
    ----------
    stored, fresh : sequence of mapping
        The shipped records and the recomputed ones.
    key : sequence of str
        The fields that identify a record.
    rel : float
        Relative tolerance of float fields (0: to the last digit). For quantities computed
        through LAPACK / BLAS only: OpenBLAS picks its kernels by CPU, so their last digits
        differ between machines (a flight's numbers do not: its kernels call no BLAS).

    Returns
    -------
    list of str
        One line per difference; empty when every fresh record is stored as computed.
    """
    index = {tuple(r.get(k) for k in key): r for r in stored}
    out = []
    for f in fresh:
        k = tuple(f.get(x) for x in key)
        s = index.get(k)
        if s is None:
            out.append(f"{k}: not among the stored records")
            continue
        for field, v in f.items():
            if field not in s:
                out.append(f"{k}: {field} not stored")
            elif not _same(s[field], v, rel):
                out.append(f"{k}: {field} stored {s[field]!r}, computed {v!r}")
    return out
