"""Tests of harpx.imaging.fft: identities against numpy and between directions."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from harpx.imaging import fft as hfft

SHAPES = [
    pytest.param((16, 12), id="2d-even"),
    pytest.param((3, 15, 9), id="batch-odd"),
    pytest.param((2, 2, 8, 10), id="two-leading"),
]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("complex_input", [False, True], ids=["real", "complex"])
def test_roundtrip_and_numpy_equality(shape, complex_input, rng):
    a = rng.standard_normal(shape)
    if complex_input:
        a = a + 1j * rng.standard_normal(shape)
    spec = hfft.fft2(a)
    # floating-point identity: an FFT of n <= 240 points loses ~log2(n) eps; 1e-10 absolute
    # on O(sqrt(n)) spectra is far above that and far below any indexing/sign error
    np.testing.assert_allclose(spec, np.fft.fft2(a), rtol=0, atol=1e-10)
    # inverse of forward: rtol 1e-12 (values O(1), rounding ~1e-15)
    np.testing.assert_allclose(hfft.ifft2(spec), a, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(hfft.ifft2(a), np.fft.ifft2(a), rtol=0, atol=1e-10)


@pytest.mark.parametrize("shape", SHAPES)
def test_real_transforms_match_numpy(shape, rng):
    a = rng.standard_normal(shape)
    half = hfft.rfft2(a)
    np.testing.assert_allclose(half, np.fft.rfft2(a), rtol=0, atol=1e-10)  # as above
    back = hfft.irfft2(half, shape[-2:])
    np.testing.assert_allclose(back, a, rtol=1e-12, atol=1e-13)  # round trip identity


def test_parseval(rng):
    a = rng.standard_normal((4, 20, 24)) + 1j * rng.standard_normal((4, 20, 24))
    spec = hfft.fft2(a)
    energy = np.sum(np.abs(a) ** 2, axis=(-2, -1))
    # Parseval: sum |a|^2 = sum |A|^2 / n; identity up to rounding (rtol 1e-12)
    np.testing.assert_allclose(np.sum(np.abs(spec) ** 2, axis=(-2, -1)) / 480, energy, rtol=1e-12)


def test_results_are_independent_arrays(rng):
    a = rng.standard_normal((6, 8))
    first = hfft.fft2(a)
    kept = first.copy()
    hfft.fft2(rng.standard_normal((6, 8)))  # reuses the cached plan and its buffers
    np.testing.assert_array_equal(first, kept)


def test_plan_cache_reuses_plans_per_thread():
    plan = hfft.get_plan((4, 8, 8), np.complex128, (-2, -1), direction="forward", threads=1)
    again = hfft.get_plan((4, 8, 8), np.complex128, (1, 2), direction="forward", threads=1)
    assert plan is again  # negative and positive axes name the same plan
    other = {}
    worker = threading.Thread(
        target=lambda: other.setdefault(
            "plan",
            hfft.get_plan((4, 8, 8), np.complex128, (-2, -1), direction="forward", threads=1),
        )
    )
    worker.start()
    worker.join()
    assert other["plan"] is not plan  # threads never share a plan's buffers


def test_threads_default_and_validation():
    assert hfft.default_threads() >= 1
    assert hfft.default_threads(3) == 3
    with pytest.raises(ValueError, match="'threads'"):
        hfft.default_threads(0)
    with pytest.raises(ValueError, match="'threads'"):
        hfft.fft2(np.ones((4, 4)), threads=-1)


def test_bad_shapes():
    with pytest.raises(ValueError, match="at least 2 dimensions"):
        hfft.fft2(np.ones(4))
    with pytest.raises(ValueError, match="real input"):
        hfft.rfft2(np.ones((4, 4), dtype=complex))
    with pytest.raises(ValueError, match="does not match"):
        hfft.irfft2(np.ones((4, 4), dtype=complex), (4, 8))


@pytest.mark.parametrize("dtype", [np.complex64, np.complex128])
def test_inplace_plans_transform_their_buffer_like_numpy(dtype, rng):
    shape = (3, 10, 12)
    a = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(dtype)
    buffer, forward, backward = hfft.inplace_plans(shape, dtype, (-2, -1), threads=1)
    assert buffer.dtype == dtype and buffer.shape == shape
    buffer[...] = a
    forward.execute()
    # single precision: a 120-point transform of O(1) values rounds to ~1e-6 of its O(10)
    # output; double to ~1e-14
    atol = 1e-4 if dtype == np.complex64 else 1e-11
    np.testing.assert_allclose(buffer, np.fft.fft2(a), rtol=0, atol=atol)
    backward.execute()  # unnormalised: n times the input
    np.testing.assert_allclose(buffer / 120, a, rtol=0, atol=atol / 10)
    # a second shape of the same size shares the memory
    other, forward2, _ = hfft.inplace_plans((3, 12, 10), dtype, (-1,), memory=buffer)
    assert np.shares_memory(other, buffer)
    other[...] = a.reshape(3, 12, 10)
    forward2.execute()
    np.testing.assert_allclose(other, np.fft.fft(a.reshape(3, 12, 10)), rtol=0, atol=atol)


def test_inplace_plans_refuse_real_dtypes_and_memory_that_does_not_fit():
    with pytest.raises(ValueError, match="complex dtype"):
        hfft.inplace_plans((4, 4), np.float32, (-2, -1))
    with pytest.raises(ValueError, match="'memory'"):
        hfft.inplace_plans((4, 4), np.complex64, (-2, -1), memory=np.zeros(15, np.complex64))


def test_uncached_plan_is_new_every_time_and_the_cached_one_is_kept(rng):
    a = rng.standard_normal((6, 8))
    kw = {"direction": "forward", "threads": 1, "cached": False}
    first = hfft.get_plan(a.shape, np.float64, (-2, -1), **kw)
    second = hfft.get_plan(a.shape, np.float64, (-2, -1), **kw)
    assert first is not second and not np.shares_memory(first.input_array, second.input_array)
    cached = hfft.get_plan(a.shape, np.float64, (-2, -1), direction="forward", threads=1)
    assert hfft.get_plan(a.shape, np.float64, (-2, -1), direction="forward", threads=1) is cached
    first.input_array[...] = a
    first.execute()
    np.testing.assert_allclose(first.output_array, np.fft.rfft2(a), rtol=0, atol=1e-12)


def test_inplace_plans_are_measured_only_when_they_run_often(monkeypatch):
    monkeypatch.setattr(hfft, "MEASURE_MIN_SIZE", 16)  # a small stack stands in for a large one
    rarely = hfft.MEASURE_PAYS_AFTER - 1
    _, forward, _ = hfft.inplace_plans((2, 8, 8), np.complex64, (-2, -1), threads=1,
                                       executions=rarely)  # fmt: skip
    assert "FFTW_ESTIMATE" in forward.flags and "FFTW_MEASURE" not in forward.flags
    for often in (None, hfft.MEASURE_PAYS_AFTER):
        _, forward, _ = hfft.inplace_plans((2, 8, 8), np.complex64, (-2, -1), threads=1,
                                           executions=often)  # fmt: skip
        assert "FFTW_MEASURE" in forward.flags
