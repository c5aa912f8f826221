"""Cascaded P-PID attitude loop of the paper (fig. 5) and its weighted closed-loop functions.

One axis. Plant ``G`` = :func:`vtolftc.synthesis.models.attitude_model` (moment u [N m] -> outputs
[rate (rad/s); angle (rad)], strictly proper). Controller (gains ``theta`` in the order of
:data:`PARAM_NAMES`, units as in :mod:`vtolftc.firmware_sim.autopilot.pid`)::

    rate_ref = kp_angle (angle_ref - angle)                                   [rad/s]
    u        = K_rate(s) (rate_ref - rate),
               K_rate(s) = kp_rate + ki_rate/s + kd_rate s/(tf_rate_s s + 1)  [N m]

Signals: r = angle_ref, e = r - angle, u = controller moment, d = moment disturbance at the
plant input (the plant sees u + d: the multiplicative input uncertainty G (1 + W_t Delta) of
paper eq. 11 enters there with d = Delta W_t u). With L_u = K_rate (kp_angle G_angle + G_rate)
(the loop broken at the plant input),

    S   = e/r  = (1 + K_rate G_rate) / (1 + L_u)
    R   = u/r  = kp_angle K_rate / (1 + L_u)
    T_u = -u/d = L_u / (1 + L_u)

The tuned channel of eq. 8 is the column [Ws S; Wt T_u; Wr R] (three SISO functions stacked;
their H-infinity norm is sup_w sqrt(|Ws S|^2 + |Wt T_u|^2 + |Wr R|^2)). It is realised with
two copies of the closed loop (one driven by r, one by d) so that it is a single-input LTI
system; see :class:`CascadeChannel` (picklable, cheap: numpy only).

Weights: Ws of eq. 5 (:class:`SensitivityWeight`) and Wr of eq. 6 (:class:`ControlWeight`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import control as ct
import numpy as np
from numpy.typing import NDArray

from vtolftc.synthesis.hinfnorm import StateSpaceData, as_state_space

__all__ = [
    "PARAM_NAMES",
    "CascadeChannel",
    "ClosedLoop",
    "ControlWeight",
    "SensitivityWeight",
    "closed_loop",
    "rate_controller",
    "series",
]

PARAM_NAMES: tuple[str, ...] = ("kp_angle", "kp_rate", "ki_rate", "kd_rate", "tf_rate_s")


# ------------------------------------------------------------------------------------------
# weights (eq. 5, eq. 6)
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SensitivityWeight:
    """Ws(s) = (s/M + omega_b) / (s + A omega_b) (paper eq. 5).

    Parameters
    ----------
    M : float
        Allowed peak of |S| (high-frequency gain 1/M), > 0.
    omega_b_rad_s : float
        Required bandwidth (rad/s): |Ws| = 1 near omega_b.
    A : float
        Allowed steady-state error (low-frequency gain 1/A), > 0 (A = 0 puts a pole at s = 0
        and the weighted norm is infinite).

    Raises
    ------
    ValueError
        For a value that is not a finite number > 0.

    Examples
    --------
    >>> Ws = SensitivityWeight(2.0, 1.0, 1e-3)
    >>> round(float(abs(Ws.tf()(0))), 1), round(float(abs(Ws.tf()(1e9j))), 3)
    (1000.0, 0.5)
    """

    M: float
    omega_b_rad_s: float
    A: float = 1e-3

    def __post_init__(self) -> None:
        for name, v in (("M", self.M), ("omega_b", self.omega_b_rad_s), ("A", self.A)):
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"sensitivity weight: {name} = {v!r}, expected a finite "
                                 "number > 0 (A = 0 gives an infinite weighted norm)")

    def tf(self) -> ct.TransferFunction:
        """Ws(s) as a python-control transfer function.

        Returns
        -------
        control.TransferFunction
            Ws(s).
        """
        return ct.tf([1.0 / self.M, self.omega_b_rad_s], [1.0, self.A * self.omega_b_rad_s])

    def ss(self) -> StateSpaceData:
        """First-order state-space realisation ``(A, B, C, D)`` of Ws(s).

        Returns
        -------
        A, B, C, D : ndarray
            Each of shape (1, 1).
        """
        a = -self.A * self.omega_b_rad_s
        # (s/M + wb)/(s - a) = 1/M + (wb + a/M)/(s - a)
        return (np.array([[a]]), np.array([[1.0]]),
                np.array([[self.omega_b_rad_s + a / self.M]]), np.array([[1.0 / self.M]]))

    def response(self, omegas: NDArray[np.float64]) -> NDArray[np.complex128]:
        """Ws(j omega) at the frequencies ``omegas`` (rad/s).

        Parameters
        ----------
        omegas : array_like, shape (nw,)
            Frequencies (rad/s).

        Returns
        -------
        ndarray of complex, shape (nw,)
            Ws(j omega).
        """
        s = 1j * np.asarray(omegas, float)
        return (s / self.M + self.omega_b_rad_s) / (s + self.A * self.omega_b_rad_s)

    def to_dict(self) -> dict[str, float]:
        """The parameters ``M``, ``omega_b_rad_s``, ``A`` as a JSON-ready dict.

        Returns
        -------
        dict of str to float
            The parameters.
        """
        return {"M": self.M, "omega_b_rad_s": self.omega_b_rad_s, "A": self.A}


@dataclass(frozen=True)
class ControlWeight:
    """Wr(s) = ((r_max/u_max) s + omega_a 1e-3) / (s + omega_a) (paper eq. 6).

    High-frequency gain r_max/u_max, so ||Wr R|| <= 1 keeps the moment of a reference step of
    r_max within u_max.

    Parameters
    ----------
    r_max_rad : float
        Largest angle reference step (rad), > 0.
    u_max_N_m : float
        The largest moment the actuators produce about the axis (N m), > 0.
    omega_a_rad_s : float
        Actuator bandwidth (rad/s; paper: 5).

    Raises
    ------
    ValueError
        For a value that is not a finite number > 0.
    """

    r_max_rad: float
    u_max_N_m: float
    omega_a_rad_s: float = 5.0

    def __post_init__(self) -> None:
        for name, v in (("r_max", self.r_max_rad), ("u_max", self.u_max_N_m),
                        ("omega_a", self.omega_a_rad_s)):
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"control weight: {name} = {v!r}, expected a finite number > 0")

    @property
    def high_gain(self) -> float:
        """High-frequency gain r_max / u_max (rad per N m)."""
        return self.r_max_rad / self.u_max_N_m

    def tf(self) -> ct.TransferFunction:
        """Wr(s) = (h s + 1e-3 omega_a) / (s + omega_a) as a python-control transfer function.

        Returns
        -------
        control.TransferFunction
            Wr(s), h = r_max / u_max (rad / (N m)).
        """
        return ct.tf([self.high_gain, self.omega_a_rad_s * 1e-3], [1.0, self.omega_a_rad_s])

    def ss(self) -> StateSpaceData:
        """First-order state-space realisation ``(A, B, C, D)`` of Wr(s).

        Returns
        -------
        A, B, C, D : ndarray
            Each of shape (1, 1).
        """
        wa, h = self.omega_a_rad_s, self.high_gain
        # (h s + wa 1e-3)/(s + wa) = h + (wa 1e-3 - h wa)/(s + wa)
        return (np.array([[-wa]]), np.array([[1.0]]), np.array([[wa * 1e-3 - h * wa]]),
                np.array([[h]]))

    def response(self, omegas: NDArray[np.float64]) -> NDArray[np.complex128]:
        """Wr(j omega) at the frequencies ``omegas`` (rad/s).

        Parameters
        ----------
        omegas : array_like, shape (nw,)
            Frequencies (rad/s).

        Returns
        -------
        ndarray of complex, shape (nw,)
            Wr(j omega).
        """
        s = 1j * np.asarray(omegas, float)
        return (self.high_gain * s + self.omega_a_rad_s * 1e-3) / (s + self.omega_a_rad_s)

    def to_dict(self) -> dict[str, float]:
        """The parameters ``r_max_rad``, ``u_max_N_m``, ``omega_a_rad_s`` as a JSON-ready dict.

        Returns
        -------
        dict of str to float
            The parameters.
        """
        return {"r_max_rad": self.r_max_rad, "u_max_N_m": self.u_max_N_m,
                "omega_a_rad_s": self.omega_a_rad_s}


# ------------------------------------------------------------------------------------------
# loop algebra
# ------------------------------------------------------------------------------------------


def rate_controller(kp: float, ki: float, kd: float, tf: float) -> StateSpaceData:
    """K_rate(s) = kp + ki/s + kd s/(tf s + 1) as (A, B, C, D); states: integral, filter.

    Parameters
    ----------
    kp : float
        Proportional gain (N m s / rad).
    ki : float
        Integral gain (N m / rad).
    kd : float
        Derivative gain (N m s^2 / rad).
    tf : float
        Derivative filter time constant (s), > 0.

    Returns
    -------
    A, B, C, D : ndarray
        Shapes (2, 2), (2, 1), (1, 2), (1, 1); input rate error (rad/s), output moment (N m).

    Raises
    ------
    ValueError
        If tf <= 0.
    """
    if not tf > 0:
        raise ValueError(f"derivative filter time constant tf_rate_s must be > 0 s, got {tf}")
    return (np.array([[0.0, 0.0], [0.0, -1.0 / tf]]), np.array([[1.0], [1.0 / tf]]),
            np.array([[ki, -kd / tf]]), np.array([[kp + kd / tf]]))


def series(H: StateSpaceData, W: StateSpaceData) -> StateSpaceData:
    """W(s) H(s) (H first) as state space, states [x_H; x_W].

    Parameters
    ----------
    H : tuple of ndarray
        (A, B, C, D) of the first system.
    W : tuple of ndarray
        (A, B, C, D) of the second; its inputs are H's outputs.

    Returns
    -------
    A, B, C, D : ndarray
        The series connection.
    """
    Ah, Bh, Ch, Dh = H
    Aw, Bw, Cw, Dw = W
    nh, nw = Ah.shape[0], Aw.shape[0]
    A = np.zeros((nh + nw, nh + nw))
    A[:nh, :nh] = Ah
    A[nh:, :nh] = Bw @ Ch
    A[nh:, nh:] = Aw
    return A, np.vstack([Bh, Bw @ Dh]), np.hstack([Dw @ Ch, Cw]), Dw @ Dh


@dataclass(frozen=True)
class ClosedLoop:
    """Closed loop of one axis (see the module docstring).

    Parameters
    ----------
    A : ndarray of float, shape (4, 4)
        State [x_plant (2); x_controller (2)].
    B : ndarray of float, shape (4, 2)
        Inputs [r (rad), d (N m)].
    C : ndarray of float, shape (4, 4)
        Outputs [e (rad), u (N m), rate (rad/s), angle (rad)].
    D : ndarray of float, shape (4, 2)
        Feedthrough.
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    D: NDArray[np.float64]

    def _siso(self, out: int, inp: int, sign: float = 1.0) -> StateSpaceData:
        return (self.A, self.B[:, [inp]], sign * self.C[[out], :],
                sign * self.D[[out]][:, [inp]])

    def S(self) -> StateSpaceData:
        """Sensitivity e/r.

        Returns
        -------
        A, B, C, D : ndarray
            SISO state space (rad/rad).
        """
        return self._siso(0, 0)

    def R(self) -> StateSpaceData:
        """Control sensitivity u/r.

        Returns
        -------
        A, B, C, D : ndarray
            SISO state space (N m / rad).
        """
        return self._siso(1, 0)

    def T_u(self) -> StateSpaceData:
        """-u/d: complementary sensitivity at the plant input.

        Returns
        -------
        A, B, C, D : ndarray
            SISO state space (dimensionless).
        """
        return self._siso(1, 1, -1.0)

    def S_ud(self) -> StateSpaceData:
        """e/d (= -G_angle S_u), the angle error per input moment.

        Returns
        -------
        A, B, C, D : ndarray
            SISO state space (rad / (N m)).
        """
        return self._siso(0, 1)

    @property
    def poles(self) -> NDArray[np.complex128]:
        """Eigenvalues of the closed-loop state matrix (rad/s)."""
        return np.linalg.eigvals(self.A)

    def stable(self, margin: float = 0.0) -> bool:
        """True when every closed-loop pole has real part < ``-margin`` (rad/s).

        Parameters
        ----------
        margin : float
            Required decay rate (1/s).

        Returns
        -------
        bool
            The verdict.
        """
        return bool(np.max(self.poles.real) < -margin)

    def lti(self) -> ct.StateSpace:
        """The closed loop as a python-control state-space system.

        Returns
        -------
        control.StateSpace
            Inputs [r, d], outputs [e, u, rate, angle].
        """
        return ct.ss(self.A, self.B, self.C, self.D)


