"""``--cpu N`` of the SITL process programs (:mod:`vtolftc.runners.processes.affinity`): once
applied (when the process is compiled and ready), every thread of the process and every thread
started afterwards runs on CPU N only; an invalid N is one line and exit status 2; a refusal by
the system is one line and the process stays unpinned (all threads, none half-way)."""

from __future__ import annotations

import errno
import io
import os
import subprocess
import sys

import pytest
from support.procs import sitl_command_lines, zenoh_probe

from vtolftc.runners.processes import affinity
from vtolftc.runners.processes.affinity import apply_cpu, check_cpu, thread_cpus
from vtolftc.runners.sitl import SitlConfig, SitlRun

_CHILD = """
import os, sys, threading
from vtolftc.runners.processes.affinity import apply_cpu
cpu = int(sys.argv[1])
mask = lambda: sorted(os.sched_getaffinity(0))   # the calling thread's
go, seen = threading.Event(), {}
def early():
    go.wait(); seen["early"] = mask()
th = threading.Thread(target=early); th.start()   # a thread that exists before the call
ok = apply_cpu(cpu, "probe", sys.stdout)
go.set(); th.join()
later = threading.Thread(target=lambda: seen.update(later=mask())); later.start(); later.join()
print("main", *mask()); print("early", *seen["early"]); print("later", *seen["later"])
print("ok", ok)
"""

_CPUS = sorted(os.sched_getaffinity(0))


@pytest.mark.parametrize("n, valid", [(-1, True), (_CPUS[0], True), (_CPUS[-1], True),
                                      (max(_CPUS) + 1, False), (-2, False), (4096, False)])
def test_valid_cpus_are_off_and_those_this_process_may_use(n, valid):
    assert (check_cpu(n) is None) == valid


@pytest.mark.skipif(len(_CPUS) < 2, reason="pinning is only visible with 2 CPUs or more")
@pytest.mark.parametrize("cpu", [_CPUS[0], _CPUS[-1]])
def test_every_thread_of_the_process_runs_on_the_cpu(cpu):
    """The threads that exist at the call (the autopilot's ground-station threads) and those
    started afterwards."""
    out = subprocess.run([sys.executable, "-c", _CHILD, str(cpu)], capture_output=True,
                         text=True, timeout=60, check=True).stdout.splitlines()
    assert out == [f"probe: pinned to CPU {cpu} (2 threads)", f"main {cpu}", f"early {cpu}",
                   f"later {cpu}", "ok True"]


def test_zenoh_runtime_threads_on_their_own_cpu_only_when_asked():
    """``--zenoh-cpu M``: zenoh's tokio workers (rx/tx/app/acc/net-N) on M, every other thread
    (Python's, rerun's ``tokio-rt-worker``, look-alike names) on the process's CPU."""
    names = {1: "python", 2: "rx-0", 3: "tx-0", 4: "app-0", 5: "acc-1", 6: "net-2",
             7: "tokio-rt-worker", 8: "zenoh-recv-watchdog", 9: "rx-", 10: "", 11: "rx-1x"}
    zenoh = {2, 3, 4, 5, 6}
    assert thread_cpus(0, 1, names) == {t: 1 if t in zenoh else 0 for t in names}
    assert thread_cpus(3, -1, names) == dict.fromkeys(names, 3)


@pytest.mark.skipif(len(_CPUS) < 2, reason="pinning is only visible with 2 CPUs or more")
def test_a_zenoh_process_puts_zenoh_threads_on_the_zenoh_cpu():
    cpu, zcpu = _CPUS[-1], _CPUS[0]
    got = zenoh_probe(f"affinity.apply_cpu({cpu}, {zcpu})", "*sorted(os.sched_getaffinity(tid))")
    assert got.applied and got.linked, got.lines
    assert got.zenoh and got.others, got.threads
    assert all(t[1:] == [str(zcpu)] for t in got.zenoh), got.threads
    assert all(t[1:] == [str(cpu)] for t in got.others), got.threads
    assert got.lines[0] == (f"probe: pinned to CPU {cpu} ({len(got.threads)} threads), zenoh's "
                            f"{len(got.zenoh)} runtime threads to CPU {zcpu}"), got.lines[0]


def test_off_does_nothing(monkeypatch):
    def never(*a):
        raise AssertionError("sched_setaffinity called for --cpu -1")

    monkeypatch.setattr(os, "sched_setaffinity", never)
    log = io.StringIO()
    assert apply_cpu(-1, "probe", log) is False
    assert log.getvalue() == ""


def test_refused_is_one_line_and_no_thread_stays_pinned(monkeypatch):
    """The system refuses the second thread (EINVAL: the cpuset changed): the first one is put
    back on its previous set and the process runs unpinned."""
    calls: list[tuple[int, set[int]]] = []

    def setaff(tid, cpus):
        calls.append((tid, set(cpus)))
        if len(calls) == 2:
            raise OSError(errno.EINVAL, "Invalid argument")

    monkeypatch.setattr(os, "listdir", lambda p: ["11", "12", "13"])
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(os, "sched_setaffinity", setaff)
    log = io.StringIO()
    assert affinity.apply_cpu(1, "probe", log) is False
    assert log.getvalue() == "probe: --cpu 1 not applied (Invalid argument): not pinned\n"
    assert calls[:2] == [(11, {1}), (12, {1})]
    assert calls[2:] == [(11, {0, 1}), (12, {0, 1}), (13, {0, 1})]


@pytest.mark.parametrize("program, args", [
    ("vehicle", ["--link", "udp-server://127.0.0.1:9"]),
    ("autopilot", ["--hil-link", "udp-client://127.0.0.1:9"])])
