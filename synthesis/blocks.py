"""Tunable controller blocks (matrix-valued) composed into a structure and the tuning problem
of a generalized plant closed by them (MATLAB ``tunableGain``, ``tunableSS``, ``tunablePID``).

A block maps its slice of the parameter vector theta to a state space (Ak, Bk, Ck, Dk):

* :class:`StaticGain` -- an n_out x n_in matrix, every entry a parameter (static output
  feedback when it is the whole controller);
* :class:`StateSpaceBlock` -- a fixed-order state space, all entries of (Ak, Bk, Ck, Dk)
  free (an order-n dynamic output feedback);
* :class:`PIDBlock` -- the SISO PID with filtered derivative of
  :func:`vtolftc.synthesis.structured.pid`;
* :class:`PPIDBlock` -- the paper's cascaded P-PID (fig. 5) as one block with inputs
  [angle error e = angle_ref - angle (rad); body rate (rad/s)] and output the moment
  (N m): u = K_rate(s) (kp_angle e - rate), K_rate of
  :func:`vtolftc.synthesis.loops.rate_controller`.

:class:`ControllerStructure` stacks blocks block-diagonally (inputs and outputs
concatenated in order). :func:`lft_problem` closes a
:class:`~vtolftc.synthesis.lft.GeneralizedPlant` (or several, one per model) with the
structure and returns a :class:`~vtolftc.synthesis.structured.TuningProblem` for
:func:`~vtolftc.synthesis.structured.tune`.

Scales, bounds and starts: matrix entries get ``scale`` (the step unit and the standard
deviation of random starts, ``Parameter.sample_sd``) from the plant when the block is given
``plant=`` (:meth:`GeneralizedPlant.gain_scale`), and the bounds |K_ij| <= ``bound`` (default
1e3 x scale): a minimiser can then no longer drift to 1e5-1e10 gains on problems whose infimum
is only approached at infinity. A :class:`StaticGain` with a plant-derived scale keeps the unit
step (``Parameter.scale`` 1): the plant scale sets its random starts and bounds only. All
entries are real; units are those of the plant signals.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.synthesis.hinfnorm import StateSpaceData
from vtolftc.synthesis.lft import GeneralizedPlant, lft
from vtolftc.synthesis.structured import Parameter, TuningProblem, pid

__all__ = [
    "ControllerStructure",
    "LFTChannel",
    "PIDBlock",
    "PPIDBlock",
    "StateSpaceBlock",
    "StaticGain",
    "TunableBlock",
    "lft_problem",
]

DEFAULT_BOUND_FACTOR = 1e3


def _grid(x: Any, shape: tuple[int, int], name: str, default: float) -> NDArray[np.float64]:
    if x is None:
        return np.full(shape, default)
    a = np.asarray(x, dtype=float)
    if a.ndim == 0:
        return np.full(shape, float(a))
    if a.shape != shape:
        raise ValueError(f"{name} must be a scalar or have shape {shape}, got {a.shape}")
    return a.copy()


class TunableBlock:
    """Base class: a named block with parameters and a realisation theta -> (A, B, C, D)."""

    name: str
    n_in: int
    n_out: int
    n_states: int

    def parameters(self) -> list[Parameter]:
        """The block's parameters (names prefixed with the block name).

        Returns
        -------
        list of Parameter
            In the order of the block's slice of theta.
        """
        raise NotImplementedError

    def realize(self, theta: NDArray[np.float64]) -> StateSpaceData:
        """(Ak, Bk, Ck, Dk) for this block's slice of theta.

        Parameters
        ----------
        theta : ndarray of float, shape (n_params,)
            The block's parameter values.

        Returns
        -------
        Ak, Bk, Ck, Dk : ndarray
            Shapes (n_states, n_states), (n_states, n_in), (n_out, n_states), (n_out, n_in).
        """
        raise NotImplementedError

    @property
    def n_params(self) -> int:
        """Number of tunable parameters of the block."""
        return len(self.parameters())

    def _matrix_params(
        self, label: str, initial: NDArray[Any], scale: NDArray[Any], bound: NDArray[Any],
        step_unit: float | None = None,
    ) -> list[Parameter]:
        out = []
        r, c = initial.shape
        for i in range(r):
            for j in range(c):
                s = float(scale[i, j])
                b = float(bound[i, j])
                x0 = float(np.clip(initial[i, j], -b, b))
                out.append(Parameter(f"{self.name}.{label}[{i},{j}]", x0, -b, b,
                                     scale=s if step_unit is None else step_unit,
                                     sample_sd=s))
        return out


@dataclass
class StaticGain(TunableBlock):
    """A tunable n_out x n_in static gain u = K y (units: the plant's controls per measurement).

    Parameters
    ----------
    name : str
        Block name (parameter names are ``name.K[i,j]``).
    n_out, n_in : int
        Shape of K.
    initial : array_like, optional
        Start value, shape (n_out, n_in) (default zeros).
    plant : GeneralizedPlant, optional
        If given (and ``scale`` is None), entry scales from :meth:`GeneralizedPlant.gain_scale`
        for the random starts and the bounds (the optimiser's step unit stays 1); the block
        must then map all the plant's measurements to all its controls.
    scale : float or array_like, optional
        Typical magnitude per entry (scalar or n_out x n_in); default 1 or the plant's.
    bound : float or array_like, optional
        |K_ij| <= bound (scalar or array); default ``DEFAULT_BOUND_FACTOR * scale``; ``inf``
        for unbounded.

    Raises
    ------
    ValueError
        For shapes that do not fit, or a plant whose sizes differ from the block's.

    Examples
    --------
    >>> K = StaticGain("K", 1, 2)
    >>> [p.name for p in K.parameters()]
    ['K.K[0,0]', 'K.K[0,1]']
    """

    name: str
    n_out: int
    n_in: int
    initial: Any = None
    plant: GeneralizedPlant | None = field(default=None, repr=False)
    scale: Any = None
    bound: Any = None

    def __post_init__(self) -> None:
        shape = (self.n_out, self.n_in)
        self.n_states = 0
        if self.scale is None and self.plant is not None:
            gs = self.plant.gain_scale()
            if gs.shape != shape:
                raise ValueError(
                    f"StaticGain {self.name!r} is {shape[0]}x{shape[1]} but the plant has "
                    f"{gs.shape[0]} controls and {gs.shape[1]} measurements"
                )
            self._scale = gs
        else:
            self._scale = _grid(self.scale, shape, "scale", 1.0)
        self._bound = _grid(self.bound, shape, "bound", math.nan)
        self._bound = np.where(np.isnan(self._bound), DEFAULT_BOUND_FACTOR * self._scale,
                               self._bound)
        self._initial = _grid(self.initial, shape, "initial", 0.0)

    def parameters(self) -> list[Parameter]:
        """The gain matrix entries ``K[i,j]``, row-major, as parameters.

        Returns
        -------
        list of Parameter
            n_out * n_in parameters.
        """
        # a plant-derived scale sets the random starts and the bounds, not the optimiser's
        # step unit: on COMPleib HE3 (||A|| = 9.8 from a gravity coupling, eigenvalues below
        # 1.01 rad/s) plant-scaled steps stall at 0.94 where unit steps reach 0.82 (issue 23)
        unit = 1.0 if self.scale is None and self.plant is not None else None
        return self._matrix_params("K", self._initial, self._scale, self._bound, unit)

    def realize(self, theta: NDArray[np.float64]) -> StateSpaceData:
        """Static gain: no states, ``D = theta`` reshaped to (n_out, n_in).

        Parameters
        ----------
        theta : ndarray of float, shape (n_out * n_in,)
            The entries, row-major.

        Returns
        -------
        Ak, Bk, Ck, Dk : ndarray
            Empty state matrices and D of shape (n_out, n_in).
        """
        K = np.asarray(theta, float).reshape(self.n_out, self.n_in)
        return np.zeros((0, 0)), np.zeros((0, self.n_in)), np.zeros((self.n_out, 0)), K


@dataclass
class StateSpaceBlock(TunableBlock):
    """A tunable fixed-order state space (Ak, Bk, Ck, Dk), every entry free.

    Initial realisation: Ak = -rate I (rate: the plant's ||A|| if ``plant`` is given, else
    1 [1/s]), Bk = I-like, Ck = 0, Dk = 0 (or ``initial``). Scales: Ak ~ rate, Bk ~ 1, Ck and
    Dk ~ the plant gain scale.

    Parameters
    ----------
    name : str
        Block name (parameter prefix).
    order : int
        Number of states.
    n_out, n_in : int
        Outputs (controls) and inputs (measurements).
    initial : tuple of array_like, optional
        (Ak, Bk, Ck, Dk) to start from.
    plant : GeneralizedPlant, optional
        Plant whose scales set the start and the parameter scales.
    bound_factor : float
        Every entry is bounded by ``bound_factor`` x its scale.

    Raises
    ------
    ValueError
        For order < 1 or an ``initial`` realisation of the wrong shapes.
    """

    name: str
    order: int
    n_out: int
    n_in: int
    initial: Any = None
    plant: GeneralizedPlant | None = field(default=None, repr=False)
    bound_factor: float = DEFAULT_BOUND_FACTOR

    def __post_init__(self) -> None:
        if self.order < 1:
            raise ValueError(f"StateSpaceBlock order must be >= 1, got {self.order}")
        k, p, m = self.order, self.n_out, self.n_in
        self.n_states = k
        rate = 1.0
        gscale = np.ones((p, m))
        if self.plant is not None:
            rate = max(float(np.linalg.norm(self.plant.A, 2)), 1e-3)
            gs = self.plant.gain_scale()
            if gs.shape == (p, m):
                gscale = gs
        gk = float(np.median(gscale))
        if self.initial is None:
            Ak = -rate * np.eye(k)
            Bk = np.eye(k, m)
            Ck = np.zeros((p, k))
            Dk = np.zeros((p, m))
        else:
            Ak, Bk, Ck, Dk = (np.atleast_2d(np.asarray(x, float)) for x in self.initial)
            if Ak.shape != (k, k) or Bk.shape != (k, m) or Ck.shape != (p, k) or (
                Dk.shape != (p, m)
            ):
                raise ValueError(
                    f"initial (Ak, Bk, Ck, Dk) must have shapes ({k},{k}), ({k},{m}), "
                    f"({p},{k}), ({p},{m})"
                )
        self._init = (Ak, Bk, Ck, Dk)
        self._scales = (np.full((k, k), rate), np.ones((k, m)), np.full((p, k), gk * rate),
                        gscale)

    def parameters(self) -> list[Parameter]:
        """All entries of A, B, C and D (in that order, row-major) as parameters.

        Returns
        -------
        list of Parameter
            order^2 + order (n_in + n_out) + n_out n_in parameters.
        """
        out: list[Parameter] = []
        for label, x0, s in zip("ABCD", self._init, self._scales, strict=True):
            out += self._matrix_params(label, x0, s, self.bound_factor * s)
        return out

    def realize(self, theta: NDArray[np.float64]) -> StateSpaceData:
        """``(A, B, C, D)`` cut from ``theta`` in the order of :meth:`parameters`.

        Parameters
        ----------
        theta : ndarray of float
            The block's parameter values.

        Returns
        -------
        Ak, Bk, Ck, Dk : ndarray
            Shapes (order, order), (order, n_in), (n_out, order), (n_out, n_in).
        """
        k, p, m = self.order, self.n_out, self.n_in
        th = np.asarray(theta, float)
        i = 0
        mats = []
        for r, c in ((k, k), (k, m), (p, k), (p, m)):
            mats.append(th[i : i + r * c].reshape(r, c))
            i += r * c
        return mats[0], mats[1], mats[2], mats[3]


@dataclass
class PIDBlock(TunableBlock):
    """SISO PID kp + ki/s + kd s/(tf s + 1) (:func:`vtolftc.synthesis.structured.pid`).

    Parameters
    ----------
    name : str
        Block name; parameters ``name.kp``, ``name.ki``, ``name.kd``, ``name.tf``.
    kp, ki, kd : float
        Initial gains (ki > 0 is required by the realisation).
    tf : float
        Initial derivative filter time constant (s), > 0.
    bounds : dict of str to (float, float)
        Optional (lower, upper) per gain name.
    """

    name: str
    kp: float = 1.0
    ki: float = 0.1
    kd: float = 0.0
    tf: float = 0.05
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.n_in = self.n_out = 1
        self.n_states = 2

    def parameters(self) -> list[Parameter]:
        """``kp``, ``ki``, ``kd`` and the derivative filter time constant ``tf`` (s).

        Returns
        -------
        list of Parameter
            Four parameters.
        """
        dflt = {"kp": (-1e6, 1e6), "ki": (1e-9, 1e6), "kd": (-1e6, 1e6), "tf": (1e-4, 1e3)}
        out = []
        for k in ("kp", "ki", "kd", "tf"):
            lo, hi = self.bounds.get(k, dflt[k])
            x0 = float(getattr(self, k))
            out.append(Parameter(f"{self.name}.{k}", x0, lo, hi,
                                 scale=max(abs(x0), 1e-3) if x0 else 1.0))
        return out

    def realize(self, theta: NDArray[np.float64]) -> StateSpaceData:
        """State-space PID with filtered derivative for ``theta = (kp, ki, kd, tf)``.

        Parameters
        ----------
        theta : ndarray of float, shape (4,)
            kp, ki, kd, tf (s).

        Returns
        -------
        Ak, Bk, Ck, Dk : ndarray
            As :func:`vtolftc.synthesis.structured.pid`.
        """
        return pid(*(float(v) for v in theta))


@dataclass
class PPIDBlock(TunableBlock):
    """The paper's P-PID cascade as one 1 x 2 block: u = K_rate(s) (kp_angle e - rate).

    Inputs [e = angle_ref - angle (rad); body rate (rad/s)], output moment (N m).

    Parameters
    ----------
    name : str
        Block name; the five parameters are named ``name.<g>`` for g in
        :data:`vtolftc.synthesis.loops.PARAM_NAMES`.
    gains : dict of str to float
        Initial values per gain name.
    bounds : dict of str to (float, float)
        Optional (lower, upper) per gain.

    Raises
    ------
    ValueError
        If ``gains`` lacks one of the five initial gains.
    """

    name: str
    gains: dict[str, float]
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from vtolftc.synthesis.loops import PARAM_NAMES

        missing = [k for k in PARAM_NAMES if k not in self.gains]
        if missing:
            raise ValueError(f"PPIDBlock {self.name!r}: missing initial gains {missing}")
        self.n_in, self.n_out, self.n_states = 2, 1, 2

    def parameters(self) -> list[Parameter]:
        """The five cascaded P-PID gains (angle P, rate P, I, D, derivative filter s).

        Returns
        -------
        list of Parameter
            In :data:`vtolftc.synthesis.loops.PARAM_NAMES` order.
        """
        from vtolftc.synthesis.loops import PARAM_NAMES

        dflt = {"kp_angle": (1e-6, 1e3), "kp_rate": (1e-9, 1e6), "ki_rate": (1e-9, 1e6),
                "kd_rate": (0.0, 1e6), "tf_rate_s": (1e-4, 10.0)}
        out = []
        for k in PARAM_NAMES:
            lo, hi = self.bounds.get(k, dflt[k])
            x0 = float(self.gains[k])
            out.append(Parameter(f"{self.name}.{k}", x0, lo, hi,
                                 scale=max(abs(x0), 1e-3) if x0 else 1.0))
        return out

    def realize(self, theta: NDArray[np.float64]) -> StateSpaceData:
        """Cascaded P-PID for ``theta``: inputs (angle error (rad), rate (rad/s)), output moment.

        The rate loop sees ``kp_angle * e - rate``.

        Parameters
        ----------
        theta : ndarray of float, shape (5,)
            The gains in :data:`vtolftc.synthesis.loops.PARAM_NAMES` order.

        Returns
        -------
        Ak, Bk, Ck, Dk : ndarray
            Shapes (2, 2), (2, 2), (1, 2), (1, 2); output in N m.
        """
        from vtolftc.synthesis.loops import rate_controller

        kpa, kp, ki, kd, tf = (float(v) for v in theta)
        Ar, Br, Cr, Dr = rate_controller(kp, ki, kd, tf)
        mix = np.array([[kpa, -1.0]])  # rate_ref - rate = kp_angle e - rate
        return Ar, Br @ mix, Cr, Dr @ mix


class ControllerStructure:
    """Block-diagonal composition K = diag(K_1, ..., K_n) of tunable blocks.

    K's inputs are the blocks' inputs concatenated in order (they must add up to the plant's
    measurements), its outputs the blocks' outputs (the plant's controls). ``parameters``
    concatenates the blocks' parameters; :meth:`split` and :meth:`realize` map theta back.

    Parameters
    ----------
    blocks : sequence of TunableBlock or TunableBlock
        The blocks, in order.

    Raises
    ------
    ValueError
        Without blocks, or with duplicate block names.
    """

    def __init__(self, blocks: Sequence[TunableBlock] | TunableBlock):
        if isinstance(blocks, TunableBlock):
            blocks = [blocks]
        self.blocks = list(blocks)
        if not self.blocks:
            raise ValueError("a ControllerStructure needs at least one block")
        names = [b.name for b in self.blocks]
        if len(set(names)) != len(names):
            raise ValueError(f"block names must be unique, got {names}")
        self._params = [b.parameters() for b in self.blocks]
        sizes = [len(p) for p in self._params]
        self._slices = []
        i = 0
        for s in sizes:
            self._slices.append(slice(i, i + s))
            i += s
        self.n_in = sum(b.n_in for b in self.blocks)
        self.n_out = sum(b.n_out for b in self.blocks)

    def parameters(self) -> list[Parameter]:
        """Parameters of all blocks, concatenated in block order.

        Returns
        -------
        list of Parameter
            The structure's theta layout.
        """
        return [p for ps in self._params for p in ps]

    def split(self, theta: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
        """theta -> {block name: its parameter slice}.

        Parameters
        ----------
        theta : array_like, shape (n_params,)
            All parameters.

        Returns
        -------
        dict of str to ndarray
            Each block's slice.
        """
        th = np.asarray(theta, float)
        return {b.name: th[s] for b, s in zip(self.blocks, self._slices, strict=True)}

    def realize(self, theta: NDArray[np.float64]) -> StateSpaceData:
        """(Ak, Bk, Ck, Dk) of the block-diagonal controller at theta.

        Parameters
        ----------
        theta : ndarray of float, shape (n_params,)
            All parameters.

        Returns
        -------
        Ak, Bk, Ck, Dk : ndarray
            The block-diagonal realisation (inputs and outputs concatenated in block order).
        """
        th = np.asarray(theta, float)
        parts = [b.realize(th[s]) for b, s in zip(self.blocks, self._slices, strict=True)]
        from scipy.linalg import block_diag

        A = block_diag(*[p[0] for p in parts]) if any(p[0].size for p in parts) else (
            np.zeros((0, 0)))
        nk = A.shape[0]
        B = np.zeros((nk, self.n_in))
        C = np.zeros((self.n_out, nk))
        D = np.zeros((self.n_out, self.n_in))
        s = r = c = 0
        for p in parts:
            ns, (po, pi) = p[0].shape[0], p[3].shape
            B[s : s + ns, c : c + pi] = p[1]
            C[r : r + po, s : s + ns] = p[2]
            D[r : r + po, c : c + pi] = p[3]
            s, r, c = s + ns, r + po, c + pi
        return A, B, C, D


class LFTChannel:
    """Picklable tuning channel theta -> F_l(P, K(theta)) (A, B, C, D).

    Parameters
    ----------
    plant : GeneralizedPlant
        The plant.
    structure : ControllerStructure
        The controller structure closing it.

    Raises
    ------
    ValueError
        If the structure's inputs/outputs do not match the plant's measurements/controls.
    """

    def __init__(self, plant: GeneralizedPlant, structure: ControllerStructure):
        d = plant.dims
        if structure.n_in != d["ny"] or structure.n_out != d["nu"]:
            raise ValueError(
                f"the controller structure maps {structure.n_in} inputs to {structure.n_out} "
                f"outputs but the plant has {d['ny']} measurements and {d['nu']} controls"
            )
        self.plant = plant
        self.structure = structure

    def __call__(self, theta: NDArray[np.float64]) -> StateSpaceData:
        return lft(self.plant, self.structure.realize(theta))


def lft_problem(
    plants: GeneralizedPlant | Sequence[GeneralizedPlant],
    structure: ControllerStructure | TunableBlock | Sequence[TunableBlock],
    *,
    names: Sequence[str] | None = None,
    stability_margin: float = 0.0,
) -> TuningProblem:
    """The structured H-infinity problem min_theta max_i ||F_l(P_i, K(theta))||_inf.

    One channel per plant (several models = a multi-model design).

    Parameters
    ----------
    plants : GeneralizedPlant or sequence of GeneralizedPlant
        The plant(s).
    structure : ControllerStructure, TunableBlock or sequence of TunableBlock
        The controller structure.
    names : sequence of str, optional
        Channel names (default one per plant).
    stability_margin : float
        Required closed-loop decay rate (1/s).

    Returns
    -------
    TuningProblem
        For :func:`~vtolftc.synthesis.structured.tune`.

    Raises
    ------
    ValueError
        If a plant does not fit the structure.

    Examples
    --------
    Static output feedback u = k y of x' = x + w1 + u (unstable), y = x + w2, z = [x; u];
    the optimum is k = -(1 + sqrt(3)) with norm 1 + sqrt(3):

    >>> from vtolftc.synthesis.lft import GeneralizedPlant
    >>> from vtolftc.synthesis.structured import tune
    >>> P = GeneralizedPlant.from_matrices(A=[[1.0]], B1=[[1.0, 0.0]], B2=[[1.0]],
    ...                                    C1=[[1.0], [0.0]], C2=[[1.0]],
    ...                                    D12=[[0.0], [1.0]], D21=[[0.0, 1.0]])
    >>> res = tune(lft_problem(P, StaticGain("K", 1, 1, initial=[[-3.0]])))
    >>> res.stable, round(res.value, 6), round(float(res.theta[0]), 4)
    (True, 2.732051, -2.7321)
    """
    if isinstance(plants, GeneralizedPlant):
        plants = [plants]
    if not isinstance(structure, ControllerStructure):
        structure = ControllerStructure(structure)  # type: ignore[arg-type]
    chans = [LFTChannel(P, structure) for P in plants]
    return TuningProblem(structure.parameters(), chans,
                         list(names) if names is not None else None, stability_margin)