def _plant(G: Any) -> StateSpaceData:
    Ag, Bg, Cg, Dg = as_state_space(G)
    if Dg.shape != (2, 1):
        raise ValueError(f"plant must be moment -> [rate; angle] (2 outputs, 1 input), got "
                         f"{Dg.shape[0]} outputs x {Dg.shape[1]} inputs")
    if np.any(Dg != 0):
        raise ValueError("plant must be strictly proper (D = 0), as attitude_model is")
    return Ag, Bg, Cg, Dg


def _closed(Gd: StateSpaceData, theta: NDArray[np.float64]) -> ClosedLoop:
    Ag, Bg, Cg, _ = Gd
    kpa, kp, ki, kd, tf = (float(x) for x in theta)
    Ak, Bk, Ck, Dk = rate_controller(kp, ki, kd, tf)
    Cq, Cth = Cg[[0]], Cg[[1]]
    Cy = kpa * Cth + Cq          # e_rate = kpa r - Cy x_g
    ng, nk = Ag.shape[0], Ak.shape[0]
    A = np.zeros((ng + nk, ng + nk))
    A[:ng, :ng] = Ag - Bg @ Dk @ Cy
    A[:ng, ng:] = Bg @ Ck
    A[ng:, :ng] = -Bk @ Cy
    A[ng:, ng:] = Ak
    B = np.zeros((ng + nk, 2))
    B[:ng, [0]] = Bg @ Dk * kpa
    B[:ng, [1]] = Bg
    B[ng:, [0]] = Bk * kpa
    C = np.zeros((4, ng + nk))
    D = np.zeros((4, 2))
    C[0, :ng] = -Cth[0]
    D[0, 0] = 1.0
    C[[1], :ng] = -Dk @ Cy
    C[[1], ng:] = Ck
    D[1, 0] = float(Dk[0, 0]) * kpa
    C[2, :ng] = Cq[0]
    C[3, :ng] = Cth[0]
    return ClosedLoop(A, B, C, D)


