"""DecimatingBuffer against the brute-force answer: every stride-th row of the whole stream."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.telemetry.plotbuffer import DecimatingBuffer


@pytest.mark.parametrize(("n", "cap"), [(0, 4), (3, 4), (4, 4), (5, 4), (17, 4), (1000, 64),
                                        (4096, 64), (4097, 64), (100_003, 256)])
def test_keeps_every_stride_th_row_of_the_whole_stream(n: int, cap: int) -> None:
    x = np.arange(n, dtype=float)
    b = DecimatingBuffer(2, capacity=cap)
    for v in x:
        b.add((v, -v))
    stride = 1
    while -(-n // stride) > cap:  # the smallest power of two whose decimation fits
        stride *= 2
    assert b.stride == stride
    assert np.array_equal(b.rows()[:, 0], x[::stride])
    assert np.array_equal(b.rows()[:, 1], -x[::stride])
    assert cap // 2 <= len(b) <= cap or n < cap // 2


def test_capacity_must_be_even() -> None:
    with pytest.raises(ValueError):
        DecimatingBuffer(1, capacity=5)
