"""The vehicle process against a scripted autopilot: HIL messages, lockstep, fault commands,
run folder, and the clean exit when the autopilot vanishes."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.interface import (
    HilState,
    NavState,
    decode_hil_state,
    encode_hil_state,
)
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.process import VehicleProcess
from vtolftc.protocols import open_link
from vtolftc.protocols.netutil import free_udp_port


class _Harness:
    """A VehicleProcess on a free UDP port, run in a thread; ``ap`` is the test's link."""

    def __init__(self, tmp_path, start: bool = True, **kw) -> None:
        port = free_udp_port()
        self.port = port
        self.proc = VehicleProcess(f"udp-server://127.0.0.1:{port}", out_dir=tmp_path,
                                   peer_timeout_s=5.0, connect_timeout_s=5.0, **kw)
        self.ap = open_link(f"udp-client://127.0.0.1:{port}", system_id=1, component_id=1)
        self.rc: list[int] = []
        self.thread = threading.Thread(target=lambda: self.rc.append(self.proc.run()),
                                       daemon=True)
        if start:
            self.start()

    def start(self) -> None:
        self.thread.start()
        self.ap.send(self.ap.codec.heartbeat_encode(22, 12, 0, 0, 3))

    def step_msgs(self, timeout: float = 3.0) -> dict[str, object]:
        """Messages of one state datagram, by type."""
        got: dict[str, object] = {}
        deadline = time.monotonic() + timeout
        while "HIL_STATE_QUATERNION" not in got and time.monotonic() < deadline:
            for m in self.ap.recv(0.2):
                got[m.get_type()] = m
        return got

    def controls(self, t_us: int, u: list[float] | None = None, armed: bool = True) -> None:
        c = [0.0] * 16 if u is None else list(u) + [0.0] * (16 - len(u))
        self.ap.send(self.ap.codec.hil_actuator_controls_encode(t_us, c, 128 if armed else 0, 1))

    def command(self, cmd: int, *p: float) -> list[object]:
        """Send a COMMAND_LONG; messages received until its ACK (and 0.1 s more)."""
        self.ap.recv(0.0)
        params = list(p) + [math.nan] * (7 - len(p))
        self.ap.send(self.ap.codec.command_long_encode(0, 0, cmd, 0, *params))
        out: list[object] = []
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline and not any(
                m.get_type() == "COMMAND_ACK" for m in out):
            out += self.ap.recv(0.1)
        out += self.ap.recv(0.1)
        return out

    def close(self) -> None:
        self.proc.running = False
        self.thread.join(5.0)
        self.ap.close()


@pytest.fixture()
def harness(tmp_path):
    h = _Harness(tmp_path)
    yield h
    h.close()


def test_state_datagram_and_lockstep(harness):
    got = harness.step_msgs()
    assert {"GPS_GLOBAL_ORIGIN", "HIL_SENSOR", "HIL_GPS", "HIL_STATE_QUATERNION"} <= set(got)
    sensor, state, origin = got["HIL_SENSOR"], got["HIL_STATE_QUATERNION"], \
        got["GPS_GLOBAL_ORIGIN"]
    assert sensor.time_usec == state.time_usec == 0 and sensor.fields_updated == 0x1FFF
    # at rest on the gear: the accelerometer reads -g (up) in FRD, pressure near the home's
    assert sensor.zacc == pytest.approx(-9.81, abs=0.05)
    assert 990.0 < sensor.abs_pressure < 1013.25
    home = (origin.latitude * 1e-7, origin.longitude * 1e-7, origin.altitude * 1e-3)
    # the HIL_STATE_QUATERNION is encode_hil_state of the truth, exactly as in-process
    ref = Vehicle()
    nav = NavState(0, ref.quaternion, ref.omega_body_rad_s, ref.position_ned_m,
                   ref.velocity_ned_m_s, ref.airspeed_m_s)
    h = ref.sensor_model.home
    expect = encode_hil_state(nav, h.lat_deg, h.lon_deg, h.alt_m)
    wire = HilState(state.time_usec, tuple(state.attitude_quaternion), state.rollspeed,
                    state.pitchspeed, state.yawspeed, state.lat, state.lon, state.alt, state.vx,
                    state.vy, state.vz, state.ind_airspeed, state.true_airspeed)
    assert wire == expect
    assert decode_hil_state(wire, *home).pos_ned_m[2] == pytest.approx(ref.position_ned_m[2],
                                                                       abs=1e-3)
    # lockstep: controls for another time do not advance the vehicle
    harness.controls(4000)
    late = harness.ap.recv(0.7)  # at most a resend of the t = 0 datagram
    assert all(m.time_usec == 0 for m in late if m.get_type() == "HIL_SENSOR")
    assert harness.proc.vehicle.time_usec == 0
    harness.controls(0)
    got = harness.step_msgs()
    assert got["HIL_SENSOR"].time_usec == 4000 and harness.proc.vehicle.time_usec == 4000
    assert "HIL_GPS" not in got  # 10 Hz: next one at 100 ms