#: Closed loops of the last (plant, gains) pairs asked for by :class:`CascadeChannel`: the
#: tuners evaluate several channels on the same plant at the same gains (eq. 8, disturbance and
#: delay channels of one design point), so each loop is built once. Pure cache: the same
#: function of the same numbers, hence the same result bit for bit.
_CL_CACHE: dict[bytes, ClosedLoop] = {}
_CL_CACHE_SIZE = 256


def _plant_key(Gd: StateSpaceData) -> bytes:
    """Exact identity of a plant realisation (shapes and every bit of A, B, C)."""
    Ag, Bg, Cg, _ = Gd
    return b"".join([np.asarray(Ag.shape, np.int64).tobytes(),
                     np.asarray(Cg.shape, np.int64).tobytes(),
                     np.ascontiguousarray(Ag, float).tobytes(),
                     np.ascontiguousarray(Bg, float).tobytes(),
                     np.ascontiguousarray(Cg, float).tobytes()])


def _closed_cached(Gd: StateSpaceData, gkey: bytes, theta: NDArray[np.float64]) -> ClosedLoop:
    """:func:`_closed` through :data:`_CL_CACHE` (the returned loop must not be modified)."""
    key = gkey + np.ascontiguousarray(theta, float).tobytes()
    cl = _CL_CACHE.get(key)
    if cl is None:
        cl = _closed(Gd, theta)
        if len(_CL_CACHE) >= _CL_CACHE_SIZE:
            _CL_CACHE.clear()
        _CL_CACHE[key] = cl
    return cl


