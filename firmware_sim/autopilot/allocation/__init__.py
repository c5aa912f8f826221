"""Control allocation: map a virtual command ``v`` onto the actuators ``u`` with ``B u ≈ v``.

Split as PX4 splits it: the effectiveness ``B(V)`` lives apart
(``vtolftc.firmware_sim.autopilot.effectiveness``); ``interface`` holds the result, status,
statistics, per-step bounds and the ``Allocator`` protocol; ``wls`` the weighted least-squares
problem the QP algorithms share; one file per algorithm:

``active_set.ActiveSetAllocator``
    The compiled active-set solver alone, warm-started from the previous command: the
    allocator that flies (the autopilot's default).
``qp_osqp.QPAllocator``
    OSQP (ADMM) finished by the compiled active-set solver: an independent comparison for
    the tests and ``benchmarks/bench_allocation.py``; needs the optional ``osqp`` extra.
``pseudo_inverse.PseudoInverseAllocator``
    PX4's pseudo-inverse + sequential desaturation (baseline, and the QP fallback).

Conventions: ``v`` in SI (N, N m; NED/FRD), ``u`` normalised; axis layout ``AXES_5``.
"""

from vtolftc.firmware_sim.autopilot.allocation.active_set import ActiveSetAllocator, box_qp
from vtolftc.firmware_sim.autopilot.allocation.interface import (
    AXES_5,
    AllocationResult,
    AllocationStatus,
    Allocator,
    AllocatorStats,
    shortfall_mask,
    step_bounds,
)
from vtolftc.firmware_sim.autopilot.allocation.pseudo_inverse import PseudoInverseAllocator
from vtolftc.firmware_sim.autopilot.allocation.wls import WLSAllocator

__all__ = [
    "AXES_5",
    "ActiveSetAllocator",
    "AllocationResult",
    "AllocationStatus",
    "Allocator",
    "AllocatorStats",
    "PseudoInverseAllocator",
    "QPAllocator",
    "WLSAllocator",
    "box_qp",
    "shortfall_mask",
    "step_bounds",
]


def __getattr__(name: str) -> object:
    """``QPAllocator`` on first use (PEP 562): its module imports scipy.sparse (0.5-0.7 s of
    a fresh process), which the flown allocator never needs."""
    if name == "QPAllocator":
        from vtolftc.firmware_sim.autopilot.allocation.qp_osqp import QPAllocator

        return QPAllocator
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
