"""The hyperelastic finite-element engine: meshes, bodies, materials, loads, Newton solver.

Public names::

    Body, NeoHookean, Guccione, ActiveContraction, FiberGrowth,
    solve, equilibrate, SolveResult, Fixed, Prescribed, Pressure, BodyForce, box, cylinder, tube,
    tetrahedralize, displacement_at

Anatomy built on it (segmentation mesher, ventricle and tongue templates, template fits)
lives in :mod:`harpx.anatomy`, physiological experiments (active contraction, growth,
cuts) in :mod:`harpx.physiology`. ``harpx.mechanics.ventricle`` and ``cavity_volume``
still resolve, with a :class:`DeprecationWarning`.
"""

from __future__ import annotations

from harpx._moved import moved_getattr
from harpx.mechanics.body import Body
from harpx.mechanics.fiber_laws import ActiveContraction, FiberGrowth
from harpx.mechanics.loads import BodyForce, Fixed, Prescribed, Pressure
from harpx.mechanics.locate import displacement_at
from harpx.mechanics.materials import Guccione, NeoHookean
from harpx.mechanics.mesh import MeshSpec, box, cylinder, tetrahedralize, tube
from harpx.mechanics.newton import SolveResult, equilibrate, solve

__all__ = [
    "ActiveContraction",
    "Body",
    "BodyForce",
    "FiberGrowth",
    "Fixed",
    "Guccione",
    "MeshSpec",
    "NeoHookean",
    "Prescribed",
    "Pressure",
    "SolveResult",
    "box",
    "cylinder",
    "displacement_at",
    "equilibrate",
    "solve",
    "tetrahedralize",
    "tube",
]


__getattr__ = moved_getattr(__name__)