def test_faults_applied_acknowledged_and_reported(harness):
    harness.step_msgs()
    names = harness.proc.airframe.actuator_names
    out = harness.command(59900, 101.0, 4.0, 0.5)
    ack = next(m for m in out if m.get_type() == "COMMAND_ACK")
    assert ack.command == 59900 and ack.result == 0
    st = next(m for m in out if m.get_type() == "FAULT_INJECTION_STATUS")
    assert st.motor_count == 10 and st.servo_count == 5
    assert st.motor_failure[3] == 100 and st.motor_loss[3] == pytest.approx(0.5)
    # servo 3 = elevator OFF (420, FAILURE_TYPE_OFF)
    out = harness.command(420, 102.0, 1.0, 3.0)
    assert next(m for m in out if m.get_type() == "COMMAND_ACK").result == 0
    harness.controls(0)
    harness.step_msgs()
    eff = harness.proc.vehicle.effectiveness
    assert eff[names.index("rotor_2b")] == 0.5 and eff[names.index("elevator")] == 0.0
    assert np.count_nonzero(eff != 1.0) == 2
    # a new fault on an actuator replaces the old one; loss 0 clears
    harness.command(59900, 101.0, 4.0, 0.2)
    harness.command(59900, 102.0, 3.0, 0.0)
    harness.controls(4000)
    harness.step_msgs()
    eff = harness.proc.vehicle.effectiveness
    assert eff[names.index("rotor_2b")] == 0.8 and eff[names.index("elevator")] == 1.0
    # refusals: bad instance, bad loss, unknown unit, unknown failure type
    for args, result in (((101.0, 11.0, 0.5), 2), ((101.0, 1.0, 1.5), 2),
                         ((105.0, 1.0, 0.5), 3)):
        out = harness.command(59900, *args)
        assert next(m for m in out if m.get_type() == "COMMAND_ACK").result == result
    out = harness.command(420, 101.0, 5.0, 1.0)
    assert next(m for m in out if m.get_type() == "COMMAND_ACK").result == 3


def test_run_folder_written_on_stop(harness, tmp_path):
    harness.step_msgs()
    harness.command(59900, 101.0, 0.0, 0.1)  # instance 0: every motor
    for k in range(5):
        harness.controls(4000 * k)
        harness.step_msgs()
    harness.close()
    truth = np.loadtxt(tmp_path / "vehicle_truth.csv", delimiter=",", skiprows=1)
    assert truth.shape[0] == 5 and truth[-1, 0] == pytest.approx(0.016)
    header = (tmp_path / "vehicle_truth.csv").read_text().splitlines()[0].split(",")
    assert truth[-1, header.index("eff_rotor_1a")] == pytest.approx(0.9)
    assert truth[-1, header.index("eff_elevator")] == 1.0
    events = [json.loads(x) for x in (tmp_path / "vehicle_events.jsonl").read_text().splitlines()]
    assert [e["event"] for e in events][-1] == "stop"
    assert any(e["event"] == "fault" and len(e["actuators"]) == 10 for e in events)
    summary = json.loads((tmp_path / "vehicle_summary.json").read_text())
    assert summary["steps"] == 5 and summary["link"]["dropped"] == 0
    assert summary["cpu_per_step_us"] > 0  # the load-independent cost of a step


def _wait(pred, timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.01)
    return pred()


def test_stray_senders_change_nothing(harness):
    """Garbage, valid HIL_ACTUATOR_CONTROLS (even with the autopilot's ids) and a fault
    command from another port than the pinned autopilot's: nothing is applied or answered."""
    harness.step_msgs()  # pinned on the harness's heartbeat
    proc = harness.proc
    assert proc.pinned == harness.ap.local_address
    stray = open_link(f"udp-client://127.0.0.1:{harness.port}", system_id=1, component_id=1)
    try:
        c = stray.codec
        for _ in range(20):
            stray.send(b"\xfd\x09garbage" * 3)
            stray.send(c.hil_actuator_controls_encode(0, [1.0] * 16, 128, 1))
            stray.send(c.command_long_encode(0, 0, 59900, 0, 101.0, 0.0, 1.0, 0, 0, 0, 0))
            stray.send(c.command_long_encode(0, 0, 420, 0, 102.0, 1.0, 0.0, 0, 0, 0, 0))
        assert _wait(lambda: proc.link.stats.dropped_foreign >= 80)
        assert stray.recv(0.3) == []  # the vehicle never answers a stranger
    finally:
        stray.close()
    assert proc.vehicle.time_usec == 0 and np.all(proc.commands == 0.0)
    assert proc.faults == {} and np.all(proc.vehicle.effectiveness == 1.0)
    # the pinned autopilot still flies it
    harness.controls(0, [0.25] * 15)
    assert harness.step_msgs()["HIL_SENSOR"].time_usec == 4000
    assert np.all(proc.commands == 0.25)


