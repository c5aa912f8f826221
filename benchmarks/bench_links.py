"""Round-trip benchmark of the MAVLink links (UDP and zenoh, loopback only).

One round trip = the "vehicle" (this process) sends a HIL_SENSOR and waits for the
HIL_ACTUATOR_CONTROLS that the "autopilot" (a child process) sends back on receiving it: the
lockstep exchange of one simulated step. Prints median and p99 round-trip latency, round trips
per second and messages per second (two per round trip), plus the in-process cost of packing
and parsing the two messages without any transport.

    python benchmarks/bench_links.py [--n 5000] [--transport udp|zenoh|both]

For reference, a 4 ms step at 20x real time needs 5000 round trips/s (200 us per step for
everything: link, physics and control).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import statistics
import time
from typing import Any

from vtolftc.protocols.link import Link, open_link
from vtolftc.protocols.mavlink import make_codec
from vtolftc.protocols.netutil import free_tcp_port


def _hil_sensor(codec: Any, t_us: int) -> Any:
    return codec.hil_sensor_encode(
        t_us, 0.1, -0.2, -9.81, 0.01, 0.02, 0.03, 0.21, 0.01, 0.43, 1013.25, 0.1, 1010.0, 20.0,
        0x1FFF, 0,
    )


def _controls(codec: Any, t_us: int) -> Any:
    return codec.hil_actuator_controls_encode(t_us, [0.5] * 16, 128, 1)


def _echo(url: str, ready: Any, n_total: int) -> None:
    """Child: answer every HIL_SENSOR with HIL_ACTUATOR_CONTROLS carrying its time_usec."""
    with open_link(url, system_id=1, component_id=1) as link:
        ready.send(link.local_address)
        answered = 0
        deadline = time.monotonic() + 120.0
        while answered < n_total and time.monotonic() < deadline:
            for msg in link.recv(0.5):
                if msg.get_type() == "HIL_SENSOR":
                    link.send(_controls(link.codec, msg.time_usec))
                    answered += 1
        time.sleep(0.2)  # let the last frames leave before the session closes


def _round_trips(link: Link, n: int) -> list[float]:
    codec = link.codec
    lat: list[float] = []
    t_us = 0
    for _ in range(n):
        t_us += 4000
        msg = _hil_sensor(codec, t_us)
        t0 = time.perf_counter()
        link.send(msg)
        while True:
            got = link.recv(2.0)
            if not got:
                raise TimeoutError("no HIL_ACTUATOR_CONTROLS within 2 s")
            if any(m.get_type() == "HIL_ACTUATOR_CONTROLS" and m.time_usec == t_us for m in got):
                break
        lat.append(time.perf_counter() - t0)
    return lat


def _report(name: str, lat: list[float], wall: float) -> None:
    lat_us = sorted(x * 1e6 for x in lat)
    p99 = lat_us[min(len(lat_us) - 1, int(0.99 * len(lat_us)))]
    rts = len(lat) / wall
    print(
        f"{name:6s} n={len(lat):6d}  median {statistics.median(lat_us):7.1f} us  "
        f"p99 {p99:7.1f} us  {rts:8.0f} round trips/s  {2 * rts:8.0f} msgs/s  "
        f"({rts / 250.0:5.1f}x real time at 4 ms/step, link only)"
    )


def bench_transport(kind: str, n: int, warmup: int) -> None:
    """Run one transport: child echo process, then timed round trips."""
    ctx = mp.get_context("spawn")
    parent_end, child_end = ctx.Pipe()
    if kind == "udp":
        child_url = "udp-server://127.0.0.1:0"
    else:
        port = free_tcp_port()
        child_url = f"zenoh://bench/hil/down?listen=tcp/127.0.0.1:{port}"
    proc = ctx.Process(target=_echo, args=(child_url, child_end, n + warmup), daemon=True)
    proc.start()
    try:
        if not parent_end.poll(30.0):
            raise TimeoutError("echo process did not start")
        addr = parent_end.recv()
        if kind == "udp":
            url = f"udp-client://127.0.0.1:{addr[1]}"
        else:
            url = f"zenoh://bench/hil/up?connect=tcp/127.0.0.1:{port}"
        with open_link(url, system_id=1, component_id=200) as link:
            if not link.wait_ready(10.0):
                raise TimeoutError("link not ready")
            _round_trips(link, warmup)
            t0 = time.perf_counter()
            lat = _round_trips(link, n)
            wall = time.perf_counter() - t0
            _report(kind, lat, wall)
    finally:
        proc.join(10.0)
        if proc.is_alive():
            proc.kill()
            proc.join(2.0)


def bench_codec(n: int) -> None:
    """Pack + parse of both messages in-process: the floor under any transport."""
    a = make_codec(1, 200)
    b = make_codec(1, 1)
    from vtolftc.protocols.link import Link, Transport

    class _Null(Transport):
        kind = "null"

        def send_bytes(self, data: bytes) -> bool:
            return True

        def recv_datagrams(self, timeout_s: float | None) -> list[bytes]:
            return []

        def ready(self) -> bool:
            return True

        def close(self) -> None:
            pass

    link = Link(_Null(), codec=b)
    t0 = time.perf_counter()
    out: list[Any] = []
    for i in range(n):
        s = _hil_sensor(a, i).pack(a)
        c = _controls(b, i).pack(b)
        link._parse_datagram(s, out)
        link._parse_datagram(c, out)
        out.clear()
    dt = (time.perf_counter() - t0) / n
    print(f"codec  pack+parse HIL_SENSOR + HIL_ACTUATOR_CONTROLS: {dt * 1e6:6.1f} us per pair")


def main() -> None:
    """CLI entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=5000, help="timed round trips per transport")
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--transport", choices=["udp", "zenoh", "both"], default="both")
    args = ap.parse_args()
    bench_codec(min(args.n, 5000))
    for kind in ("udp", "zenoh") if args.transport == "both" else (args.transport,):
        bench_transport(kind, args.n, args.warmup)


if __name__ == "__main__":
    main()
