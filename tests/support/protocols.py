"""A structural check stronger than ``isinstance`` on a runtime-checkable Protocol (which only
looks for attribute names): every method of the protocol exists on the object with the same
parameters, in the same order, with the same kinds."""

from __future__ import annotations

import inspect
from typing import Any


def protocol_mismatches(obj: Any, protocol: type) -> list[str]:
    """What ``obj`` lacks or gets wrong of ``protocol`` (empty when it implements it)."""
    out = []
    for name, member in inspect.getmembers(protocol):
        if name.startswith("_") or not callable(member):
            continue
        impl = getattr(obj, name, None)
        if impl is None or not callable(impl):
            out.append(f"{name}: missing")
            continue
        want = [(p.name, p.kind) for p in inspect.signature(member).parameters.values()
                if p.name != "self"]
        got = [(p.name, p.kind) for p in inspect.signature(impl).parameters.values()]
        if want != got:
            out.append(f"{name}{inspect.signature(impl)}: expected {want}")
    return out
