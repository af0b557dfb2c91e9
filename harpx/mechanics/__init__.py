"""Hyperelastic finite-element mechanics: meshes, bodies, materials, loads, Newton solver.

Public names::

    Body, NeoHookean, Guccione, ActiveContraction, FiberGrowth,
    solve, equilibrate, SolveResult, Fixed, Prescribed, Pressure, BodyForce, box, cylinder, tube,
    tetrahedralize, ventricle, cavity_volume, displacement_at
"""

from __future__ import annotations

from harpx.mechanics.body import Body
from harpx.mechanics.loads import BodyForce, Fixed, Prescribed, Pressure
from harpx.mechanics.locate import displacement_at
from harpx.mechanics.materials import ActiveContraction, FiberGrowth, Guccione, NeoHookean
from harpx.mechanics.mesh import MeshSpec, box, cylinder, tetrahedralize, tube
from harpx.mechanics.newton import SolveResult, equilibrate, solve
from harpx.mechanics.ventricle import cavity_volume, ventricle

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
    "cavity_volume",
    "cylinder",
    "displacement_at",
    "equilibrate",
    "solve",
    "tetrahedralize",
    "tube",
    "ventricle",
]
