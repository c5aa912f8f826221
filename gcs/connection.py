"""The ground station's link to the autopilot: open it, receive, send, wait for answers.

:class:`GcsConnection` owns one MAVLink link (any URL of :func:`protocols.open_link`) and a
receive thread that sends a 1 Hz GCS HEARTBEAT, feeds the :class:`.telemetry.TelemetryCache`
with every message of the autopilot (``target``, system 1 component 1 by default), wakes the
waiters whose predicate matches a message (:meth:`GcsConnection.request`) and hands every
received message to the listeners. The command, parameter and mission clients
(:mod:`.commands`, :mod:`.params`, :mod:`.mission`) build on it; :class:`.client.GroundStation`
is all of them.
"""

from __future__ import annotations

import contextlib
import errno
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Self

from vtolftc.gcs.actuators import ActuatorTable
from vtolftc.gcs.telemetry import TelemetryCache, VehicleSnapshot
from vtolftc.protocols import SigningConfig, open_link
from vtolftc.protocols.generated import constants as mav

__all__ = ["GcsConnection", "GcsError", "GcsTimeout", "Waiter"]


class GcsError(RuntimeError):
    """Not connected, bad argument, refused parameter ...: the message says what to do."""


class GcsTimeout(GcsError):  # noqa: N818 - name fixed by the API
    """No answer (heartbeat, PARAM_VALUE, condition) in time."""


@dataclass
class Waiter:
    """A message awaited by a request: set when ``predicate`` holds for a received one."""

    predicate: Callable[[Any], bool]
    event: threading.Event = field(default_factory=threading.Event)
    message: Any = None


