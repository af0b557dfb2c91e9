"""The progress rule: explicit on/off, auto = terminal or notebook, delayed bars."""

from __future__ import annotations

import io
import sys
import types

import pytest

from harpx import _progress
from harpx._progress import DELAY, progress_bar, show_progress


class _Stream(io.StringIO):
    def __init__(self, tty: bool) -> None:
        super().__init__()
        self._tty = tty

    def isatty(self) -> bool:
        return self._tty


@pytest.mark.parametrize(
    ("tty", "expected"),
    [pytest.param(True, True, id="terminal"), pytest.param(False, False, id="pipe")],
)
def test_auto_follows_stderr(monkeypatch, tty, expected):
    monkeypatch.setattr(sys, "stderr", _Stream(tty))
    monkeypatch.setattr(_progress, "in_notebook", lambda: False)
    assert show_progress(None) is expected
    # explicit values win over the detection
    assert show_progress(True) is True and show_progress(False) is False


def test_auto_is_on_in_a_jupyter_kernel(monkeypatch):
    shell = types.SimpleNamespace(config={"IPKernelApp": {}})
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))
    monkeypatch.setattr(sys, "stderr", _Stream(False))  # a kernel's stderr is no terminal
    assert _progress.in_notebook() and show_progress(None)


def test_terminal_ipython_is_not_a_notebook(monkeypatch):
    shell = types.SimpleNamespace(config={"TerminalIPythonApp": {}})
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))
    assert not _progress.in_notebook()


def test_auto_bar_waits_before_it_appears(monkeypatch):
    stream = _Stream(True)
    monkeypatch.setattr(sys, "stderr", stream)
    monkeypatch.setattr(_progress, "in_notebook", lambda: False)
    with progress_bar(range(3), progress=None, file=stream) as bar:
        assert not bar.disable and bar.delay == DELAY
        list(bar)
    assert stream.getvalue() == ""  # a call faster than DELAY prints nothing
    with progress_bar(range(3), progress=True, file=stream) as bar:
        list(bar)
    assert "3/3" in stream.getvalue()  # forced on: shown at once


def test_solve_shows_the_load_factor_reached_with_iterations_and_cutbacks(monkeypatch):
    import numpy as np

    from harpx.mechanics import Body, Fixed, NeoHookean, Prescribed, box, solve

    body = Body(box((1.0, 1.0, 1.0), (1, 1, 1)), NeoHookean(c1=1.0, kappa=120.0))
    pull = Prescribed("right", lambda X, s: 0.1 * s * np.ones_like(X), components=(0,))
    loads = [Fixed("left", (0,)), Fixed("front", (1,)), Fixed("bottom", (2,)), pull]
    stream = _Stream(False)
    monkeypatch.setattr(sys, "stderr", stream)
    result = solve(body, loads, steps=4, progress=True)
    text = stream.getvalue()
    assert result.converged
    assert "load" in text and "100%" in text and "cutbacks=0" in text, text
    quiet = _Stream(False)
    monkeypatch.setattr(sys, "stderr", quiet)
    solve(body, loads, steps=4, progress=False)
    assert quiet.getvalue() == ""


# --- on by default where someone waits, off where nobody watches; no TqdmWarning -----------


def _fake_kernel(monkeypatch):
    """A Jupyter kernel as far as harpx and tqdm can tell, without ipywidgets."""
    shell = types.SimpleNamespace(config={"IPKernelApp": {}})
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))
    monkeypatch.setitem(sys.modules, "ipywidgets", None)  # import fails, find_spec is None


def _tracked_with_defaults():
    """Track a small cylinder with the default settings (a blur-correction pass included)."""
    from harpx.tracking.track import track
    from tests.test_batch import _subject, body_factory

    phase = _subject(3.0)
    phase.attrs["bandpass"] = "disk"  # as extract_phase marks it: the correction pass runs
    result = track(phase, body_factory(None))
    assert result.attrs["blur_passes_applied"] == 1
    return result


def test_tracking_progress_is_auto_by_default():
    from harpx.tracking.settings import TrackingSettings

    assert TrackingSettings().progress is None  # auto, not off
    assert TrackingSettings(progress=1).progress is True
    assert TrackingSettings().as_attrs()["setting_progress"] == "auto"


