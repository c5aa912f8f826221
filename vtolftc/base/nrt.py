"""Array views that compiled kernels pass to their callees without reference counting.

numba counts references to an array's memory (its ``meminfo``) and, at every call of one
compiled function from another, increments the count of each array argument on entry and
decrements it on exit: two atomic read-modify-write instructions per array per call (~20
cycles each, uncontended), which numba's pruning pass leaves in place in a function with
several branches. A kernel that calls a small function many times with many arrays (the
vehicle's RK4 calls its 20-array derivative 16 times per control step: 36 atomic operations a
call, 65 % of that kernel's samples in ``perf``) spends more on counting than on arithmetic.

:func:`borrowed` returns a view with no ``meminfo``: numba's count functions return at once
on it. The view does not keep the memory alive; it is valid while the array it was taken from
is alive, e.g. a kernel's own arguments (its caller holds them for the whole call) or an
array the kernel keeps to its end (:func:`keep_alive`).
"""

from __future__ import annotations

from numba import njit
from numba.core import cgutils, types
from numba.extending import intrinsic

__all__ = ["borrowed", "keep_alive"]


@intrinsic
def borrowed(typingctx, arr):  # pragma: no cover - compiled
    """The array ``arr`` (same data pointer, shape, strides and numba type) without its
    ``meminfo`` and ``parent``: passing it to a compiled callee counts no reference. Only
    valid while ``arr`` is alive (see the module docstring)."""
    if not isinstance(arr, types.Array):
        return None

    def codegen(context, builder, signature, args):
        src = context.make_array(arr)(context, builder, value=args[0])
        out = context.make_array(arr)(context, builder, value=src._getvalue())
        out.meminfo = cgutils.get_null_value(out.meminfo.type)
        out.parent = cgutils.get_null_value(out.parent.type)
        return out._getvalue()

    return arr(arr), codegen


@njit(cache=True)
def keep_alive(a):  # pragma: no cover - compiled
    """Nothing: a use of ``a`` that keeps it (and the memory of views :func:`borrowed` from
    it) alive up to this point of a compiled function (numba releases an array after its
    last use)."""
    return None
