"""Harmonic phase error against the band-pass radius, SPAMM beside CSPAMM.

SPAMM images keep the tissue's untagged signal, a peak at zero frequency that grows as the
tags fade; CSPAMM subtracts it. A disk band-pass of radius r (a fraction of the tag
frequency) around the tag peak comes within (1 - r) of the tag frequency of that peak.
This synthesises a still, noise-free cylinder (44 mm across, 18 mm high, 7 mm tags, 1.5 mm
voxels, frames at 0 and 200 ms with T1 = 850 ms) with both sequences, extracts the phase
at native resolution with each radius, and records the mean |wrapped phase error| against
the known tag phase over the voxels at least half a tag period inside the body, averaged
over the two frames and the three tags.

Writes ``benchmarks/results/spamm_radius.md``.

Usage::

    python benchmarks/spamm_radius.py
"""

from __future__ import annotations

import platform
import time
import warnings
from pathlib import Path

import numpy as np

from harpx.errors import HarpxWarning
from harpx.imaging.harp import extract_phase
from harpx.imaging.phase_parameters import SPAMM_MAX_RADIUS
from harpx.imaging.synth import synthesize_tagged

RESULTS = Path(__file__).resolve().parent / "results"
RADII = (0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95, 1.0)
PERIOD, RADIUS, HALF_HEIGHT = 7.0, 22.0, 9.0


def _cylinder(X: np.ndarray) -> np.ndarray:
    return ((np.hypot(X[:, 0], X[:, 1]) <= RADIUS) & (np.abs(X[:, 2]) <= HALF_HEIGHT)) * 1.0


def phase_error(sequence: str, radius: float) -> tuple[float, bool]:
    """Mean |phase error| (rad) and whether ``extract_phase`` warned about the radius."""
    tagged = synthesize_tagged(
        lambda X, t: np.zeros_like(X), times=[0.0, 200.0], sequence=sequence, snr=None,
        body=_cylinder, oversample=2, shape=(16, 48, 48), spacing=(1.5, 1.5, 1.5),
        tag_period=PERIOD,
    )  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", HarpxWarning)
        phase = extract_phase(tagged, upsample=1, radius=radius)
    warned = any("SPAMM images band-passed" in str(w.message) for w in caught)
    z, y, x = np.meshgrid(phase.z.values, phase.y.values, phase.x.values, indexing="ij")
    X = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    margin = PERIOD / 2
    keep = (np.hypot(X[:, 0], X[:, 1]) <= RADIUS - margin) & (
        np.abs(X[:, 2]) <= HALF_HEIGHT - margin
    )
    wave = 2 * np.pi * phase.tag_frequency.values[:, None] * phase.tag_direction.values
    errors = []
    for frame in range(phase.sizes["time"]):
        values = phase.phase.isel(time=frame).values.reshape(phase.sizes["tag"], -1)
        wrapped = np.angle(np.exp(1j * (values - wave @ X.T)))
        errors.append(np.abs(wrapped)[:, keep].mean())
    return float(np.mean(errors)), warned


def main() -> None:
    rows = {seq: [phase_error(seq, r) for r in RADII] for seq in ("SPAMM", "CSPAMM")}
    lines = [
        "# Harmonic phase error against the band-pass radius",
        "",
        f"`python benchmarks/spamm_radius.py` ({time.strftime('%Y-%m-%d')}, "
        f"{platform.machine()}). Still, noise-free cylinder, frames at 0 and 200 ms; mean "
        "|wrapped phase error| (rad) over the voxels half a tag period inside the body, the "
        f"two frames and three tags. `extract_phase` warns for SPAMM above radius "
        f"{SPAMM_MAX_RADIUS:g} (*).",
        "",
        "| radius | " + " | ".join(f"{r:g}" for r in RADII) + " |",
        "|---|" + "---|" * len(RADII),
    ]
    for seq, values in rows.items():
        cells = [f"{e:.3f}{' *' if warned else ''}" for e, warned in values]
        lines.append(f"| {seq} | " + " | ".join(cells) + " |")
    text = "\n".join(lines) + "\n"
    path = RESULTS / "spamm_radius.md"
    path.write_text(text)
    print(text)
    print(f"written {path}")


if __name__ == "__main__":
    main()
