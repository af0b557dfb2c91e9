"""A blur-correction pass starts each frame from what the earlier pass left for that frame:
its fit, its penalty and, with the augmented-Lagrangian method, its multipliers."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.imaging.harp import extract_phase
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track


@pytest.fixture(scope="module")
def scene(lv_small):
    made = lv_small
    tagged = made.tagged.isel(time=slice(0, 3))  # two tracked frames keep it fast
    return made, tagged, extract_phase(tagged)


# the correction pass meets frame 2's target in a multiplier update whose solve stops at its
# iteration limit: flagged in 'converged' and warned, which this test does not look at
@pytest.mark.filterwarnings("ignore:the Gauss–Newton solve stopped:harpx.errors.HarpxWarning")
def test_the_augmented_lagrangian_correction_pass_starts_each_frame_from_its_own_multipliers(
    scene,
):
    made, tagged, phase = scene

    # the default: one blur-correction pass
    corrected = track(phase, made.body("stress-free"), dirichlet=made.dirichlet(),
                      method="augmented-lagrangian")  # fmt: skip
    error = tracking_error(corrected, tagged)["mean"].values
    assert int(corrected.attrs["blur_passes_applied"]) == 1
    assert bool(corrected.target_reached.all()), corrected.target_reached.values
    # measured 0.107 / 0.232 mm, better than without the correction (0.117 / 0.284 mm); the
    # correction pass started from the multipliers the first pass ended its LAST frame with
    # lost frame 1 (ε 1.26 rad, 7.1 mm)
    assert np.all(error[1:] <= 1.2 * np.array([0.107, 0.232])), error
    assert float(corrected.epsilon[1]) <= float(corrected.epsilon_target[1])
