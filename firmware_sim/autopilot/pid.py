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

The step itself is the compiled kernel :func:`.control_kernels.ppid_step` (the one
implementation of this law); :class:`CascadedPPID` is a view of the kernel's arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from vtolftc.firmware_sim.autopilot import control_kernels as ck

__all__ = [
    "CascadedPPID",
    "ContinuousPPID",
    "PPIDGains",
    "gains_row",
    "wrap_angle",
]

Method = Literal["tustin", "backward_euler"]
TWO_PI = ck.TWO_PI
wrap_angle = ck.wrap_angle


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


def gains_row(g: PPIDGains) -> NDArray[np.float64]:
    """The gains as the kernel's row (``control_kernels.G_*`` columns), shape (5,)."""
    return np.array([float(g.kp_angle), float(g.kp_rate), float(g.ki_rate), float(g.kd_rate),
                     float(g.tf_rate_s)])


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


def _array_property(array: str, col: int, doc: str) -> property:
    """A float attribute stored in column ``col`` of this axis' row of ``self.<array>``."""
    def get(self: CascadedPPID) -> float:
        return float(getattr(self, array)[self._row, col])

    def put(self: CascadedPPID, value: float) -> None:
        getattr(self, array)[self._row, col] = float(value)

    return property(get, put, doc=doc)


