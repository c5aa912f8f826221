"""Generalized plant and the lower linear fractional transformation (closed loop of (P, K)).

The standard problem (MATLAB ``lft``/``hinfstruct`` vocabulary): a plant P with exogenous
inputs w, control inputs u, performance outputs z and measurements y,

    x' = A x  + B1 w  + B2 u
    z  = C1 x + D11 w + D12 u
    y  = C2 x + D21 w + D22 u

closed by a controller u = K y, K = (Ak, Bk, Ck, Dk) (a static gain is Ak empty). With
D22 != 0 the loop has an algebraic equation u = Ck xk + Dk (C2 x + D21 w + D22 u); it is
well posed iff I - Dk D22 is invertible, and then, with Q = (I - Dk D22)^-1 and
Qt = (I - D22 Dk)^-1 (= I + D22 Q Dk),

    Acl = [[A + B2 Q Dk C2,  B2 Q Ck], [Bk Qt C2,  Ak + Bk Qt D22 Ck]]
    Bcl = [[B1 + B2 Q Dk D21], [Bk Qt D21]]
    Ccl = [C1 + D12 Q Dk C2,  D12 Q Ck]
    Dcl = D11 + D12 Q Dk D21

the state being [x; xk]. Units are those of the plant's signals (SI in this project).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.synthesis.hinfnorm import StateSpaceData, as_state_space

__all__ = ["GeneralizedPlant", "lft"]


def _mat(x: Any, rows: int, cols: int, name: str) -> NDArray[np.float64]:
    if x is None:
        return np.zeros((rows, cols))
    a = np.atleast_2d(np.asarray(x, dtype=float))
    if a.size == 0 and rows * cols == 0:
        return np.zeros((rows, cols))
    if a.shape != (rows, cols):
        raise ValueError(f"{name} must have shape ({rows}, {cols}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf entries")
    return a


@dataclass(frozen=True)
class GeneralizedPlant:
    """Partitioned plant P = [[P11, P12], [P21, P22]] (see the module docstring).

    Build with :meth:`from_matrices` (COMPleib order A, B1, B2, C1, C2, D11, D12, D21, D22;
    missing D blocks are zero) or :meth:`from_ss` (a state space with the last ``ny`` outputs
    measured and the last ``nu`` inputs controlled, MATLAB ``hinfstruct`` convention).
    Signals are in the plant's own units; x has n states, w nw exogenous inputs, u nu
    controls, z nz performance outputs, y ny measurements.

    Parameters
    ----------
    A : ndarray, shape (n, n)
        State matrix.
    B1, B2 : ndarray, shapes (n, nw), (n, nu)
        Input matrices of w and u.
    C1, C2 : ndarray, shapes (nz, n), (ny, n)
        Output matrices of z and y.
    D11, D12, D21, D22 : ndarray, shapes (nz, nw), (nz, nu), (ny, nw), (ny, nu)
        Feedthrough matrices.

    Examples
    --------
    >>> P = GeneralizedPlant.from_matrices(A=[[-1.0]], B1=[[1.0]], B2=[[1.0]], C1=[[1.0]],
    ...                                    C2=[[1.0]])
    >>> P.D22.shape
    (1, 1)
    """

    A: NDArray[np.float64]
    B1: NDArray[np.float64]
    B2: NDArray[np.float64]
    C1: NDArray[np.float64]
    C2: NDArray[np.float64]
    D11: NDArray[np.float64]
    D12: NDArray[np.float64]
    D21: NDArray[np.float64]
    D22: NDArray[np.float64]

    @classmethod
    def from_matrices(
        cls, A: Any, B1: Any, B2: Any, C1: Any, C2: Any, D11: Any = None, D12: Any = None,
        D21: Any = None, D22: Any = None,
    ) -> GeneralizedPlant:
        """Validated plant from its nine blocks (None = zero of the right size).

        Parameters
        ----------
        A, B1, B2, C1, C2 : array_like
            State, input (w, u) and output (z, y) matrices, COMPleib order.
        D11, D12, D21, D22 : array_like, optional
            Feedthrough matrices; None is a zero block.

        Returns
        -------
        GeneralizedPlant
            The plant.

        Raises
        ------
        ValueError
            For inconsistent shapes or non-finite entries.
        """
        A = np.atleast_2d(np.asarray(A, dtype=float))
        if A.ndim != 2 or A.shape[0] != A.shape[1]:
            raise ValueError(f"A must be square (nx, nx), got shape {A.shape}")
        nx = A.shape[0]
        B1 = np.asarray(B1, dtype=float).reshape(nx, -1)
        B2 = np.asarray(B2, dtype=float).reshape(nx, -1)
        nw, nu = B1.shape[1], B2.shape[1]
        C1 = np.asarray(C1, dtype=float).reshape(-1, nx)
        C2 = np.asarray(C2, dtype=float).reshape(-1, nx)
        nz, ny = C1.shape[0], C2.shape[0]
        return cls(
            _mat(A, nx, nx, "A"), _mat(B1, nx, nw, "B1"), _mat(B2, nx, nu, "B2"),
            _mat(C1, nz, nx, "C1"), _mat(C2, ny, nx, "C2"), _mat(D11, nz, nw, "D11"),
            _mat(D12, nz, nu, "D12"), _mat(D21, ny, nw, "D21"), _mat(D22, ny, nu, "D22"),
        )

    @classmethod
    def from_ss(cls, P: Any, ny: int, nu: int) -> GeneralizedPlant:
        """Partition a state space (A, B, C, D): last ``ny`` outputs = y, last ``nu`` inputs = u.

        Parameters
        ----------
        P : control.StateSpace or tuple
            The state space (see :func:`vtolftc.synthesis.hinfnorm.as_state_space`).
        ny : int
            Number of measurements (the last outputs).
        nu : int
            Number of controls (the last inputs).

        Returns
        -------
        GeneralizedPlant
            The partitioned plant.

        Raises
        ------
        ValueError
            If ny or nu do not fit the system.
        """
        A, B, C, D = as_state_space(P)
        p, m = D.shape
        if not (0 < ny < p + 1 and 0 < nu < m + 1):
            raise ValueError(
                f"ny={ny}, nu={nu} do not fit a plant with {p} outputs and {m} inputs"
            )
        nz, nw = p - ny, m - nu
        return cls.from_matrices(A, B[:, :nw], B[:, nw:], C[:nz], C[nz:], D[:nz, :nw],
                                 D[:nz, nw:], D[nz:, :nw], D[nz:, nw:])

    @property
    def dims(self) -> dict[str, int]:
        """nx, nw, nu, nz, ny."""
        return {"nx": self.A.shape[0], "nw": self.B1.shape[1], "nu": self.B2.shape[1],
                "nz": self.C1.shape[0], "ny": self.C2.shape[0]}

    def gain_scale(self) -> NDArray[np.float64]:
        """Typical magnitude of each static-gain entry K_ij (nu x ny) for this plant.

        A gain that moves the closed-loop eigenvalues by about the plant's own rate:
        max(||A||, 1e-3) / (||B2[:, i]|| ||C2[j, :]||) (entries with a zero column/row get 1).
        Used to scale random starts and default bounds of matrix blocks.

        Returns
        -------
        ndarray of float, shape (nu, ny)
            The scales (controls per measurement unit).
        """
        a = max(float(np.linalg.norm(self.A, 2)) if self.A.size else 0.0, 1e-3)
        b = np.linalg.norm(self.B2, axis=0)
        c = np.linalg.norm(self.C2, axis=1)
        bc = np.outer(b, c)
        out = np.ones_like(bc)
        nz = bc > 0
        out[nz] = a / bc[nz]
        return out

    def closed_loop(self, K: Any) -> StateSpaceData:
        """Closed loop (A, B, C, D) from w to z with u = K y; see :func:`lft`.

        Parameters
        ----------
        K : array_like, tuple or LTI
            The controller, as for :func:`lft`.

        Returns
        -------
        A, B, C, D : ndarray
            The closed loop.
        """
        return lft(self, K)


def _controller(K: Any, nu: int, ny: int) -> StateSpaceData:
    if isinstance(K, tuple | list) and len(K) == 4:
        Ak, Bk, Ck, Dk = as_state_space(tuple(K))
    elif hasattr(K, "A") and hasattr(K, "D"):
        Ak, Bk, Ck, Dk = as_state_space(K)
    else:
        Dk = np.atleast_2d(np.asarray(K, dtype=float))
        Ak, Bk, Ck = np.zeros((0, 0)), np.zeros((0, Dk.shape[1])), np.zeros((Dk.shape[0], 0))
    if Dk.shape != (nu, ny):
        raise ValueError(
            f"controller must map the {ny} measurements to the {nu} controls (shape "
            f"{nu}x{ny}), got {Dk.shape[0]}x{Dk.shape[1]}"
        )
    return Ak, Bk, Ck, Dk


def lft(P: GeneralizedPlant, K: Any, *, wellposed_tol: float = 1e-10) -> StateSpaceData:
    """Lower LFT F_l(P, K): the closed loop w -> z with u = K y (module docstring).

    Parameters
    ----------
    P : GeneralizedPlant
        The plant.
    K : array_like, tuple or control.StateSpace/TransferFunction
        A static gain (nu x ny array), a state space (Ak, Bk, Ck, Dk) tuple or a
        python-control StateSpace/TransferFunction.
    wellposed_tol : float
        The loop is rejected as ill-posed if sigma_min(I - Dk D22) <= wellposed_tol
        (1 + ||Dk|| ||D22||).

    Returns
    -------
    Acl, Bcl, Ccl, Dcl : ndarray
        The closed loop, state [x; xk].

    Raises
    ------
    ValueError
        Wrong controller shape or an ill-posed loop (I - Dk D22 singular).

    Examples
    --------
    x' = -x + w + u, z = x, y = x closed by u = -2 y: x' = -3 x + w.

    >>> P = GeneralizedPlant.from_matrices(A=[[-1.0]], B1=[[1.0]], B2=[[1.0]], C1=[[1.0]],
    ...                                    C2=[[1.0]])
    >>> Acl, Bcl, Ccl, Dcl = lft(P, [[-2.0]])
    >>> Acl.tolist(), Dcl.tolist()
    ([[-3.0]], [[0.0]])
    """
    d = P.dims
    nu, ny = d["nu"], d["ny"]
    Ak, Bk, Ck, Dk = _controller(K, nu, ny)
    dtype = np.result_type(P.A, Ak, Bk, Ck, Dk)
    if np.any(P.D22):
        F = np.eye(nu) - Dk @ P.D22
        smin = float(np.linalg.svd(F, compute_uv=False)[-1]) if nu else 1.0
        if smin <= wellposed_tol * (1.0 + float(np.linalg.norm(Dk, 2) * np.linalg.norm(P.D22, 2))):
            raise ValueError(
                f"the closed loop is ill-posed: I - Dk D22 is singular (sigma_min = {smin:.3g}); "
                "change the controller's feedthrough Dk"
            )
        Q = np.linalg.inv(F)
        Qt = np.eye(ny) + P.D22 @ Q @ Dk
    else:
        Q, Qt = np.eye(nu), np.eye(ny)
    QDk, QCk = Q @ Dk, Q @ Ck
    nx, nk = P.A.shape[0], Ak.shape[0]
    A = np.zeros((nx + nk, nx + nk), dtype=dtype)
    A[:nx, :nx] = P.A + P.B2 @ QDk @ P.C2
    A[:nx, nx:] = P.B2 @ QCk
    A[nx:, :nx] = Bk @ Qt @ P.C2
    A[nx:, nx:] = Ak + Bk @ Qt @ P.D22 @ Ck
    B = np.vstack([P.B1 + P.B2 @ QDk @ P.D21, Bk @ Qt @ P.D21])
    C = np.hstack([P.C1 + P.D12 @ QDk @ P.C2, P.D12 @ QCk])
    D = P.D11 + P.D12 @ QDk @ P.D21
    return A, B, C, D