@pytest.mark.parametrize("flag, value, message", [
    ("--cpu", "4096", f"--cpu 4096: expected -1 (off) or a CPU this process may use: {_CPUS}"),
    ("--zenoh-cpu", "4096",
     f"--zenoh-cpu 4096: expected -1 (off) or a CPU this process may use: {_CPUS}"),
    ("--trace-steps", "-3", "--trace-steps -3: expected N >= 0 steps (0 = off)")])
def test_bad_cpu_or_trace_steps_is_one_line_and_exit_2(program, args, flag, value, message):
    p = subprocess.run([sys.executable, "-m", f"vtolftc.runners.processes.{program}", *args,
                        flag, value], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [f"{program}: error: {message}"]


def test_cpus_reach_each_process_and_only_when_asked(tmp_path, monkeypatch):
    """``SitlConfig.autopilot_cpu`` / ``vehicle_cpu`` are passed to their own program's command
    line; the default (-1) passes nothing. No process is started."""
    for ap_cpu, v_cpu in ((-1, -1), (0, 1), (1, -1), (-1, 0)):
        argv = sitl_command_lines(monkeypatch, SitlConfig(
            out_dir=tmp_path / f"{ap_cpu}{v_cpu}", autopilot_cpu=ap_cpu, vehicle_cpu=v_cpu))
        for name, want in (("autopilot", ap_cpu), ("vehicle", v_cpu)):
            args = argv[name]
            got = int(args[args.index("--cpu") + 1]) if "--cpu" in args else -1
            assert got == want and args.count("--cpu") <= 1, (name, args)


def test_zenoh_peer_cpu_puts_each_zenoh_runtime_on_the_other_cpu(tmp_path, monkeypatch):
    """``SitlConfig.zenoh_peer_cpu``: the vehicle's zenoh threads on the autopilot's CPU and
    the reverse (zenoh only; refused unless both processes are pinned). No process starts."""
    for transport in ("zenoh", "udp"):
        argv = sitl_command_lines(monkeypatch, SitlConfig(
            out_dir=tmp_path / transport, transport=transport, autopilot_cpu=0, vehicle_cpu=1,
            zenoh_peer_cpu=True))
        got = {name: args[args.index("--zenoh-cpu") + 1] if "--zenoh-cpu" in args else None
               for name, args in argv.items()}
        want = {"vehicle": "0", "autopilot": "1"} if transport == "zenoh" else dict.fromkeys(
            argv)
        assert got == want, (transport, argv)
    argv = sitl_command_lines(monkeypatch, SitlConfig(
        out_dir=tmp_path / "off", transport="zenoh", autopilot_cpu=0, vehicle_cpu=1))
    assert not any("--zenoh-cpu" in args for args in argv.values())
    for ap_cpu, v_cpu in ((-1, -1), (0, -1), (-1, 1)):
        with pytest.raises(ValueError, match="zenoh_peer_cpu needs both processes pinned"):
            SitlRun(SitlConfig(out_dir=tmp_path / "x", transport="zenoh", zenoh_peer_cpu=True,
                               autopilot_cpu=ap_cpu, vehicle_cpu=v_cpu))


@pytest.mark.skipif(len(_CPUS) < 2, reason="pinning is only visible with 2 CPUs or more")
@pytest.mark.parametrize("program, link", [
    ("vehicle", ["--link", "zenoh://ds1/hil/up?listen=tcp/127.0.0.1:{port}",
                 "--connect-timeout", "1"]),
    ("autopilot", ["--hil-link", "zenoh://ds1/hil/down?connect=tcp/127.0.0.1:{port}",
                   "--no-default-gcs", "--no-warmup", "--max-wall", "1"])])
def test_the_programs_put_zenoh_threads_on_the_zenoh_cpu(program, link):
    """``--cpu N --zenoh-cpu M`` of both programs over a zenoh HIL link: one line."""
    from vtolftc.protocols.netutil import free_tcp_port

    port = free_tcp_port()
    p = subprocess.run([sys.executable, "-m", f"vtolftc.runners.processes.{program}",
                        *(a.format(port=port) for a in link), "--cpu", str(_CPUS[-1]),
                        "--zenoh-cpu", str(_CPUS[0])],
                       capture_output=True, text=True, timeout=120)
    pinned = [ln for ln in p.stderr.splitlines() if "CPU" in ln]
    assert len(pinned) == 1, p.stderr
    assert pinned[0].startswith(f"{program}: pinned to CPU {_CPUS[-1]} ("), pinned
    assert pinned[0].endswith(f"runtime threads to CPU {_CPUS[0]}"), pinned


@pytest.mark.skipif(len(_CPUS) < 2, reason="pinning is only visible with 2 CPUs or more")
@pytest.mark.parametrize("program, args, rc", [
    ("vehicle", ["--link", "udp-server://127.0.0.1:{port}", "--connect-timeout", "1"], 3),
    ("autopilot", ["--hil-link", "udp-client://127.0.0.1:{port}", "--no-default-gcs",
                   "--no-warmup", "--max-wall", "1"], 0)])
def test_the_programs_pin_themselves_once_ready(program, args, rc):
    """The vehicle after compiling its kernels, the autopilot (``--no-warmup``) before its
    loop: one line each, then the run goes on (no peer here: it ends by its timeout)."""
    from vtolftc.protocols.netutil import free_udp_port

    port = free_udp_port()
    p = subprocess.run([sys.executable, "-m", f"vtolftc.runners.processes.{program}",
                        *(a.format(port=port) for a in args), "--cpu", str(_CPUS[-1])],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == rc, p.stderr
    lines = p.stderr.splitlines()
    pinned = [ln for ln in lines if "CPU" in ln]
    assert len(pinned) == 1 and pinned[0].startswith(
        f"{program}: pinned to CPU {_CPUS[-1]} ("), lines
