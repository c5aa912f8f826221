"""An attribute of a composed object that lives on one of its parts."""

from __future__ import annotations

from typing import Any

__all__ = ["Delegated"]


class Delegated:
    """Descriptor: ``owner.<name>`` reads and writes ``owner.<part>.<attr>``.

    Keeps the attribute names a composed class has always offered (e.g.
    ``Autopilot.allocator``, assignable by benchmarks) while the state lives in the
    collaborator that uses it.

    Parameters
    ----------
    part
        attribute of the owner holding the collaborator.
    attr
        attribute of the collaborator.
    """

    __slots__ = ("attr", "part")

    def __init__(self, part: str, attr: str) -> None:
        self.part = part
        self.attr = attr

    def __get__(self, obj: Any, objtype: type | None = None) -> Any:
        if obj is None:
            return self
        return getattr(getattr(obj, self.part), self.attr)

    def __set__(self, obj: Any, value: Any) -> None:
        setattr(getattr(obj, self.part), self.attr, value)
