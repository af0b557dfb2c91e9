r"""Ground truth of the left-ventricle scene: the forward systole and its motion.

The systolic sequence is *simulated* on a finer hexahedral mesh than the tracking model
(see :mod:`harpx.scenes.lv`): :class:`Systole` is the quasi-static loading (active
tension by the calcium law and cavity pressure, both rising with one activation level),
:func:`simulate_systole` continues that level from 0 to 1 by Newton's method and picks the
frame levels that follow an ejection curve, and :class:`FEMotion` turns the frame
displacements into the motion ``u(X, t)`` with its inverse that image synthesis needs.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray
from harpx.errors import ConvergenceError
from harpx.mechanics.body import Body
from harpx.mechanics.linsolve import LinearSolver
from harpx.mechanics.loads import Pressure
from harpx.mechanics.locate import HexLocator, trilinear
from harpx.mechanics.newton import equilibrate
from harpx.tracking.results import tracked_dataset

__all__ = ["FEMotion", "Systole", "simulate_systole"]


@dataclass(frozen=True)
class Systole:
    """Quasi-static systolic loading (see the module docstring).

    Parameters
    ----------
    t_max : float
        Active tension parameter at end systole, kPa (calcium law).
    pressure : float
        End-systolic cavity pressure, kPa.
    """

    t_max: float = 60.0
    pressure: float = 8.0

    @staticmethod
    def ejection_profile(frames: int) -> FloatArray:
        """Fraction of the end-systolic ejected volume at every frame: ``(1 - cos πs)/2``.

        Parameters
        ----------
        frames : int
            Number of frames, frame 0 the reference.

        Returns
        -------
        ndarray, shape (frames,)
            Ejected fraction (dimensionless) at ``s = n / (frames - 1)``: 0 at frame 0,
            1 at the last.
        """
        s = np.arange(frames) / max(frames - 1, 1)
        return 0.5 * (1.0 - np.cos(np.pi * s))


def _advance(
    body: Body,
    systole: Systole,
    dirichlet: list[Any],
    u: FloatArray,
    a_from: float,
    a_to: float,
    solver: LinearSolver,
    info: dict[str, Any],
    *,
    tol: float,
    max_iterations: int,
    step: float | None = None,
    tension: FloatArray | float = 1.0,
) -> list[tuple[float, FloatArray]]:
    """Newton continuation in the activation level from ``a_from`` to ``a_to``.

    ``tension`` scales the active tension per cell (``a t_max tension``).
    """
    done = a_from
    step = a_to - a_from if step is None else step
    accepted: list[tuple[float, FloatArray]] = []
    while done < a_to - 1e-12:
        # the level grows at most geometrically: the response is strongly nonlinear early on
        a = min(a_to, done + step, 2.0 * done) if done > 0 else min(a_to, step)
        body.set_t_max(systole.t_max * a * tension)
        loads = [*dirichlet, Pressure("endo", systole.pressure * a)]
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            r = equilibrate(
                body,
                loads,
                u,
                1.0,
                tol=tol,
                max_iterations=max_iterations,
                linear_solver=solver,
                raise_on_failure=False,
            )
        info["iterations"] += r.iterations
        if r.converged:
            u, done = r.u, a
            accepted.append((a, u))
            info["steps"] += 1
            step = 2.0 * (a - (accepted[-2][0] if len(accepted) > 1 else a_from))
        else:
            info["cutbacks"] += 1
            step = 0.5 * (a - done)
            if step < 1e-7:
                raise ConvergenceError(
                    f"the systolic simulation stalled at activation level {done:.4g}; lower "
                    "Systole.t_max or Systole.pressure",
                    [],
                )
    return accepted


def simulate_systole(
    body: Body,
    frames: int,
    systole: Systole,
    dirichlet: list[Any],
    *,
    tol: float = 1e-7,
    max_iterations: int = 10,
    linear_solver: str = "auto",
    tension: ArrayLike | None = None,
) -> tuple[FloatArray, dict[str, Any]]:
    """Quasi-static systole whose cavity volume follows an ejection curve over the frames.

    The activation level ``a`` (active tension ``a t_max``, cavity pressure
    ``a pressure``) is continued from 0 to 1 by Newton's method, recording the cavity
    volume :math:`V(a)`. The frame levels :math:`a_n` are then chosen so that the ejected
    volume :math:`V_0 - V(a_n)` is the fraction ``Systole.ejection_profile`` (a smooth step
    in time) of the end-systolic one, and each frame is solved at its level starting from
    the nearest recorded state below it.

    Parameters
    ----------
    body : Body
        Ventricle body (``"endo"`` and ``"base"`` boundaries) with an active contraction
        law (``body.active``).
    frames : int
        Number of frames including the reference (>= 2).
    systole : Systole
        Peak active tension and pressure.
    dirichlet : list
        Dirichlet conditions.
    tol : float, default 1e-7
        Newton tolerance (relative residual).
    max_iterations : int, default 10
        Newton iterations before a continuation step is halved.
    linear_solver : str, default "auto"
        See :mod:`harpx.mechanics.linsolve`.
    tension : array_like, shape (ncell,), optional
        Factor of the active tension per cell, in [0, 1] (dimensionless): a cell's active
        tension parameter is ``a · t_max · tension``. Default 1 everywhere; 0 leaves a cell
        passive (a transmural infarct, :func:`harpx.scenes.lv.lv`).

    Returns
    -------
    U : ndarray, shape (frames, ndof)
        Displacement of every frame, mm (``U[0] = 0``).
    info : dict
        ``levels`` (activation per frame), ``ejection_fraction`` (per frame,
        :math:`1 - V/V_0`), ``iterations``, ``steps``, ``cutbacks``, ``wall_time`` (s).

    Raises
    ------
    ConvergenceError
        If the continuation stalls.
    ValueError
        If ``frames`` < 2, or ``tension`` is not (ncell,) values in [0, 1].
    """
    from harpx.anatomy.ventricle import cavity_volume

    if int(frames) < 2:
        raise ValueError(f"frames={frames!r} must be >= 2")
    scale: FloatArray | float = 1.0
    if tension is not None:
        scale = np.asarray(tension, dtype=np.float64)
        if scale.shape != (body.ncell,) or not np.all((scale >= 0.0) & (scale <= 1.0)):
            raise ValueError(
                f"tension must hold one factor in [0, 1] per cell, shape ({body.ncell},); "
                f"got shape {scale.shape!r}"
            )
    start = _time.perf_counter()
    solver = LinearSolver(linear_solver)
    info: dict[str, Any] = {"iterations": 0, "steps": 0, "cutbacks": 0}
    v0 = cavity_volume(body)
    path = [(0.0, np.zeros(body.ndof))]
    path += _advance(
        body,
        systole,
        dirichlet,
        path[0][1],
        0.0,
        1.0,
        solver,
        info,
        tol=tol,
        max_iterations=max_iterations,
        step=1.0 / 64.0,
        tension=scale,
    )
    levels = np.array([a for a, _ in path])
    ejected = np.maximum.accumulate(np.array([v0 - cavity_volume(body, u) for _, u in path]))
    if not ejected[-1] > 0:
        raise ConvergenceError(
            "the simulated systole does not eject (end-systolic volume >= reference); raise "
            "Systole.t_max or lower Systole.pressure",
            [],
        )
    target = Systole.ejection_profile(int(frames)) * ejected[-1]
    frame_levels = np.interp(target, ejected, levels)
    frame_levels[0], frame_levels[-1] = 0.0, 1.0
    U = np.zeros((int(frames), body.ndof))
    for n in range(1, int(frames)):
        k = int(np.searchsorted(levels, frame_levels[n], side="right")) - 1
        a_k, u_k = path[k]
        if frame_levels[n] - a_k < 1e-12:
            U[n] = u_k
            continue
        U[n] = _advance(
            body,
            systole,
            dirichlet,
            u_k,
            a_k,
            float(frame_levels[n]),
            solver,
            info,
            tol=tol,
            max_iterations=max_iterations,
            tension=scale,
        )[-1][1]
    body.set_t_max(systole.t_max * scale)
    info["levels"] = frame_levels
    info["ejection_fraction"] = np.array([1.0 - cavity_volume(body, u) / v0 for u in U])
    info["wall_time"] = _time.perf_counter() - start
    return U, info


# ------------------------------------------------------------------------ FE motion


class FEMotion:
    """A hex8 finite-element displacement history as a motion ``u(X, t)`` with its inverse.

    Parameters
    ----------
    body : Body
        hex8 body whose dofs ``U`` refer to (reference configuration, mm).
    U : ndarray, shape (ntime, ndof)
        Displacement per frame (mm); ``U[0]`` is the reference (zero).
    times : array_like, shape (ntime,)
        Frame times, ms. The motion is defined at these times only.

    Notes
    -----
    ``u(X, t)`` interpolates the displacement at reference points (NaN outside the mesh).
    ``inverse(x, t)`` is the reference position of the material at spatial points: the
    points are located in the deformed mesh (trilinear cells, exact for hex8) and mapped
    back; points outside the deformed body are sent 10 m away, where
    :meth:`density` is 0. Used as ``synthesize_tagged(motion, inverse=motion.inverse,
    body=motion.density)``.
    """

    FAR = np.array([0.0, 0.0, 1.0e4])

    def __init__(self, body: Body, U: ArrayLike, times: ArrayLike) -> None:
        if body.element != "hex8":
            raise ValueError(f"FEMotion needs a hex8 body, got {body.element!r}")
        self.body = body
        self.U = np.asarray(U, dtype=np.float64)
        self.times = np.asarray(times, dtype=np.float64)
        if self.U.shape != (self.times.size, body.ndof):
            raise ValueError(
                f"U has shape {self.U.shape!r}; expected ({self.times.size}, {body.ndof})"
            )
        self._reference = HexLocator(body.nodes, body.cells)
        self._deformed: dict[int, HexLocator] = {}
        # synthesize_tagged asks for density(inverse(x)) and for u at the same voxel centres
        # every frame: remember the last located arrays instead of locating them again
        self._last_inverse: tuple[FloatArray, np.ndarray] | None = None
        self._located: dict[tuple, tuple[IntArray, FloatArray]] = {}

    @staticmethod
    def _key(X: FloatArray) -> tuple:
        return (X.shape, X.ctypes.data, float(X[0, 0]), float(X[-1, -1]), float(X.sum()))

    def _locate_reference(self, X: FloatArray) -> tuple[IntArray, FloatArray]:
        if X.size == 0:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        key = self._key(X)
        if key not in self._located:
            if len(self._located) >= 4:
                self._located.pop(next(iter(self._located)))
            self._located[key] = self._reference.locate(X)
        return self._located[key]

    def frame(self, t: float) -> int:
        """Index of the frame at time ``t`` (ms).

        Parameters
        ----------
        t : float
            A frame time of the motion, ms.

        Returns
        -------
        int
            Index into ``times`` (and the rows of ``U``).

        Raises
        ------
        ValueError
            If ``t`` is not one of the frame times.
        """
        n = int(np.argmin(np.abs(self.times - float(t))))
        if abs(self.times[n] - float(t)) > 1e-6 * max(1.0, float(np.abs(self.times).max())):
            raise ValueError(
                f"t={t!r} ms is not a frame time of this motion {self.times.tolist()!r}"
            )
        return n

    def _nodal(self, n: int) -> FloatArray:
        return self.U[n].reshape(-1, 3)[: len(self.body.nodes)]

    def displacement(self, points: ArrayLike) -> FloatArray:
        """Displacement of every frame at reference points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Reference positions, mm.

        Returns
        -------
        ndarray, shape (ntime, n, 3)
            Displacement, mm; NaN at points outside the reference mesh.
        """
        cells, xi = self._reference.locate(np.asarray(points, dtype=np.float64))
        out = np.full((self.times.size, len(cells), 3), np.nan)
        inside = cells >= 0
        if inside.any():
            N = trilinear(xi[inside])
            vert = self.body.cells[cells[inside]]  # (m, 8)
            nodal = self.U.reshape(self.times.size, -1, 3)  # (ntime, nnode, 3)
            out[:, inside] = np.einsum("ma,tmai->tmi", N, nodal[:, vert])
        return out

    def __call__(self, X: ArrayLike, t: float) -> FloatArray:
        """Displacement (n, 3) mm at reference points ``X`` (n, 3) mm; NaN outside."""
        n = self.frame(t)
        cells, xi = self._locate_reference(np.asarray(X, dtype=np.float64).reshape(-1, 3))
        out = np.full((len(cells), 3), np.nan)
        inside = cells >= 0
        N = trilinear(xi[inside])
        out[inside] = np.einsum("ma,mai->mi", N, self._nodal(n)[self.body.cells[cells[inside]]])
        return out

    def inverse(self, x: ArrayLike, t: float) -> FloatArray:
        """Reference positions of the material at spatial points.

        Parameters
        ----------
        x : array_like, shape (n, 3)
            Spatial (deformed) positions, mm.
        t : float
            A frame time of the motion, ms (:meth:`frame`).

        Returns
        -------
        ndarray, shape (n, 3)
            Reference positions, mm; a point outside the deformed body is sent to
            ``x + FAR`` (10 m above it along z), where :meth:`density` is 0.
        """
        n = self.frame(t)
        x = np.asarray(x, dtype=np.float64)
        if n == 0:
            return x.copy()
        if n not in self._deformed:
            self._deformed[n] = HexLocator(self.body.nodes + self._nodal(n), self.body.cells)
        cells, xi = self._deformed[n].locate(x)
        X = x + self.FAR
        inside = cells >= 0
        N = trilinear(xi[inside])
        X[inside] = np.einsum("ma,mai->mi", N, self.body.nodes[self.body.cells[cells[inside]]])
        self._last_inverse = (X, inside)
        return X

    def as_tracked(self, grid: xr.Dataset) -> xr.Dataset:
        """The motion as a finite-element result on its own (fine) mesh, ``tracked/1``.

        Parameters
        ----------
        grid : xarray.Dataset
            Dataset with the ``time`` coordinate (ms, the motion's frame times) and the
            ``z``, ``y``, ``x`` voxel centres (mm) of ``displacement_grid``, e.g. the
            scene's ``tagged`` images.

        Returns
        -------
        xarray.Dataset
            ``tracked/1`` (:func:`harpx.tracking.results.tracked_dataset`): ``points``,
            ``cells``, ``displacement`` (mm), ``green_strain``, ``fiber_stretch`` and
            ``displacement_grid`` of the forward simulation, ``observed_fraction`` 1 for
            every cell and axis (the truth knows every direction) and ``attrs["method"] =
            "forward simulation"``; what :func:`harpx.cardiac.strain.cardiac_strain`
            takes to give the true segment strains.

        Raises
        ------
        ValueError
            If the grid's times are not the motion's.
        """
        times = np.asarray(grid["time"].values, dtype=np.float64)
        if times.shape != self.times.shape or not np.allclose(times, self.times):
            raise ValueError(
                f"the grid's times {times.tolist()!r} ms are not the motion's "
                f"{self.times.tolist()!r}"
            )
        known: dict[str, Any] = {
            "observed_fraction": (("cell", "axis"), np.ones((self.body.ncell, 3)))
        }
        return tracked_dataset(self.body, self.U, grid, known, {"method": "forward simulation"})

    def density(self, X: ArrayLike) -> FloatArray:
        """Body indicator at reference points: 1 inside the reference mesh, 0 outside.

        Parameters
        ----------
        X : array_like, shape (n, 3)
            Reference positions, mm (e.g. the output of :meth:`inverse`).

        Returns
        -------
        ndarray of float, shape (n,)
            1.0 inside the mesh, 0.0 outside.
        """
        if self._last_inverse is not None and self._last_inverse[0] is X:
            return self._last_inverse[1].astype(np.float64)
        cells, _ = self._reference.locate(np.asarray(X, dtype=np.float64))
        return (cells >= 0).astype(np.float64)