def test_tracking_shows_both_passes_by_name_in_a_notebook(monkeypatch):
    _fake_kernel(monkeypatch)
    stream = _Stream(False)  # a kernel's stderr is no terminal
    monkeypatch.setattr(sys, "stderr", stream)
    monkeypatch.setattr(_progress, "DELAY", 0.0)  # the frames here are faster than DELAY
    _tracked_with_defaults()
    text = stream.getvalue()
    assert "tracking: 100%" in text and "2/2" in text, text
    assert "tracking (blur correction): 100%" in text, text


def test_tracking_shows_nothing_when_nobody_watches(monkeypatch):
    monkeypatch.setattr(_progress, "in_notebook", lambda: False)
    stream = _Stream(False)  # a pipe, a log file, the tests
    monkeypatch.setattr(sys, "stderr", stream)
    monkeypatch.setattr(_progress, "DELAY", 0.0)
    _tracked_with_defaults()
    assert stream.getvalue() == ""


def test_notebook_without_ipywidgets_gets_a_text_bar_and_no_warning(monkeypatch):
    import warnings

    from tqdm.std import tqdm as text_bar

    _fake_kernel(monkeypatch)
    stream = _Stream(False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a TqdmWarning ("IProgress not found") would raise
        with progress_bar(range(3), progress=True, file=stream, desc="frames") as bar:
            assert type(bar) is text_bar
            list(bar)
    assert "frames: 100%" in stream.getvalue()


_IMPORT_IN_A_KERNEL = """
import sys, types, warnings
import IPython, ipykernel.zmqshell  # what tqdm.auto looks for
IPython.get_ipython = lambda: types.SimpleNamespace(config={"IPKernelApp": {}})
sys.modules["ipywidgets"] = None  # not installed
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    import harpx, harpx.batch, harpx.datasets, harpx.mechanics.newton, harpx.tracking.track
    from harpx._progress import in_notebook, progress_bar
    assert in_notebook()
    with progress_bar(range(2), progress=None) as bar:
        list(bar)
print("harpx:", [str(w.message)[:30] for w in caught if "IProgress" in str(w.message)])
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    import tqdm.auto  # the control: this is what printed "TqdmWarning: IProgress not found"
print("tqdm.auto:", [w.category.__name__ for w in caught])
"""


def test_importing_harpx_in_a_kernel_without_ipywidgets_does_not_warn():
    import subprocess
    from pathlib import Path

    run = subprocess.run(
        [sys.executable, "-c", _IMPORT_IN_A_KERNEL],
        capture_output=True,
        text=True,
        cwd=Path(__file__).parents[1],
        timeout=120,
    )
    assert run.returncode == 0, run.stderr
    # harpx: nothing; the same set-up makes tqdm.auto warn, so it is a notebook's
    assert run.stdout.splitlines() == ["harpx: []", "tqdm.auto: ['TqdmWarning']"], run.stdout


def test_elapsed_shows_the_running_time_of_a_step_without_a_count(monkeypatch):
    import time

    stream = _Stream(True)
    monkeypatch.setattr(sys, "stderr", stream)
    monkeypatch.setattr(_progress, "in_notebook", lambda: False)
    monkeypatch.setattr(_progress, "TICK", 0.01)
    with _progress.elapsed("building", progress=None):
        pass
    assert stream.getvalue() == ""  # quicker than DELAY: nothing
    monkeypatch.setattr(_progress, "DELAY", 0.0)
    with _progress.elapsed("building", progress=None):
        deadline = time.monotonic() + 10.0
        while stream.getvalue().count("building: 00:0") < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert stream.getvalue().count("building: 00:0") >= 2  # redrawn while the step runs
    assert stream.getvalue().endswith("\r")  # and cleared when it ends
    quiet = _Stream(False)
    monkeypatch.setattr(sys, "stderr", quiet)
    with _progress.elapsed("building", progress=None):
        time.sleep(0.05)
    assert quiet.getvalue() == ""


def test_auto_is_off_in_a_dask_worker(monkeypatch):
    # a cohort's subjects track in workers whose stderr may be the user's terminal: one bar
    # per subject would interleave with the cohort's "subjects" bar
    monkeypatch.setattr(sys, "stderr", _Stream(True))
    monkeypatch.setattr(_progress, "in_notebook", lambda: False)
    assert show_progress(None)
    worker = types.SimpleNamespace(get_worker=lambda: object())
    monkeypatch.setitem(sys.modules, "distributed", worker)
    assert not show_progress(None) and show_progress(True)

    def no_worker():
        raise ValueError("No worker found")

    monkeypatch.setitem(sys.modules, "distributed", types.SimpleNamespace(get_worker=no_worker))
    assert show_progress(None)
