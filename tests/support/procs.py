"""The process trees tests start, read through psutil (one home for every test that needs
the live descendants of a process it started)."""

from __future__ import annotations

import psutil

__all__ = ["descendants"]


def descendants(pid: int) -> set[int]:
    """Every live descendant of ``pid`` (children, their children, ...); empty when ``pid``
    is gone."""
    try:
        return {c.pid for c in psutil.Process(pid).children(recursive=True)}
    except psutil.NoSuchProcess:
        return set()
