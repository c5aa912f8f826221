"""Fixed-wing lateral guidance of PX4's L1 kind (Park, Deyst & How 2004; PX4's ECL L1
controller), plus the coordinated-turn references the attitude control flies.

All in the local NED plane: positions ``(north, east)`` [m], ground velocity ``(vn, ve)``
[m/s]. The output is a lateral acceleration command [m/s^2], positive to the right (a right
turn, positive roll in FRD); :func:`roll_for_lateral_accel` turns it into the bank angle of a
level coordinated turn, ``phi = atan(a / g)``.

The L1 distance is ``L1 = period * damping * V / pi`` (``FW_L1_PERIOD`` [s], ``FW_L1_DAMPING``),
the gain ``K = 4 damping^2``; on a straight line the law behaves like a second-order system of
that period and damping, on a circle of radius R it settles at ``a = V^2 / R``.
"""

from __future__ import annotations

import math

__all__ = ["L1Guidance", "cross_track", "roll_for_lateral_accel", "wrap_pi"]


def wrap_pi(a: float) -> float:
    """Angle wrapped to [-pi, pi) [rad]."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _cross(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


def cross_track(a: tuple[float, float], b: tuple[float, float],
                p: tuple[float, float]) -> tuple[float, float]:
    """(signed cross-track error [m], positive right of A->B; along-track distance from A [m])
    of the point ``p`` relative to the line through ``a`` and ``b``."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    n = math.hypot(dx, dy)
    if n < 1e-9:
        return math.hypot(p[0] - a[0], p[1] - a[1]), 0.0
    ux, uy = dx / n, dy / n
    px, py = p[0] - a[0], p[1] - a[1]
    return -_cross(px, py, ux, uy), px * ux + py * uy


def roll_for_lateral_accel(a_lat: float, g: float, roll_max: float) -> float:
    """Bank angle [rad] of a level coordinated turn with lateral acceleration ``a_lat``."""
    return min(max(math.atan2(a_lat, g), -roll_max), roll_max)


class L1Guidance:
    """L1 path following: straight segments A -> B and loiter circles (PX4's ECL law).

    Parameters
    ----------
    period
        ``FW_L1_PERIOD`` [s].
    damping
        ``FW_L1_DAMPING``.
    """

    def __init__(self, period: float = 20.0, damping: float = 0.75) -> None:
        self.period = float(period)
        self.damping = float(damping)
        self.l1_distance = 0.0
        """L1 distance of the last call [m] (also the waypoint switch distance)."""

    def _l1(self, v: float) -> float:
        self.l1_distance = self.period * self.damping * v / math.pi
        return max(self.l1_distance, 0.1)

    def segment(self, a: tuple[float, float], b: tuple[float, float],
                p: tuple[float, float], vel: tuple[float, float]) -> float:
        """Lateral acceleration [m/s^2] following the line A -> B towards B."""
        vn, ve = vel
        v = max(math.hypot(vn, ve), 1.0)
        l1 = self._l1(v)
        k = 4.0 * self.damping**2
        abx, aby = b[0] - a[0], b[1] - a[1]
        n = math.hypot(abx, aby)
        if n < 1e-3:  # degenerate segment: fly to B
            abx, aby = b[0] - p[0], b[1] - p[1]
            n = max(math.hypot(abx, aby), 1e-3)
        ux, uy = abx / n, aby / n
        apx, apy = p[0] - a[0], p[1] - a[1]
        d_ap = math.hypot(apx, apy)
        along = apx * ux + apy * uy
        bpx, bpy = p[0] - b[0], p[1] - b[1]
        if d_ap > l1 and along / max(d_ap, 1e-6) < -0.7071:
            # far behind A: fly towards A first
            pax, pay = -apx / d_ap, -apy / d_ap
            eta = math.atan2(_cross(vn, ve, pax, pay), vn * pax + ve * pay)
        elif bpx * ux + bpy * uy > 0.0 and math.hypot(bpx, bpy) > l1:
            # B behind: fly directly back to B
            d_bp = math.hypot(bpx, bpy)
            pbx, pby = -bpx / d_bp, -bpy / d_bp
            eta = math.atan2(_cross(vn, ve, pbx, pby), vn * pbx + ve * pby)
        else:
            eta2 = math.atan2(_cross(vn, ve, ux, uy), vn * ux + ve * uy)
            xtrack = _cross(apx, apy, ux, uy)
            sin_eta1 = min(max(xtrack / l1, -0.7071), 0.7071)
            eta = math.asin(sin_eta1) + eta2
        eta = min(max(eta, -math.pi / 2), math.pi / 2)
        return k * v * v / l1 * math.sin(eta)

    def loiter(self, center: tuple[float, float], radius: float, direction: int,
               p: tuple[float, float], vel: tuple[float, float]) -> float:
        """Lateral acceleration [m/s^2] circling ``center`` at ``radius`` [m]; ``direction``
        +1 clockwise (seen from above), -1 counter-clockwise."""
        vn, ve = vel
        v = max(math.hypot(vn, ve), 1.0)
        l1 = self._l1(v)
        k = 4.0 * self.damping**2
        omega = 2.0 * math.pi / self.period
        k_xt = omega * omega
        k_v = 2.0 * self.damping * omega
        apx, apy = p[0] - center[0], p[1] - center[1]
        d = math.hypot(apx, apy)
        if d < 1e-3:
            apx, apy, d = 1.0, 0.0, 1.0
        ux, uy = apx / d, apy / d
        xv_center = _cross(ux, uy, vn, ve)
        lv_center = -(vn * ux + ve * uy)
        eta = min(max(math.atan2(xv_center, lv_center), -math.pi / 2), math.pi / 2)
        a_center = k * v * v / l1 * math.sin(eta)
        xv_circle = -lv_center
        xt_err = d - radius
        a_pd = xt_err * k_xt + xv_circle * k_v
        tangent_v = xv_center * direction
        if tangent_v < 0.0:
            a_pd = max(a_pd, 0.0)
        a_centripetal = tangent_v * tangent_v / max(0.5 * radius, radius + xt_err)
        a_circle = direction * (a_pd + a_centripetal)
        # ECL: circle mode inside the L1 band around the circle (or once on the right side)
        if xt_err < l1 or (tangent_v > 0 and xt_err < 2.0 * l1):
            return a_circle
        return a_center
