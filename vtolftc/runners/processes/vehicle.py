"""The vehicle process program.

    python -m vtolftc.runners.processes.vehicle --link udp-server://127.0.0.1:4560 [--lockstep]
        [--realtime] [--airframe FILE] [--seed N] [--noise] [--duration S] [--out DIR]
        [--output-timeout S] [--hil-delay-ms MS] [--hil-loss P] [--rt-priority N]
        [--cpu N] [--trace-steps N]

What it sends and accepts, the autopilot pinning, the output watchdog and the latency knob are
documented in :mod:`vtolftc.firmware_sim.vehicle.process`. With ``VTOLFTC_HIL_KEY`` (64
hexadecimal digits) in the environment the HIL link is signed: only an autopilot with the same
key is pinned (:mod:`vtolftc.protocols.hil_signing`). Exit status: 0 done or stopped by
signal (SIGTERM, SIGINT), 2 bad arguments, 3 autopilot lost.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from pathlib import Path
from typing import Any

from vtolftc.airframe.loader import AirframeError, load_airframe
from vtolftc.firmware_sim.vehicle.process import VehicleProcess
from vtolftc.protocols.hil_signing import hil_signing_from_env
from vtolftc.runners.processes.affinity import add_cpu_argument, apply_cpu, check_cpu
from vtolftc.runners.processes.priority import (
    add_rt_priority_argument,
    apply_rt_priority,
    check_rt_priority,
)
from vtolftc.runners.processes.procstate import enable_stack_dump
from vtolftc.telemetry.step_parts import check_trace_steps

__all__ = ["main"]


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="python -m vtolftc.runners.processes.vehicle",
        description="Simulated vehicle behind a MAVLink HIL link (PX4 SITL style).")
    ap.add_argument("--link", required=True,
                    help="HIL link URL, e.g. udp-server://127.0.0.1:4560 or "
                         "zenoh://ds1/hil/up?listen=tcp/127.0.0.1:7447")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="lockstep", action="store_true", default=True,
                      help="advance only when the controls for the last step arrived (default)")
    mode.add_argument("--realtime", dest="lockstep", action="store_false",
                      help="free-running at wall-clock pace")
    ap.add_argument("--airframe", type=Path, default=None, help="airframe TOML (default DS-1)")
    ap.add_argument("--seed", type=int, default=0, help="sensor-noise seed (default 0)")
    ap.add_argument("--noise", action="store_true", help="typical sensor noise (default none)")
    ap.add_argument("--duration", type=float, default=None,
                    help="stop after this many simulated seconds (default: run until stopped)")
    ap.add_argument("--out", type=Path, default=None, help="run folder for truth telemetry")
    ap.add_argument("--peer-timeout", type=float, default=5.0,
                    help="stop if the autopilot is silent this long, wall seconds (default 5)")
    ap.add_argument("--connect-timeout", type=float, default=60.0,
                    help="wait this long for the autopilot at start, wall seconds (default 60)")
    ap.add_argument("--output-timeout", type=float, default=0.5,
                    help="real time: no controls this long (wall s) -> safe output (rotors and "
                         "pushers stopped, surfaces neutral); 0 = off (default 0.5)")
    ap.add_argument("--hil-delay-ms", type=float, default=0.0,
                    help="apply the controls this many ms (simulated time) after they arrive "
                         "(injected one-way latency; default 0)")
    ap.add_argument("--hil-loss", type=float, default=0.0,
                    help="drop this fraction of the controls (0..1, seeded by --seed; "
                         "default 0)")
    ap.add_argument("--gps-rate", type=float, default=10.0, help="HIL_GPS rate in Hz (10)")
    ap.add_argument("--allow-remote", action="store_true",
                    help="allow non-loopback link addresses (containers on separate hosts)")
    ap.add_argument("--parent-pid", type=int, default=None,
                    help="stop when this process is gone (used by vtolftc sitl)")
    ap.add_argument("--spin-us", type=float, default=0.0,
                    help="lockstep: busy-poll this long for the controls before sleeping "
                         "(faster on idle cores, costs CPU; default 0)")
    add_rt_priority_argument(ap)
    add_cpu_argument(ap)
    ap.add_argument("--trace-steps", type=int, default=0, metavar="N",
                    help="record the wall / CPU time of each part of the first N lockstep "
                         "steps into step_trace.npz in the run folder (StepParts; read by "
                         "benchmarks/bench_sitl.py --trace); default 0 = off")
    return ap.parse_args(argv)


class _Vehicle(VehicleProcess):
    """The vehicle process that takes its real-time priority (``--rt-priority``) and its CPU
    (``--cpu``) once its kernels are compiled, before it waits for the autopilot (see
    :mod:`vtolftc.runners.processes.priority` for why not before)."""

    rt_priority = 0
    cpu = -1
    zenoh_cpu = -1

    def warm_up(self) -> None:
        """Compile (:meth:`VehicleProcess.warm_up`), then apply the priority and the CPU."""
        super().warm_up()
        apply_rt_priority(self.rt_priority, "vehicle", sys.stderr)
        apply_cpu(self.cpu, "vehicle", sys.stderr, self.zenoh_cpu)


def main(argv: list[str] | None = None) -> int:
    """Run the vehicle process (see the module docstring); returns the exit status."""
    args = _parse_args(argv)
    for name, val in (("--duration", args.duration), ("--peer-timeout", args.peer_timeout),
                      ("--connect-timeout", args.connect_timeout)):
        if val is not None and not (math.isfinite(val) and val > 0):
            print(f"vehicle: error: {name} {val!r}: expected a positive number of seconds",
                  file=sys.stderr)
            return 2
    for name, val, hi in (("--output-timeout", args.output_timeout, math.inf),
                          ("--hil-delay-ms", args.hil_delay_ms, 10_000.0),
                          ("--hil-loss", args.hil_loss, 1.0)):
        if not (math.isfinite(val) and 0.0 <= val <= hi):
            print(f"vehicle: error: {name} {val!r}: expected a number in [0, {hi:g}]",
                  file=sys.stderr)
            return 2
    for bad in (check_rt_priority(args.rt_priority), check_cpu(args.cpu),
                check_cpu(args.zenoh_cpu, "--zenoh-cpu"),
                check_trace_steps(args.trace_steps)):
        if bad is not None:
            print(f"vehicle: error: {bad}", file=sys.stderr)
            return 2
    try:
        signing = hil_signing_from_env()
        airframe = load_airframe(args.airframe) if args.airframe else load_airframe()
        proc = _Vehicle(
            args.link, airframe=airframe, lockstep=args.lockstep, seed=args.seed,
            noise=args.noise, duration_s=args.duration, out_dir=args.out,
            peer_timeout_s=args.peer_timeout, connect_timeout_s=args.connect_timeout,
            gps_rate_hz=args.gps_rate, allow_remote=args.allow_remote,
            parent_pid=args.parent_pid, output_timeout_s=args.output_timeout,
            hil_delay_ms=args.hil_delay_ms, hil_loss=args.hil_loss, signing=signing)
        proc.spin_s = max(0.0, args.spin_us) * 1e-6
        proc.rt_priority = args.rt_priority
        proc.cpu = args.cpu
        proc.zenoh_cpu = args.zenoh_cpu
        proc.parts.enable_trace(args.trace_steps)
    except (AirframeError, ValueError, OSError) as exc:
        print(f"vehicle: error: {exc}", file=sys.stderr)
        return 2

    def stop(_sig: int, _frame: Any) -> None:
        proc.running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    enable_stack_dump()  # SitlRun.stop's evidence when this process does not end
    rc = proc.run()
    if args.out is not None:
        proc.parts.save_trace(args.out / "step_trace.npz")
    st = proc.link.stats
    print(f"vehicle: stopped at t = {proc.vehicle.time_usec * 1e-6:.3f} s after {proc.steps} "
          f"steps; link dropped {st.dropped} (garbage {st.dropped_garbage}, crc "
          f"{st.dropped_crc}, truncated {st.dropped_truncated}, other senders "
          f"{st.dropped_foreign}); rejected {proc.rejected}", file=sys.stderr, flush=True)
    return rc


if __name__ == "__main__":
    sys.exit(main())