def _closed_batch(Gd: StateSpaceData, thetas: NDArray[np.float64],
                  ) -> tuple[NDArray[np.float64], ...]:
    """:func:`_closed` of every row of ``thetas`` (nb, 5) at once: (A, B, C, D) stacked
    (nb, ., .). Each entry is the same IEEE operation on the same operands as in
    :func:`_closed` (its matrix products have a single term: outer products and scalars;
    a product's ``+ 0.0`` below is the matmul's accumulation from zero, which turns a -0.0
    term into +0.0), so every slice equals ``_closed(Gd, thetas[i])`` bit for bit."""
    Ag, Bg, Cg, _ = Gd
    nb = thetas.shape[0]
    kpa, kp, ki, kd, tf = (thetas[:, j] for j in range(5))
    ng = Ag.shape[0]
    # rate_controller: Ak = [[0, 0], [0, -1/tf]], Bk = [1; 1/tf], Ck = [ki, -kd/tf],
    # Dk = kp + kd/tf
    a22 = -1.0 / tf
    b2 = 1.0 / tf
    c2 = -kd / tf
    dk = kp + kd / tf
    Cq, Cth = Cg[0], Cg[1]
    Cy = kpa[:, None] * Cth[None, :] + Cq[None, :]          # (nb, ng)
    bg = Bg[:, 0]
    bgdk = bg[None, :] * dk[:, None] + 0.0                   # Bg @ Dk  (nb, ng)
    A = np.zeros((nb, ng + 2, ng + 2))
    A[:, :ng, :ng] = Ag[None] - (bgdk[:, :, None] * Cy[:, None, :] + 0.0)
    A[:, :ng, ng] = bg[None, :] * ki[:, None] + 0.0          # Bg @ Ck
    A[:, :ng, ng + 1] = bg[None, :] * c2[:, None] + 0.0
    A[:, ng, :ng] = -1.0 * Cy + 0.0                          # -Bk @ Cy, Bk[0] = 1
    A[:, ng + 1, :ng] = (-b2)[:, None] * Cy + 0.0
    A[:, ng + 1, ng + 1] = a22
    B = np.zeros((nb, ng + 2, 2))
    B[:, :ng, 0] = bgdk * kpa[:, None]
    B[:, :ng, 1] = bg[None, :]
    B[:, ng, 0] = 1.0 * kpa
    B[:, ng + 1, 0] = b2 * kpa
    C = np.zeros((nb, 4, ng + 2))
    D = np.zeros((nb, 4, 2))
    C[:, 0, :ng] = -Cth[None, :]
    D[:, 0, 0] = 1.0
    C[:, 1, :ng] = (-dk)[:, None] * Cy + 0.0                 # -Dk @ Cy
    C[:, 1, ng] = ki
    C[:, 1, ng + 1] = c2
    D[:, 1, 0] = dk * kpa
    C[:, 2, :ng] = Cq[None, :]
    C[:, 3, :ng] = Cth[None, :]
    return A, B, C, D


