"""How well the images' tag frequency can be read from tissue that spans few tag periods.

``measure_tag_frequency`` locates the tag peak of the images' spectrum. A disc of tissue
(radius 8-30 mm, CSPAMM tags along x and y, 6 and 8 mm periods, SNR 20, 1.5 mm pixels)
in a field of view of at least 48 mm is measured twice per noise realisation: with the
span rule off (``MIN_PERIODS`` set to 0, so only the spectrum decides) and as the library
does it (NaN below ``MIN_PERIODS`` periods across the tissue). The table gives the largest
|measured / true - 1| over the realisations and the two tags, against the tolerance above
which ``extract_phase`` warns that the tags miss their stated frequency.

Writes ``benchmarks/results/tag_frequency_span.md``.

Usage::

    python benchmarks/tag_frequency_span.py [--seeds 10]
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

from harpx.imaging import tag_frequency
from harpx.imaging.synth import synthesize_tagged

RESULTS = Path(__file__).resolve().parent / "results"
CASES = [(r, p) for r in (8.0, 12.0, 16.0, 20.0, 30.0) for p in (6.0, 8.0)]


def worst_errors(radius: float, period: float, seeds: int) -> tuple[float, float]:
    """Largest relative error with the span rule off, and as the library measures (NaN:
    not measured in some realisation)."""
    raw, kept = [], []
    for seed in range(seeds):
        tagged = synthesize_tagged(
            lambda X, t: 0 * X, shape=(2, 32 if radius < 20 else 64, 32 if radius < 20 else 64),
            spacing=(2.0, 1.5, 1.5), times=[0.0], tags=("x", "y"), tag_period=period,
            snr=20.0, oversample=1, rng=np.random.default_rng(seed),
            body=lambda X: (np.hypot(X[:, 0], X[:, 1]) < radius).astype(float),
        )  # fmt: skip
        kept.append(np.abs(tag_frequency.measure_tag_frequency(tagged) * period - 1).max())
        rule = tag_frequency.MIN_PERIODS
        tag_frequency.MIN_PERIODS = 0.0
        try:
            raw.append(np.abs(tag_frequency.measure_tag_frequency(tagged) * period - 1).max())
        finally:
            tag_frequency.MIN_PERIODS = rule
    return float(np.max(raw)), float(np.max(kept))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=10, help="noise realisations per case")
    seeds = parser.parse_args().seeds
    lines = [
        "# Tag frequency from tissue that spans few tag periods",
        "",
        f"`python benchmarks/tag_frequency_span.py --seeds {seeds}` "
        f"({time.strftime('%Y-%m-%d')}, {platform.machine()}). A disc of tissue, CSPAMM tags "
        "along x and y, SNR 20, 1.5 mm pixels; the largest |measured / true − 1| over "
        f"{seeds} noise realisations and both tags. `extract_phase` warns above "
        f"{tag_frequency.FREQUENCY_TOLERANCE:.0%}; the library does not measure below "
        f"{tag_frequency.MIN_PERIODS:g} periods across the tissue (NaN).",
        "",
        "| disc radius (mm) | tag period (mm) | periods across | span rule off | library |",
        "|---|---|---|---|---|",
    ]
    for radius, period in CASES:
        raw, kept = worst_errors(radius, period, seeds)
        library = "not measured" if np.isnan(kept) else f"{kept:.2%}"
        lines.append(
            f"| {radius:g} | {period:g} | {2 * radius / period:.2f} | {raw:.2%} | {library} |"
        )
    text = "\n".join(lines) + "\n"
    path = RESULTS / "tag_frequency_span.md"
    path.write_text(text)
    print(text)
    print(f"written {path}")


if __name__ == "__main__":
    main()
