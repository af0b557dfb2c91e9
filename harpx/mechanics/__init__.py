"""Hyperelastic finite-element mechanics (bodies, materials, loads, Newton solver)."""