#: Stacked closed loops of the last (plant, batch of gains) asked for by
#: :meth:`CascadeChannel.realize_batch` (the channels of one design point share them).
_CLB_CACHE: dict[bytes, tuple[NDArray[np.float64], ...]] = {}
_CLB_CACHE_SIZE = 64


def closed_loop(G: Any, theta: Any) -> ClosedLoop:
    """Closed loop of an attitude plant and the P-PID gains.

    Parameters
    ----------
    G : control.StateSpace or tuple
        Plant moment (N m) -> [rate (rad/s); angle (rad)], strictly proper (as
        :func:`vtolftc.synthesis.models.attitude_model`).
    theta : sequence of float or mapping
        The gains in :data:`PARAM_NAMES` order, or a mapping with those keys.

    Returns
    -------
    ClosedLoop
        The loop with inputs [r, d] and outputs [e, u, rate, angle].

    Raises
    ------
    ValueError
        For a plant of the wrong shape or not strictly proper, or not five gains.

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> from vtolftc.synthesis.models import attitude_model
    >>> G = attitude_model(load_airframe(), "roll", 0.0)
    >>> cl = closed_loop(G, [4.0, 2.0, 0.5, 0.05, 0.02])
    >>> cl.stable(), cl.A.shape
    (True, (4, 4))
    """
    if isinstance(theta, dict):
        theta = [theta[k] for k in PARAM_NAMES]
    th = np.asarray(theta, float).reshape(-1)
    if th.size != 5:
        raise ValueError(f"expected the 5 gains {PARAM_NAMES}, got {th.size} values")
    return _closed(_plant(G), th)