class GcsConnection:
    """A MAVLink ground-station link to the autopilot (module docstring).

    Parameters
    ----------
    url
        link URL (``udp-server://127.0.0.1:14550`` = QGroundControl's port; a zenoh URL
        such as ``zenoh://ds1/gcs/down?connect=tcp/127.0.0.1:7447`` works the same).
    system_id, component_id
        this ground station's ids (255 / 190 by convention).
    signing
        MAVLink 2 signing (:class:`protocols.SigningConfig`) for outgoing frames.
    target_system, target_component
        the autopilot's ids.
    actuators
        actuator numbering for fault injection (default: the shipped DS-1's).
    allow_remote
        allow a link to a non-loopback address.

    The receive thread starts at once; :meth:`connect` also waits for the first heartbeat.
    """

    def __init__(
        self,
        url: str = "udp-server://127.0.0.1:14550",
        *,
        system_id: int = 255,
        component_id: int = 190,
        signing: SigningConfig | None = None,
        target_system: int = 1,
        target_component: int = 1,
        actuators: ActuatorTable | None = None,
        allow_remote: bool = False,
    ) -> None:
        try:
            self._link = open_link(url, system_id=system_id, component_id=component_id,
                                   signing=signing, allow_remote=allow_remote)
        except (ValueError, OSError) as exc:
            hint = ""
            if isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE:
                hint = (" (another ground station, e.g. the dashboard or QGroundControl, "
                        "already listens there: use the autopilot's other port, "
                        "udp-server://127.0.0.1:14540, or one given with --gcs-link)")
            raise GcsError(f"cannot open ground-station link {url!r}: {exc}{hint}") from exc
        self.url = url
        self.target = (int(target_system), int(target_component))
        self.actuators = actuators
        """Actuator numbering for fault injection (None: the shipped DS-1's)."""
        self.cache = TelemetryCache()
        """What is known of the autopilot (:mod:`.telemetry`)."""
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._listeners: list[Callable[[Any], None]] = []
        self._waiters: list[Waiter] = []
        self._closed = False
        self._thread = threading.Thread(target=self._rx_loop, name="gcs-rx", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ lifetime
    @classmethod
    def connect(cls, url: str = "udp-server://127.0.0.1:14550", timeout_s: float = 10.0,
                **kw: Any) -> Self:
        """Open the link, start the receive thread, wait for the autopilot's first heartbeat.

        Raises
        ------
        GcsError
            the link cannot be opened (bad URL, port in use).
        GcsTimeout
            no heartbeat from the autopilot within ``timeout_s``.
        """
        gs = cls(url, **kw)
        if not gs.cache.heartbeat_event.wait(timeout_s):
            gs.close()
            raise GcsTimeout(
                f"no heartbeat from system {gs.target[0]} component {gs.target[1]} on {url} "
                f"within {timeout_s:g} s: is the autopilot running and sending there?")
        return gs

    def close(self) -> None:
        """Stop the receive thread and close the link. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._link.close()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def link(self) -> Any:
        """The underlying :class:`protocols.Link` (counters in ``link.stats``)."""
        return self._link

    @property
    def codec(self) -> Any:
        """The link's MAVLink codec (``*_encode`` of every message)."""
        return self._link.codec

    # ------------------------------------------------------------------ state
    def snapshot(self) -> VehicleSnapshot:
        """A copy of the current vehicle state."""
        return self.cache.snapshot()

    def add_listener(self, callback: Callable[[Any], None]) -> None:
        """Call ``callback(msg)`` for every received MAVLink message (in the receive thread:
        keep it short; exceptions are swallowed)."""
        self._listeners.append(callback)

    def remove_listener(self, callback: Callable[[Any], None]) -> None:
        """Stop calling ``callback`` for received messages (no error if not added)."""
        with contextlib.suppress(ValueError):
            self._listeners.remove(callback)

    def statustexts(self) -> list[str]:
        """Recent STATUSTEXT texts from the autopilot, oldest first."""
        return self.cache.statustexts()

    def wait_for(self, predicate: Callable[[VehicleSnapshot], bool],
                 timeout_s: float) -> VehicleSnapshot:
        """Poll the snapshot until ``predicate`` holds; raises GcsTimeout otherwise."""
        deadline = time.monotonic() + timeout_s
        while True:
            snap = self.snapshot()
            if predicate(snap):
                return snap
            if time.monotonic() >= deadline:
                raise GcsTimeout(f"condition not met within {timeout_s:g} s")
            if self._closed:
                raise GcsError("ground station closed")
            time.sleep(0.01)

    # ------------------------------------------------------------------ requests
    def from_target(self, m: Any) -> bool:
        """``m`` comes from the autopilot (``target``)."""
        return (m.get_srcSystem(), m.get_srcComponent()) == self.target

    def send(self, msg: Any) -> None:
        """Send ``msg`` to the autopilot; GcsError once closed."""
        if self._closed:
            raise GcsError("ground station closed")
        with self._send_lock:
            self._link.send(msg)

    def add_waiter(self, predicate: Callable[[Any], bool]) -> Waiter:
        """Start waiting for a received message for which ``predicate`` holds."""
        w = Waiter(predicate)
        with self._lock:
            self._waiters.append(w)
        return w

    def remove_waiter(self, w: Waiter) -> None:
        """Stop waiting (no error if already removed)."""
        with self._lock, contextlib.suppress(ValueError):
            self._waiters.remove(w)

    def request(self, msg: Any, predicate: Callable[[Any], bool], timeout_s: float,
                retries: int) -> Any:
        """Send ``msg`` and return the first message of the autopilot for which
        ``predicate`` holds, sending again up to ``retries`` times after ``timeout_s`` [s]
        without one; None if none came."""
        for _ in range(max(0, retries) + 1):
            w = self.add_waiter(lambda m: self.from_target(m) and predicate(m))
            try:
                self.send(msg)
                if w.event.wait(timeout_s):
                    return w.message
            finally:
                self.remove_waiter(w)
        return None

    # ------------------------------------------------------------------ receive thread
    def _rx_loop(self) -> None:
        next_hb = 0.0
        codec = self._link.codec
        while not self._closed:
            now = time.monotonic()
            if now >= next_hb:
                next_hb = now + 1.0
                # no peer yet on a udp-server: dropped and counted by the link
                with contextlib.suppress(Exception), self._send_lock:
                    self._link.send(codec.heartbeat_encode(
                        mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MAV_STATE_ACTIVE))
            try:
                msgs = self._link.recv(0.2)
            except Exception:  # closed under us
                if self._closed:
                    return
                time.sleep(0.05)
                continue
            for m in msgs:
                self._handle(m)

    def _handle(self, m: Any) -> None:
        if self.from_target(m):
            self.cache.update(m)
        with self._lock:
            waiters = list(self._waiters)
        for w in waiters:
            if not w.event.is_set():
                try:
                    if w.predicate(m):
                        w.message = m
                        w.event.set()
                except Exception:
                    pass
        for cb in list(self._listeners):
            with contextlib.suppress(Exception):
                cb(m)

