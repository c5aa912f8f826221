"""HIL_STATE_QUATERNION codec of the SITL processes: the compiled/fused paths against the
reference pair, timed in turn in one run (ratios, not absolute times, are what to quote).

    python benchmarks/bench_hil_codec.py [--calls 20000] [--repeats 3]

- vehicle side: ``HilStateEncoder`` (one compiled call, projection kept) against
  ``encode_hil_state`` of a ``NavState`` of views (what the vehicle process did before);
- autopilot side: ``HilStateDecoder`` (fields read straight from the parsed message) against
  ``decode_hil_state(HilBridge.hil_state(msg), *home)``.

Both pairs give the same bits (``tests/test_interface.py``). Measured (issue 24, session 10,
2 cores, load average 17-26): encode 10-13 us against 29-43 us (0.26-0.35x), decode
9.7-10.0 us against 17.1-20.5 us (0.47-0.58x) per call.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
from vtolftc.protocols.hil import (
    HilStateDecoder,
    HilStateEncoder,
    NavState,
    decode_hil_state,
    encode_hil_state,
)
from vtolftc.protocols.mavlink import make_codec

HOME = (45.5027, 9.1566, 120.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    if args.calls < 1 or args.repeats < 1:
        ap.error("--calls and --repeats must be positive")
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.normal(scale=50.0, size=6), [1.0, 0.0, 0.0, 0.0],
                        rng.normal(size=3), np.zeros(15)])
    enc = HilStateEncoder(*HOME)
    dec = HilStateDecoder(*HOME)
    codec = make_codec(1, 1)
    h = enc(4000, x, 12.0)
    msg = codec.parse_char(bytearray(codec.hil_state_quaternion_encode(
        h.time_usec, list(h.attitude_quaternion), h.rollspeed, h.pitchspeed, h.yawspeed,
        h.lat, h.lon, h.alt, h.vx, h.vy, h.vz, h.ind_airspeed, h.true_airspeed,
        0, 0, 0).pack(codec)))
    n = args.calls

    def timed(f: object) -> float:
        t0 = time.perf_counter()
        for _ in range(n):
            f()  # type: ignore[operator]
        return 1e6 * (time.perf_counter() - t0) / n

    pairs = {
        "encode": (lambda: enc(4000, x, 12.0),
                   lambda: encode_hil_state(NavState(4000, x[6:10], x[10:13], x[0:3], x[3:6],
                                                     12.0), *HOME)),
        "decode": (lambda: dec(msg),
                   lambda: decode_hil_state(HilBridge.hil_state(msg), *HOME)),
    }
    for r in range(args.repeats):
        for name, (new, old) in pairs.items():
            t_new, t_old = timed(new), timed(old)
            print(f"repeat {r + 1} {name}: {t_new:.2f} us against {t_old:.2f} us "
                  f"({t_new / t_old:.2f}x); load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