def _stack(parts: list[StateSpaceData]) -> StateSpaceData:
    """Single-input systems stacked: same input, outputs concatenated, states block-diag."""
    n = sum(p[0].shape[0] for p in parts)
    A = np.zeros((n, n))
    C_rows, D_rows, B_rows = [], [], []
    o = 0
    for Ap, Bp, Cp, Dp in parts:
        k = Ap.shape[0]
        A[o:o + k, o:o + k] = Ap
        B_rows.append(Bp)
        c = np.zeros((Cp.shape[0], n))
        c[:, o:o + k] = Cp
        C_rows.append(c)
        D_rows.append(Dp)
        o += k
    return A, np.vstack(B_rows), np.vstack(C_rows), np.vstack(D_rows)


@dataclass
class CascadeChannel:
    """theta -> (A, B, C, D) of [Ws S; Wt T_u; Wr R] (eq. 8) for one axis and plant.

    Any of the weights may be None (its row is omitted). Picklable (no closures), so it can
    be sent to worker processes. ``outputs`` names the rows.

    Parameters
    ----------
    G : control.StateSpace or tuple
        Plant moment (N m) -> [rate (rad/s); angle (rad)].
    Ws, Wt, Wr : LTI, tuple or scalar, optional
        Weights of S, T_u and R (eq. 8).
    Wd : LTI, tuple or scalar, optional
        A weight (not in eq. 8) on the angle response to a moment at the plant input, row
        ``"Wd*Sd"`` = Wd e/d (e/d = -G_angle / (1 + L_u), rad per N m); a constant
        d_max / e_max makes ||Wd e/d|| <= 1 mean "a moment d_max leaves an angle error of at
        most about e_max" (the input-disturbance objective of the robust design). Its states
        come after all the others, so a channel without ``Wd`` is exactly the eq. 8 channel.

    Raises
    ------
    ValueError
        If no weight is given or the plant has the wrong shape.
    """

    G: Any
    Ws: Any = None
    Wt: Any = None
    Wr: Any = None
    Wd: Any = None

    def __post_init__(self) -> None:
        self._G = _plant(self.G)
        self._W = [None if W is None else as_state_space(W.ss() if hasattr(W, "ss") else W)
                   for W in (self.Ws, self.Wt, self.Wr)]
        self._Wd = (None if self.Wd is None
                    else as_state_space(self.Wd.ss() if hasattr(self.Wd, "ss") else self.Wd))
        if all(W is None for W in self._W) and self._Wd is None:
            raise ValueError("at least one of Ws, Wt, Wr, Wd must be given")
        names = ("Ws*S", "Wt*T", "Wr*R")
        self.outputs = [n for n, W in zip(names, self._W, strict=True) if W is not None]
        if self._Wd is not None:
            self.outputs.append("Wd*Sd")
        self._gkey = _plant_key(self._G)

    def __getstate__(self) -> dict[str, Any]:
        return {"G": self._G, "Ws": self._W[0], "Wt": self._W[1], "Wr": self._W[2],
                "Wd": self._Wd}

    def __setstate__(self, st: dict[str, Any]) -> None:
        self.G, self.Ws, self.Wt, self.Wr = st["G"], st["Ws"], st["Wt"], st["Wr"]
        self.Wd = st.get("Wd")
        self.__post_init__()

    def _template(self) -> None:
        """Static part of the stacked realisation; states [x_cl(r) (4), x_Ws, x_Wr,
        x_cl(d) (4), x_Wt] (the S and R rows share one copy of the loop driven by r, the
        T_u row uses a second copy driven by d)."""
        Ws, Wt, Wr = self._W
        ncl = self._G[0].shape[0] + 2
        sizes = [ncl, 0 if Ws is None else Ws[0].shape[0], 0 if Wr is None else Wr[0].shape[0]]
        sizes += [ncl if Wt is not None else 0, 0 if Wt is None else Wt[0].shape[0]]
        Wd = self._Wd
        if Wd is not None:  # its own d-driven loop copy and weight, after everything else
            sizes += [ncl, Wd[0].shape[0]]
        off = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self._off, self._ncl = off, ncl
        n = int(off[-1])
        p = len(self.outputs)
        A = np.zeros((n, n))
        C = np.zeros((p, n))
        row = 0
        self._rows: dict[str, int] = {}
        for name, W, k in (("Ws*S", Ws, 1), ("Wt*T", Wt, 4), ("Wr*R", Wr, 2)):
            if W is None:
                continue
            Aw, _, Cw, _ = W
            A[off[k]:off[k + 1], off[k]:off[k + 1]] = Aw
            C[row, off[k]:off[k + 1]] = Cw[0]
            self._rows[name] = row
            row += 1
        if Wd is not None:
            Aw, _, Cw, _ = Wd
            A[off[6]:off[7], off[6]:off[7]] = Aw
            C[row, off[6]:off[7]] = Cw[0]
            self._rows["Wd*Sd"] = row
        self._A0, self._C0 = A, C

    def __call__(self, theta: NDArray[np.float64]) -> StateSpaceData:
        return self.assemble(_closed_cached(self._G, self._gkey, np.asarray(theta, float)))

    def loop(self, theta: NDArray[np.float64]) -> ClosedLoop:
        """The closed loop of this channel's plant at the gains ``theta`` (uncached).

        Parameters
        ----------
        theta : ndarray of float, shape (5,)
            P-PID gains in :data:`PARAM_NAMES` order.

        Returns
        -------
        ClosedLoop
            The loop, for :meth:`assemble`.
        """
        return _closed(self._G, theta)

    def assemble(self, cl: ClosedLoop) -> StateSpaceData:
        """The channel around a closed loop of this channel's plant (``__call__`` is
        ``assemble(_closed(G, theta))``; callers that share one loop among the channels of
        a plant build it once).

        Parameters
        ----------
        cl : ClosedLoop
            The closed loop of this channel's plant at the gains (not modified).

        Returns
        -------
        A, B, C, D : ndarray
            The channel (fresh float64 2-D arrays).
        """
        if not hasattr(self, "_A0"):
            self._template()
            self._plan()
        ncl = self._ncl
        A, C = self._A0.copy(), self._C0.copy()
        B = np.zeros((A.shape[0], 1))
        D = np.zeros((C.shape[0], 1))
        clC, clD = cl.C, cl.D
        A[:ncl, :ncl] = cl.A
        B[:ncl, 0] = cl.B[:, 0]
        # the products below are np.outer's and the scalar products of the assembly they
        # replace, element for element (same numbers, fewer temporaries)
        for sl, bw, dw, r, out in self._rdriven:   # Ws S (e from r), Wr R (u from r)
            Cx, Dx = clC[out], clD[out, 0]
            A[sl, :ncl] = bw[:, None] * Cx[None, :]
            B[sl, 0] = bw * Dx
            C[r, :ncl] = dw * Cx
            D[r, 0] = dw * Dx
        for c2, sl, bw, dw, r, out, sign in self._ddriven:   # Wt T_u (-u/d), Wd e/d
            Cx = -clC[out] if sign < 0 else clC[out]
            A[c2, c2] = cl.A
            B[c2, 0] = cl.B[:, 1]
            A[sl, c2] = bw[:, None] * Cx[None, :]
            C[r, c2] = (-dw * clC[out]) if sign < 0 else dw * Cx
        return A, B, C, D

    def realize_batch(self, thetas: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """The channel at every row of ``thetas``, all at once.

        Each slice equals ``self(thetas[i])`` bit for bit (same element operations; used for the
        tuner's finite-difference realisations).

        Parameters
        ----------
        thetas : ndarray of float, shape (nb, 5)
            P-PID gains, one set per row.

        Returns
        -------
        A, B, C, D : ndarray
            Stacked realisations, each of shape (nb, ., .).
        """
        if not hasattr(self, "_A0"):
            self._template()
            self._plan()
        thetas = np.ascontiguousarray(thetas, float)
        nb = thetas.shape[0]
        key = self._gkey + np.asarray(thetas.shape, np.int64).tobytes() + thetas.tobytes()
        cl = _CLB_CACHE.get(key)
        if cl is None:
            cl = _closed_batch(self._G, thetas)
            if len(_CLB_CACHE) >= _CLB_CACHE_SIZE:
                _CLB_CACHE.clear()
            _CLB_CACHE[key] = cl
        clA, clB, clC, clD = cl
        ncl = self._ncl
        A = np.repeat(self._A0[None], nb, axis=0)
        C = np.repeat(self._C0[None], nb, axis=0)
        B = np.zeros((nb, A.shape[1], 1))
        D = np.zeros((nb, C.shape[1], 1))
        A[:, :ncl, :ncl] = clA
        B[:, :ncl, 0] = clB[:, :, 0]
        for sl, bw, dw, r, out in self._rdriven:
            Cx, Dx = clC[:, out], clD[:, out, 0]
            A[:, sl, :ncl] = bw[None, :, None] * Cx[:, None, :]
            B[:, sl, 0] = bw[None, :] * Dx[:, None]
            C[:, r, :ncl] = dw * Cx
            D[:, r, 0] = dw * Dx
        for c2, sl, bw, dw, r, out, sign in self._ddriven:
            Cx = -clC[:, out] if sign < 0 else clC[:, out]
            A[:, c2, c2] = clA
            B[:, c2, 0] = clB[:, :, 1]
            A[:, sl, c2] = bw[None, :, None] * Cx[:, None, :]
            C[:, r, c2] = (-dw * clC[:, out]) if sign < 0 else dw * Cx
        return A, B, C, D

    def _plan(self) -> None:
        """Slices and weight numbers of :meth:`__call__` (after :meth:`_template`)."""
        Ws, Wt, Wr = self._W
        off = self._off
        self._rdriven: list[tuple[Any, ...]] = []
        for W, k, out, name in ((Ws, 1, 0, "Ws*S"), (Wr, 2, 1, "Wr*R")):
            if W is None:
                continue
            _, Bw, _, Dw = W
            self._rdriven.append((slice(off[k], off[k + 1]), Bw[:, 0].copy(), Dw[0, 0],
                                  self._rows[name], out))
        self._ddriven: list[tuple[Any, ...]] = []
        if Wt is not None:
            _, Bw, _, Dw = Wt
            self._ddriven.append((slice(off[3], off[4]), slice(off[4], off[5]),
                                  Bw[:, 0].copy(), Dw[0, 0], self._rows["Wt*T"], 1, -1))
        if self._Wd is not None:
            _, Bw, _, Dw = self._Wd
            self._ddriven.append((slice(off[5], off[6]), slice(off[6], off[7]),
                                  Bw[:, 0].copy(), Dw[0, 0], self._rows["Wd*Sd"], 0, 1))

    def rows(self, theta: NDArray[np.float64]) -> dict[str, StateSpaceData]:
        """Each weighted function on its own.

        Parameters
        ----------
        theta : ndarray of float, shape (5,)
            P-PID gains.

        Returns
        -------
        dict of str to tuple of ndarray
            Row name -> (A, B, C, D).
        """
        A, B, C, D = self(theta)
        return {n: (A, B, C[[i]], D[[i]]) for i, n in enumerate(self.outputs)}

    def reference(self, theta: NDArray[np.float64]) -> StateSpaceData:
        """The same channel assembled the slow, obvious way (series + stack; for tests).

        Parameters
        ----------
        theta : ndarray of float, shape (5,)
            P-PID gains.

        Returns
        -------
        A, B, C, D : ndarray
            The channel.
        """
        cl = _closed(self._G, np.asarray(theta, float))
        Ws, Wt, Wr = self._W
        parts = []
        if Ws is not None:
            parts.append(series(cl.S(), Ws))
        if Wt is not None:
            parts.append(series(cl.T_u(), Wt))
        if Wr is not None:
            parts.append(series(cl.R(), Wr))
        if self._Wd is not None:
            parts.append(series(cl.S_ud(), self._Wd))
        return _stack(parts)
