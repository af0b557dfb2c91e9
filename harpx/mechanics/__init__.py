"""Hyperelastic finite-element mechanics: meshes, bodies, materials, loads, Newton solver.

Public names::

    Body, NeoHookean, Guccione, ActiveContraction, FiberGrowth,
    solve, equilibrate, SolveResult, Fixed, Prescribed, Pressure, BodyForce, box, cylinder, tube
"""

from __future__ import annotations

from harpx.mechanics.body import Body
from harpx.mechanics.loads import BodyForce, Fixed, Prescribed, Pressure
from harpx.mechanics.materials import ActiveContraction, FiberGrowth, Guccione, NeoHookean
from harpx.mechanics.mesh import MeshSpec, box, cylinder, tube
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
    "equilibrate",
    "solve",
    "tube",
]
