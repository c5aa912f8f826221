"""Classical loop-margin requirements as constraints of a gain-surface design.

The validation (:mod:`vtolftc.synthesis.validation`) checks a schedule against
:class:`~vtolftc.synthesis.validation.Requirements`: 6 dB gain margin, 30 deg phase margin
and the 50 ms extra-delay margin of the loop broken at the plant input. Here the same
margins (:func:`~vtolftc.synthesis.validation.loop_margins_classical`, on the same loop
:func:`~vtolftc.synthesis.robust.loop_frequency_response` of the same design plant) are
computed at every airspeed of a design grid and turned into a penalty:

    v(theta) = sum_k  max(0, 1 - DM_k / DM_t) + max(0, 1 - |PM_k| / PM_t)
                     + max(0, 1 - GM_k / GM_t)                             (dimensionless)

(GM in dB, the upper gain margin, and the lower one for a conditionally stable loop), with
the targets ``DM_t, PM_t, GM_t`` = the requirements times ``1 + target_margin`` (default
4 %: the validation grid also checks the airspeeds between the design grid's, where the
gains are interpolated). v = 0 exactly when every design-grid point meets the targets.

Speed: the plant's frequency response on the search grid (400 log-spaced frequencies,
1e-2 .. 1e3 rad/s) is computed once; each evaluation forms the P-PID's response in closed
form and refines only the crossings (Brent) with exact single-frequency responses (the
plain resolvent of the state-space data).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.hinfnorm import StateSpaceData, as_state_space
from vtolftc.synthesis.models import Axis
from vtolftc.synthesis.validation import ClassicalMargins, Requirements, loop_margins_classical

__all__ = ["MARGIN_SEARCH_OMEGAS", "MarginConstraints"]

#: The crossing search grid [rad/s].
MARGIN_SEARCH_OMEGAS = np.logspace(-2, 3, 400)


def _pid_response(g: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.complex128]:
    """K_rate(j w) = kp + ki / s + kd s / (tf s + 1) (:func:`~vtolftc.synthesis.loops.
    rate_controller`)."""
    s = 1j * w
    return g[1] + g[2] / s + g[3] * s / (g[4] * s + 1.0)


def _plant_response(G: StateSpaceData, w: NDArray[np.float64]) -> NDArray[np.complex128]:
    """C (j w I - A)^-1 B + D at each frequency, shape (n, p, m) (the plain resolvent: no
    wrapper overhead for the single frequencies of the crossing refinement)."""
    A, B, C, D = G
    n = A.shape[0]
    M = 1j * np.asarray(w, float)[:, None, None] * np.eye(n) - A
    return C @ np.linalg.solve(M, np.broadcast_to(B, (len(w), *B.shape))) + D


@dataclass
class MarginConstraints:
    """The margin penalty v(theta) of the module docstring on one axis and grid.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    airspeeds_m_s : sequence of float
        The design grid's airspeeds [m/s].
    requirements : Requirements, optional
        Default the validation's (6 dB, 30 deg, 50 ms).
    target_margin : float, optional
        Relative margin of the targets over the requirements.
    """

    af: Airframe
    axis: Axis
    airspeeds_m_s: Sequence[float]
    requirements: Requirements = field(default_factory=Requirements)
    target_margin: float = 0.04

    def __post_init__(self) -> None:
        from vtolftc.synthesis.robust import design_plant

        self._plants = [as_state_space(design_plant(self.af, self.axis, float(v)))
                        for v in self.airspeeds_m_s]
        w = MARGIN_SEARCH_OMEGAS
        self._F = [_plant_response(G, w) for G in self._plants]
        r, k = self.requirements, 1.0 + self.target_margin
        self.targets = (k * r.delay_margin_s, k * r.phase_margin_deg, k * r.gain_margin_db)

    def margins(self, gains: NDArray[np.float64]) -> list[ClassicalMargins]:
        """The margins at every grid airspeed.

        Parameters
        ----------
        gains : ndarray of float, shape (n_grid, 5)
            The gains at the grid airspeeds (:data:`~vtolftc.synthesis.loops.PARAM_NAMES`
            order).

        Returns
        -------
        list of ClassicalMargins
            One per grid airspeed.
        """
        w = MARGIN_SEARCH_OMEGAS
        out = []
        for G, F, g in zip(self._plants, self._F, np.asarray(gains, float), strict=True):
            grid_L = _pid_response(g, w) * (g[0] * F[:, 1, 0] + F[:, 0, 0])

            def L(x: NDArray[np.float64], G: StateSpaceData = G, g: NDArray[np.float64] = g,
                  grid_L: NDArray[np.complex128] = grid_L) -> NDArray[np.complex128]:
                if x is w:
                    return grid_L
                Fx = _plant_response(G, x)
                return _pid_response(g, x) * (g[0] * Fx[:, 1, 0] + Fx[:, 0, 0])

            out.append(loop_margins_classical(L, w))
        return out

    def violation(self, gains: NDArray[np.float64]) -> float:
        """v of the module docstring (0 when every target holds).

        Parameters
        ----------
        gains : ndarray of float, shape (n_grid, 5)
            The gains at the grid airspeeds.

        Returns
        -------
        float
            Dimensionless.
        """
        dm_t, pm_t, gm_t = self.targets
        v = 0.0
        for m in self.margins(gains):
            dm = m.delay_margin_s if math.isfinite(m.delay_margin_s) else math.inf
            v += max(0.0, 1.0 - dm / dm_t)
            if math.isfinite(m.phase_margin_deg):
                v += max(0.0, 1.0 - abs(m.phase_margin_deg) / pm_t)
            v += max(0.0, 1.0 - m.gain_margin_upper_db / gm_t)
            if m.gain_margin_lower > 0.0:
                v += max(0.0, 1.0 + m.gain_margin_lower_db / gm_t)
        return v