def test_other_ids_and_stale_controls_rejected(harness):
    harness.step_msgs()
    proc = harness.proc
    harness.controls(0, [0.5] * 15)
    harness.step_msgs()  # t = 4000
    # the same time again, an older one, one in the future: all refused
    for t in (0, 0, 8000):
        harness.controls(t, [0.9] * 15)
    assert _wait(lambda: proc.rejected["stale_controls"] >= 2
                 and proc.rejected["future_controls"] >= 1)
    assert np.all(proc.commands == 0.5) and proc.vehicle.time_usec == 4000
    # right ids matter too (same address, another component)
    other = harness.ap.codec
    other.srcComponent = 25
    harness.controls(4000, [0.7] * 15)
    assert _wait(lambda: proc.rejected["foreign_ids"] >= 1)
    other.srcComponent = 1
    assert np.all(proc.commands == 0.5) and proc.vehicle.time_usec == 4000


def test_latency_knob_delays_and_drops_controls(tmp_path):
    h = _Harness(tmp_path, hil_delay_ms=8.0)
    try:
        h.step_msgs()
        applied = []
        for k in range(4):
            h.controls(4000 * k, [0.1 * (k + 1)] * 15)
            h.step_msgs()
            applied.append(float(h.proc.commands[0]))
        # the controls answering t act from t + 8 ms: two control periods late
        assert applied == pytest.approx([0.0, 0.0, 0.1, 0.2])
    finally:
        h.close()
    h = _Harness(tmp_path / "loss", hil_loss=1.0)
    try:
        h.step_msgs()
        for k in range(3):
            h.controls(4000 * k, [0.6] * 15)
            h.step_msgs()
        assert np.all(h.proc.commands == 0.0) and h.proc.rejected["lost_injected"] == 3
        assert h.proc.vehicle.time_usec == 12000  # lockstep goes on with the old commands
    finally:
        h.close()


def test_output_watchdog_safe_output_in_real_time(tmp_path):
    """Real time: the autopilot stops sending controls; after --output-timeout the actuators
    get the safe output (all 0), not the last commands."""
    timeout = 0.4
    h = _Harness(tmp_path, lockstep=False, output_timeout_s=timeout)
    try:
        h.step_msgs()
        sent = time.monotonic()
        for _ in range(50):  # 0.2 s of controls from the newest state
            st = h.step_msgs()
            h.controls(int(st["HIL_SENSOR"].time_usec), [0.5] * 15)
            sent = time.monotonic()
        assert _wait(lambda: np.all(h.proc.commands == 0.5), 5.0)
        assert _wait(lambda: h.proc.watchdog_tripped, 10.0)
        tripped = time.monotonic()
        assert tripped - sent >= timeout
        assert tripped - sent < timeout + 2.0  # generous: a loaded machine
        assert np.all(h.proc.commands == 0.0)
        h.ap.send(h.ap.codec.heartbeat_encode(22, 12, 0, 0, 3))  # keep the peer alive
    finally:
        h.close()
    events = [json.loads(x) for x in (tmp_path / "vehicle_events.jsonl").read_text().splitlines()]
    assert any(e["event"] == "watchdog" and "stopped" in e["text"] for e in events)