class CascadedPPID:
    """Discrete cascaded P-PID for one attitude axis: a view of one row of the state and
    constant arrays that the compiled kernel (:mod:`.control_kernels`) steps.

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
    state, const, row
        arrays ``(n, N_STATE)`` and ``(n, N_CONST)`` holding this axis in row ``row`` (shared
        with the other axes of a controller, which steps them all in one compiled call);
        None: arrays of its own. The whole arrays and the row index are kept (not a view),
        so a deep copy or pickle of a controller keeps them shared.
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
        state: NDArray[np.float64] | None = None,
        const: NDArray[np.float64] | None = None,
        row: int = 0,
    ) -> None:
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be finite and > 0, got {dt}")
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
        self._state = np.zeros((1, ck.N_STATE)) if state is None else state
        self._const = np.zeros((1, ck.N_CONST)) if const is None else const
        self._row = int(row)
        self.method = method
        self.dt = float(dt)
        self.wrap = bool(wrap)
        self.rate_limit = None if rate_limit is None else float(rate_limit)
        self.u_min, self.u_max = lo, hi
        self.gains = gains
        self._garr_of: PPIDGains | None = None
        self._garr = np.zeros(ck.N_GAINS)
        self._state[self._row, ck.S_TF] = math.nan  # no filter coefficients cached yet
        self.reset()

    # the constants, read and written in the kernel's array -------------------------------
    @property
    def wrap(self) -> bool:
        """Wrap the angle error to (-pi, pi] (yaw)."""
        return bool(self._const[self._row, ck.C_WRAP] != 0.0)

    @wrap.setter
    def wrap(self, value: bool) -> None:
        self._const[self._row, ck.C_WRAP] = 1.0 if value else 0.0

    @property
    def rate_limit(self) -> float | None:
        """Limit of the rate reference [rad/s], None for none."""
        v = float(self._const[self._row, ck.C_RATE_LIMIT])
        return None if v != v else v

    @rate_limit.setter
    def rate_limit(self, value: float | None) -> None:
        self._const[self._row, ck.C_RATE_LIMIT] = math.nan if value is None else float(value)

    @property
    def method(self) -> Method:
        """Discretisation, ``"tustin"`` or ``"backward_euler"``."""
        return "tustin" if self._const[self._row, ck.C_TUSTIN] != 0.0 else "backward_euler"

    @method.setter
    def method(self, value: Method) -> None:
        if value not in ("tustin", "backward_euler"):
            raise ValueError(f"method must be 'tustin' or 'backward_euler', got {value!r}")
        self._const[self._row, ck.C_TUSTIN] = 1.0 if value == "tustin" else 0.0

    dt = _array_property("_const", ck.C_DT, "sample time [s]")
    u_min = _array_property("_const", ck.C_U_MIN, "lower output limit [N m]")
    u_max = _array_property("_const", ck.C_U_MAX, "upper output limit [N m]")

    # the state ----------------------------------------------------------------------------
    integral = _array_property("_state", ck.S_INTEGRAL, "integral of ki e dt [N m]")
    derivative = _array_property("_state", ck.S_DERIVATIVE, "filtered kd de/dt [N m]")
    rate_ref = _array_property("_state", ck.S_RATE_REF, "last rate reference [rad/s]")
    output = _array_property("_state", ck.S_OUTPUT, "last output [N m]")
    output_unsat = _array_property("_state", ck.S_OUTPUT_UNSAT,
                                   "last output before the limits [N m]")

    @property
    def saturated(self) -> bool:
        """The last output was at a limit."""
        return bool(self._state[self._row, ck.S_SATURATED] != 0.0)

    @property
    def previous_rate_error(self) -> float:
        """Rate error of the last step [rad/s]."""
        return float(self._state[self._row, ck.S_E_PREV])

    # ------------------------------------------------------------------------------------
    def reset(self, integral: float = 0.0, rate_error: float = 0.0) -> None:
        """Reset the state: integral [N m], previous rate error [rad/s], filter state 0."""
        st = self._state[self._row]
        st[ck.S_INTEGRAL] = float(integral)
        st[ck.S_DERIVATIVE] = 0.0
        st[ck.S_E_PREV] = float(rate_error)
        st[ck.S_RATE_REF:] = 0.0

    def _gains_row(self) -> NDArray[np.float64]:
        g = self.gains
        if g is not self._garr_of:
            self._garr = gains_row(g)
            self._garr_of = g
        return self._garr

    def rate_reference(
        self, angle_ref: float, angle: float, gains: PPIDGains | None = None, rate_ff: float = 0.0
    ) -> float:
        """Outer loop: ``kp_angle * (angle_ref - angle) + rate_ff``, limited [rad/s]."""
        g = self._gains_row() if gains is None else gains_row(gains)
        return ck.ppid_rate_reference(g, self._const, self._row, float(angle_ref),
                                      float(angle), float(rate_ff))

    def update_rate(self, rate_ref: float, rate: float, gains: PPIDGains | None = None) -> float:
        """Inner loop only: one step of the PID on ``e = rate_ref - rate``; returns N m."""
        if gains is not None:
            self.gains = gains
        return ck.ppid_rate_step(self._gains_row(), self._state, self._const, self._row,
                                 float(rate_ref), float(rate))

    def update(
        self,
        angle_ref: float,
        angle: float,
        rate: float,
        gains: PPIDGains | None = None,
        rate_ff: float = 0.0,
        *,
        sat_hi: bool = False,
        sat_lo: bool = False,
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
        sat_hi, sat_lo
            the allocation saturated this axis upwards / downwards last step: the integral
            does not move further that way (its increment is taken back out of the output).

        Returns
        -------
        float
            Moment command [N m], within the output limits.
        """
        if gains is not None:
            self.gains = gains
        return ck.ppid_step(self._gains_row(), self._state, self._const, self._row,
                            float(angle_ref), float(angle), float(rate), float(rate_ff),
                            bool(sat_hi), bool(sat_lo))

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
        a, b = ck.filter_coefficients(g.tf_rate_s, dt, self.method == "tustin")
        P = np.array([g.kp_rate])  # over den 1
        if self.method == "tustin":
            I_num, I_den = 0.5 * g.ki_rate * dt * np.array([1.0, 1.0]), np.array([1.0, -1.0])
        else:
            I_num, I_den = g.ki_rate * dt * np.array([1.0, 0.0]), np.array([1.0, -1.0])
        D_num, D_den = b * g.kd_rate * np.array([1.0, -1.0]), np.array([1.0, -a])
        den = np.polymul(I_den, D_den)
        num = np.polymul(P, den) + np.polymul(I_num, D_den) + np.polymul(D_num, I_den)
        return num, den
