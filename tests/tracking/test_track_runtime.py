"""A tracked result records its run time by stage; the error-against-run-time figure reads it."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from harpx.errors import SchemaError
from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import track_harp
from harpx.plotting import error_vs_runtime
from harpx.plotting.figures import run_seconds
from harpx.scenes.phantom import phantom
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track

STAGES = ("time_phase", "time_setup", "time_first_pass", "time_blur", "time_correction_pass",
          "time_output")  # fmt: skip


@pytest.fixture(scope="module")
def runs():
    scene = phantom("small")
    tagged = scene.tagged.isel(time=slice(0, 3))  # two tracked frames keep it fast
    phase = extract_phase(tagged)
    fe = track(phase, scene.body())  # defaults: a first pass and a correction pass
    harp = track_harp(phase, points=tagged)
    return tagged, fe, harp


def test_the_stages_of_a_run_with_a_correction_pass_add_up_to_its_total(runs):
    _, fe, _ = runs
    assert int(fe.attrs["blur_passes_applied"]) == 1
    times = {k: float(fe.attrs[k]) for k in (*STAGES, "time_total")}
    assert times["time_first_pass"] > 0 and times["time_correction_pass"] > 0
    assert times["time_blur"] > 0
    # timer reads between the stages cost microseconds: 2 % + 10 ms of slack
    staged = sum(times[k] for k in STAGES)
    assert abs(times["time_total"] - staged) <= 0.02 * staged + 0.01, times
    # the per-frame wall times are the passes' frames plus set-up and blur (frame 0)
    frames = times["time_first_pass"] + times["time_correction_pass"]
    assert float(fe.wall_time[1:].sum()) == pytest.approx(frames, abs=2e-3)  # attrs: ms


def test_error_vs_runtime_plots_each_result_at_its_recorded_time_and_error(runs):
    tagged, fe, harp = runs
    assert run_seconds(fe) == float(fe.attrs["time_total"])
    assert run_seconds(harp) == pytest.approx(float(harp.wall_time.sum()))
    fig = error_vs_runtime({"FE": fe, "HARP": harp}, tagged)
    try:
        ax = fig.axes[0]
        assert len(ax.containers) == 2
        for container, result in zip(ax.containers, (fe, harp), strict=True):
            x, y = (np.asarray(v) for v in container.lines[0].get_data())
            err = tracking_error(result, tagged)
            assert x[0] == pytest.approx(run_seconds(result))
            assert y[0] == pytest.approx(float(err.mean_all))
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert labels == ["FE", "HARP"]
    finally:
        plt.close(fig)


def test_error_vs_runtime_names_what_it_misses(runs):
    tagged, fe, _ = runs
    with pytest.raises(TypeError, match="truth"):
        error_vs_runtime({"FE": fe})
    bare = fe.drop_vars("wall_time")
    bare.attrs = {k: v for k, v in fe.attrs.items() if k != "time_total"}
    with pytest.raises(SchemaError, match="run time"):
        error_vs_runtime({"FE": bare}, tagged)