def test_process_exits_when_the_autopilot_vanishes():
    port = free_udp_port()
    p = subprocess.Popen([sys.executable, "-m", "vtolftc.runners.processes.vehicle", "--link",
                          f"udp-server://127.0.0.1:{port}", "--peer-timeout", "1",
                          "--connect-timeout", "20"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    try:
        ap = open_link(f"udp-client://127.0.0.1:{port}", system_id=1, component_id=1)
        deadline = time.monotonic() + 20.0
        got = []
        while not got and time.monotonic() < deadline:
            ap.send(ap.codec.heartbeat_encode(22, 12, 0, 0, 3))
            got = ap.recv(0.5)
        assert got, "the vehicle never answered"
        ap.close()  # the autopilot vanishes
        rc = p.wait(timeout=20.0)
        err = p.stderr.read().decode()
        assert rc == 3 and "silent" in err
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(5.0)


def test_bad_arguments_exit_2():
    r = subprocess.run([sys.executable, "-m", "vtolftc.runners.processes.vehicle", "--link",
                        "udp-server://8.8.8.8:4560"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and "loopback" in r.stderr and "Traceback" not in r.stderr


def test_battery_integrated_off_the_critical_path_gives_the_same_values(tmp_path):
    """The power module is integrated after the send at steps whose datagram has no
    BATTERY_STATUS, before it when it has: every step is integrated once, in order, right
    after its physics (so from the same state as before), and every BATTERY_STATUS is built
    from the pack integrated over every step so far."""
    h = _Harness(tmp_path, start=False)
    calls: list[int] = []  # vehicle time at each integration
    built: list[tuple[int, int]] = []  # (vehicle time, integrations) at each BATTERY_STATUS
    step, msg = h.proc._step_battery, h.proc.encoder._battery_msg
    h.proc._step_battery = lambda: (calls.append(h.proc.vehicle.time_usec), step())[1]
    h.proc.encoder._battery_msg = lambda: (
        built.append((h.proc.vehicle.time_usec, len(calls))), msg())[1]
    h.start()
    try:
        for k in range(120):
            got = h.step_msgs()
            assert got["HIL_SENSOR"].time_usec == 4000 * k
            h.controls(4000 * k, [0.55] * 8 + [0.3, 0.3])
        h.step_msgs()
    finally:
        h.close()
    assert built == [(0, 0), (200_000, 50), (400_000, 100)]
    assert calls == [4000 * (k + 1) for k in range(120)]


def test_truth_log_writes_what_savetxt_writes(tmp_path):
    """The truth rows, formatted after the sends and written at the flush, are byte for byte
    ``np.savetxt``'s (``%.9g``), negative zero, NaN and infinities included."""
    from vtolftc.base.rotation import quat_to_euler
    from vtolftc.firmware_sim.vehicle.dynamics import N_RIGID
    from vtolftc.firmware_sim.vehicle.truth_log import TruthLog

    rng = np.random.default_rng(3)
    names = ["a", "b", "c"]
    log = TruthLog(tmp_path, names, flush_rows=1000)
    rows = []
    for k in range(7):
        x = rng.normal(size=N_RIGID + 3) * 10.0 ** rng.integers(-8, 8)
        x[6:10] /= np.linalg.norm(x[6:10])
        eff, cmd = rng.random(3), np.array([-0.0, np.nan, np.inf if k % 2 else -np.inf])
        log.record(4000 * k, x, 12.345678901 * k, eff, cmd)
        if k % 3 == 1:
            log.format_pending()  # as the process does after each send
        rows.append(np.concatenate(([4000 * k * 1e-6], x[0:6], quat_to_euler(x[6:10]),
                                    x[10:13], [12.345678901 * k], x[N_RIGID:], eff, cmd)))
    log.close()
    import io

    want = io.StringIO()
    np.savetxt(want, np.vstack(rows), delimiter=",", fmt="%.9g")
    lines = (tmp_path / "vehicle_truth.csv").read_text().splitlines(keepends=True)
    assert "".join(lines[1:]) == want.getvalue()


_WARM_SCRIPT = """
import json, types
import numpy as np
from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.autopilot.warmup import compiled_specialisations, new_specialisations
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.process import VehicleProcess

af = load_airframe()
VehicleProcess.warm_up(types.SimpleNamespace(airframe=af))
before = compiled_specialisations("vtolftc.firmware_sim.vehicle")
v = Vehicle(af)
u = np.zeros(af.n_actuators)
u[:8] = 0.55
for _ in range(25):                 # control steps as the process flies them
    v.step(u, 4)
    v.sensors()
print(json.dumps(new_specialisations(before, compiled_specialisations(
    "vtolftc.firmware_sim.vehicle"))))
"""


def test_warm_up_compiles_every_kernel_a_control_step_flies():
    """A fresh interpreter: after the vehicle process's warm-up, flying control steps as the
    process does loads or compiles no further numba specialisation (on a fresh install one
    would compile for seconds inside the first real-time steps, and the autopilot's HIL-loss
    failsafe would trip before take-off)."""
    out = subprocess.run([sys.executable, "-c", _WARM_SCRIPT], capture_output=True, text=True,
                         timeout=600, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == {}
