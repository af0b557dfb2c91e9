"""Inverse problems on tracked motion: muscle activation from tracked fibre stretch.

Public names::

    estimate_activation, correct_activation, calibrate_activation, resimulate,
    simulate_activation, simulate_history, plot_stretch_agreement
"""

from __future__ import annotations

from harpx.inverse.activation import (
    calibrate_activation,
    correct_activation,
    estimate_activation,
    plot_stretch_agreement,
    resimulate,
    simulate_activation,
    simulate_history,
)

__all__ = [
    "calibrate_activation",
    "correct_activation",
    "estimate_activation",
    "plot_stretch_agreement",
    "resimulate",
    "simulate_activation",
    "simulate_history",
]
