"""Cascaded P-PID attitude controller for one axis (paper fig. 5), discrete time.

Structure (continuous time, the form the synthesis tool tunes)::

    rate_ref = kp_angle * (angle_ref - angle)            outer P loop [rad/s]
                (+ optional feed-forward, limited to ±rate_limit)
    e        = rate_ref - rate                           rate error [rad/s]
    tau      = K_rate(s) e,  K_rate(s) = kp + ki/s + kd s / (tf s + 1)     [N m]

with ``kp = kp_rate`` [N m s/rad], ``ki = ki_rate`` [N m/rad], ``kd = kd_rate``
[N m s²/rad] and ``tf = tf_rate_s`` [s]. As a ratio of polynomials::

    K_rate(s) = ((kp tf + kd) s² + (kp + ki tf) s + ki) / (tf s² + s)

(``PPIDGains.rate_tf``). The yaw angle error is wrapped to (-pi, pi].

Discretisation (sample time ``dt``, 250 Hz by default), chosen by ``method``:

- ``"tustin"`` (default): the integral and the derivative filter are discretised with the
  bilinear transform s -> (2/dt)(z-1)/(z+1) (trapezoidal integral; derivative filter pole at
  (2tf - dt)/(2tf + dt)). The controller is then exactly the Tustin image of K_rate(s)
  (``discrete_rate_tf`` is ``scipy.signal.cont2discrete(..., method="bilinear")`` of
  ``rate_tf``). If ``tf < dt/2`` the Tustin filter pole would be negative (ringing at
  Nyquist; for tf = 0 not decaying at all), so for such ``tf`` the derivative filter falls
  back to backward Euler (pole tf/(tf + dt) in [0, 1)).
- ``"backward_euler"``: s -> (z-1)/(z dt) for both (integral I_k = I_{k-1} + ki dt e_k;
  filter pole tf/(tf + dt)); always stable, first-order accurate.

State is kept in output units (N m): the integral of ``ki e`` and the filtered ``kd ė``, so
that gains changed every step by the schedule are bumpless (a change of ki or kd does not
rescale the accumulated state). After ``reset`` the controller is at rest (previous error 0),
i.e. an LTI system with zero initial state: a step in the error at engagement produces the
derivative kick the continuous transfer function has; use ``reset(rate_error=e0)`` for a
bumpless start instead.

Output limits ``[u_min, u_max]`` (N m) with anti-windup by conditional integration
(clamping): an integral increment that would take the unsaturated output beyond a limit is
cut so that the output just reaches the limit (and dropped entirely when the output is
already beyond it, e.g. through the P or D part); increments away from the limit always
pass, and the integral itself is kept within the output limits. The integral therefore never
grows while saturated in the direction of saturation, and unwinds at once when the error
changes sign.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = [
    "CascadedPPID",
    "ContinuousPPID",
    "PPIDGains",
    "wrap_angle",
]

Method = Literal["tustin", "backward_euler"]
TWO_PI = 2.0 * math.pi


def wrap_angle(x: float) -> float:
    """Wrap an angle [rad] to (-pi, pi]."""
    return -((-x + math.pi) % TWO_PI - math.pi)


@dataclass(frozen=True, slots=True)
class PPIDGains:
    """Gains of one P-PID axis (SI; rate error in rad/s to moment in N m).

    Attributes
    ----------
    kp_angle
        outer P gain [1/s] (rate reference per angle error).
    kp_rate
        inner proportional gain [N m s/rad].
    ki_rate
        inner integral gain [N m/rad].
    kd_rate
        inner derivative gain [N m s²/rad].
    tf_rate_s
        derivative filter time constant [s].
    """

    kp_angle: float
    kp_rate: float
    ki_rate: float
    kd_rate: float
    tf_rate_s: float

    def rate_tf(self) -> tuple[np.ndarray, np.ndarray]:
        """Continuous ``K_rate(s) = kp + ki/s + kd s/(tf s + 1)`` as (num, den), descending s.

        ``num = [kp tf + kd, kp + ki tf, ki]``, ``den = [tf, 1, 0]``; with ``tf = 0`` the
        transfer function is improper when ``kd > 0`` (den ``[0, 1, 0]`` is returned as is).
        """
        kp, ki, kd, tf = self.kp_rate, self.ki_rate, self.kd_rate, self.tf_rate_s
        return np.array([kp * tf + kd, kp + ki * tf, ki]), np.array([tf, 1.0, 0.0])


@dataclass(frozen=True, slots=True)
class ContinuousPPID:
    """Equivalent continuous-time description of the cascaded P-PID, for analysis.

    ``tau = K_rate(s) (kp_angle (angle_ref - angle) - rate)``; ``rate_num``/``rate_den`` are
    the polynomial coefficients of ``K_rate(s)`` in descending powers of s (see
    ``PPIDGains.rate_tf``).
    """

    kp_angle: float
    kp_rate: float
    ki_rate: float
    kd_rate: float
    tf_rate_s: float
    rate_num: np.ndarray
    rate_den: np.ndarray


class CascadedPPID:
    """Discrete cascaded P-PID for one attitude axis.

    Parameters
    ----------
    gains
        initial gains (may be replaced every step, see ``update``).
    dt
        sample time [s] (default 1/250).
    wrap
        wrap the angle error to (-pi, pi] (yaw).
    rate_limit
        limit of the rate reference [rad/s] (None = none).
    output_limit
        moment limits [N m]: a scalar ``m`` means ``(-m, m)``; None = none.
    method
        ``"tustin"`` or ``"backward_euler"`` (see module docstring).
    """

    def __init__(
        self,
        gains: PPIDGains,
        dt: float = 1.0 / 250.0,
        *,
        wrap: bool = False,
        rate_limit: float | None = None,
        output_limit: float | tuple[float, float] | None = None,
        method: Method = "tustin",
    ) -> None:
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be finite and > 0, got {dt}")
        if method not in ("tustin", "backward_euler"):
            raise ValueError(f"method must be 'tustin' or 'backward_euler', got {method!r}")
        if rate_limit is not None and not rate_limit > 0:
            raise ValueError(f"rate_limit must be > 0, got {rate_limit}")
        if output_limit is None:
            lo, hi = -math.inf, math.inf
        elif isinstance(output_limit, tuple):
            lo, hi = float(output_limit[0]), float(output_limit[1])
        else:
            lo, hi = -float(output_limit), float(output_limit)
        if not lo < hi:
            raise ValueError(f"output_limit: need lower < upper, got ({lo}, {hi})")
        self.dt = float(dt)
        self.wrap = bool(wrap)
        self.rate_limit = None if rate_limit is None else float(rate_limit)
        self.u_min, self.u_max = lo, hi
        self.method: Method = method
        self.gains = gains
        self._tf_cached = math.nan
        self._a = 0.0
        self._b = 0.0
        self.reset()

    # ------------------------------------------------------------------------------------
    def reset(self, integral: float = 0.0, rate_error: float = 0.0) -> None:
        """Reset the state: integral [N m], previous rate error [rad/s], filter state 0."""
        self.integral = float(integral)  # ∫ ki e dt [N m]
        self.derivative = 0.0  # filtered kd de/dt [N m]
        self._e_prev = float(rate_error)
        self.rate_ref = 0.0
        self.output = 0.0
        self.output_unsat = 0.0
        self.saturated = False

    def _filter_coeffs(self, tf: float) -> tuple[float, float]:
        if tf != self._tf_cached:
            dt = self.dt
            if self.method == "tustin" and tf >= 0.5 * dt:
                self._a = (2.0 * tf - dt) / (2.0 * tf + dt)
                self._b = 2.0 / (2.0 * tf + dt)
            else:
                self._a = tf / (tf + dt)
                self._b = 1.0 / (tf + dt)
            self._tf_cached = tf
        return self._a, self._b

    def rate_reference(
        self, angle_ref: float, angle: float, gains: PPIDGains | None = None, rate_ff: float = 0.0
    ) -> float:
        """Outer loop: ``kp_angle * (angle_ref - angle) + rate_ff``, limited [rad/s]."""
        g = self.gains if gains is None else gains
        err = angle_ref - angle
        if self.wrap:
            err = wrap_angle(err)
        r = g.kp_angle * err + rate_ff
        if self.rate_limit is not None:
            r = min(max(r, -self.rate_limit), self.rate_limit)
        return r

    def update_rate(self, rate_ref: float, rate: float, gains: PPIDGains | None = None) -> float:
        """Inner loop only: one step of the PID on ``e = rate_ref - rate``; returns N m."""
        if gains is not None:
            self.gains = gains
        g = self.gains
        e = rate_ref - rate
        dt = self.dt
        e_prev = self._e_prev
        de = e - e_prev
        tf = g.tf_rate_s
        if tf == self._tf_cached:
            a, b = self._a, self._b
        else:
            a, b = self._filter_coeffs(tf)
        derivative = a * self.derivative + b * g.kd_rate * de
        self.derivative = derivative
        dI = 0.5 * g.ki_rate * dt * (e + e_prev) if self.method == "tustin" else g.ki_rate * dt * e
        p = g.kp_rate * e
        integral = self.integral
        u_min, u_max = self.u_min, self.u_max
        u_test = p + integral + dI + derivative
        # conditional integration: integrate at most up to the limit, never further into it
        if dI > 0.0 and u_test > u_max:
            dI = max(0.0, u_max - (u_test - dI))
        elif dI < 0.0 and u_test < u_min:
            dI = min(0.0, u_min - (u_test - dI))
        integral = min(max(integral + dI, u_min), u_max)
        self.integral = integral
        u = p + integral + derivative
        self.output_unsat = u
        self.saturated = u >= u_max or u <= u_min
        u = min(max(u, u_min), u_max)
        self._e_prev = e
        self.rate_ref = rate_ref
        self.output = u
        return u

    def update(
        self,
        angle_ref: float,
        angle: float,
        rate: float,
        gains: PPIDGains | None = None,
        rate_ff: float = 0.0,
    ) -> float:
        """One control step.

        Parameters
        ----------
        angle_ref, angle
            reference and measured angle [rad].
        rate
            measured body rate of this axis [rad/s].
        gains
            gains for this step (e.g. ``GainSchedule.gains_at(V)[axis]``); None keeps
            the current ones.
        rate_ff
            rate feed-forward added to the outer loop output [rad/s].

        Returns
        -------
        float
            Moment command [N m], within the output limits.
        """
        if gains is not None:
            self.gains = gains
        g = self.gains
        # outer loop: rate_reference(angle_ref, angle, g, rate_ff), inlined (hot path)
        err = angle_ref - angle
        if self.wrap:
            err = wrap_angle(err)
        r = g.kp_angle * err + rate_ff
        rl = self.rate_limit
        if rl is not None:
            r = min(max(r, -rl), rl)
        return self.update_rate(r, rate)

    # ------------------------------------------------------------------------------------
    def continuous_coefficients(self, gains: PPIDGains | None = None) -> ContinuousPPID:
        """Equivalent continuous-time controller (the one the synthesis tool tunes)."""
        g = self.gains if gains is None else gains
        num, den = g.rate_tf()
        return ContinuousPPID(g.kp_angle, g.kp_rate, g.ki_rate, g.kd_rate, g.tf_rate_s, num, den)

    def discrete_rate_tf(self, gains: PPIDGains | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The implemented inner-loop transfer function e -> tau in z (unsaturated).

        Returns (num, den) in descending powers of z, den monic. For ``method="tustin"``
        (and ``tf >= dt/2``) this equals the bilinear transform of ``K_rate(s)``.
        """
        g = self.gains if gains is None else gains
        dt = self.dt
        tf = g.tf_rate_s
        if self.method == "tustin" and tf >= 0.5 * dt:
            a, b = (2.0 * tf - dt) / (2.0 * tf + dt), 2.0 / (2.0 * tf + dt)
        else:
            a, b = tf / (tf + dt), 1.0 / (tf + dt)
        P = np.array([g.kp_rate])  # over den 1
        if self.method == "tustin":
            I_num, I_den = 0.5 * g.ki_rate * dt * np.array([1.0, 1.0]), np.array([1.0, -1.0])
        else:
            I_num, I_den = g.ki_rate * dt * np.array([1.0, 0.0]), np.array([1.0, -1.0])
        D_num, D_den = b * g.kd_rate * np.array([1.0, -1.0]), np.array([1.0, -a])
        den = np.polymul(I_den, D_den)
        num = np.polymul(P, den) + np.polymul(I_num, D_den) + np.polymul(D_num, I_den)
        return num, den
