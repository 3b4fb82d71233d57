"""The LMS200 model: beam layouts, quantisation, overflow codes, noise statistics."""

from __future__ import annotations

import numpy as np
import pytest

from datmo_cli.sim.sensor import Sensor

pytestmark = pytest.mark.unit


@pytest.mark.parametrize(
    "fov,res,n,first",
    [(180, 1.0, 181, -90), (180, 0.5, 361, -90), (100, 1.0, 101, -50), (100, 0.5, 201, -50), (100, 0.25, 401, -50)],
)
def test_beam_layouts(fov, res, n, first):
    s = Sensor(fov, res, rate_hz=5.0)
    a = s.angles()
    assert s.n_beams == n == len(a)
    assert np.degrees(a[0]) == pytest.approx(first) and np.degrees(a[-1]) == pytest.approx(-first)
    g = s.geometry()
    assert g.n_beams == n and g.frame_id == "laser"
    np.testing.assert_allclose(g.angles(), a, atol=1e-12)
    assert g.range_max == 8.0 and g.scan_time == pytest.approx(0.2)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(fov_deg=180, resolution_deg=0.25),
        dict(fov_deg=90),
        dict(range_mode_m=80, units="mm"),
        dict(rate_hz=40.0),
        dict(resolution_deg=1.0, rate_hz=76.0),
        dict(noise_sigma=-1.0),
        dict(units="m"),
    ],
)
def test_impossible_settings_are_refused(kwargs):
    with pytest.raises(ValueError):
        Sensor(**kwargs)


def test_75_hz_at_one_degree_is_allowed():
    assert Sensor(resolution_deg=1.0, rate_hz=75.0).rate_hz == 75.0


def test_mm_quantisation_without_noise():
    s = Sensor(noise_sigma=0.0)
    d = np.array([0.0004, 1.23449, 1.2346, 7.5, 8.1824, 8.183, 9.0, np.inf])
    codes = s.measure(d, np.random.default_rng(0))
    assert list(codes[:5]) == [0, 1234, 1235, 7500, 8182]
    assert list(codes[5:]) == [0x1FF7] * 3  # greater than maximum
    r = s.ranges(codes)
    assert r.dtype == np.float32
    np.testing.assert_allclose(r[:5], [0.0, 1.234, 1.235, 7.5, 8.182], atol=1e-6)
    assert np.isposinf(r[5:]).all()


@pytest.mark.parametrize("mode,bits", [(16, 14), (32, 15)])
def test_longer_mm_modes_use_more_bits(mode, bits):
    s = Sensor(range_mode_m=mode, noise_sigma=0.0)
    top = (1 << bits) - 9
    codes = s.measure(np.array([mode - 0.5, (top + 1) / 1000.0]), np.random.default_rng(0))
    assert codes[0] == round((mode - 0.5) * 1000) and codes[1] == top


def test_cm_units_and_the_80_m_mode():
    s = Sensor(range_mode_m=80, units="cm", noise_sigma=0.0)
    codes = s.measure(np.array([1.234, 50.004, 79.0, 85.0]), np.random.default_rng(0))
    assert list(codes) == [123, 5000, 7900, 0x1FF7]
    np.testing.assert_allclose(s.ranges(codes)[:3], [1.23, 50.0, 79.0], atol=1e-5)
    s8 = Sensor(range_mode_m=8, units="cm", noise_sigma=0.0)  # cm in the 8 m mode: 8 m is still the limit
    assert list(s8.measure(np.array([7.9, 8.3]), np.random.default_rng(0))) == [790, 0x1FF7]


def test_codes_other_than_greater_than_maximum_are_nan():
    s = Sensor()
    r = s.ranges(np.array([0x1FF7, 0x1FFA, 0x1FFB, 0x1FFD, 0x1FFE, 0x1FFF, 100], np.uint16))
    assert np.isposinf(r[0]) and np.isnan(r[1:6]).all() and r[6] == pytest.approx(0.1)


def test_dropout_gives_no_return_codes():
    s = Sensor(dropout=0.3)
    codes = s.measure(np.full(20000, 3.0), np.random.default_rng(1))
    frac = np.mean(codes == 0x1FFF)
    assert frac == pytest.approx(0.3, abs=0.02)
    assert np.isnan(s.ranges(codes)[codes == 0x1FFF]).all()


@pytest.mark.parametrize("sigma", [0.01, 0.03])
def test_noise_statistics(sigma):
    s = Sensor(noise_sigma=sigma)
    true = np.full(200_000, 4.2)
    r = s.ranges(s.measure(true, np.random.default_rng(7))).astype(np.float64)
    err = r - true
    # sigma of the sum of Gaussian noise and uniform 1 mm rounding error
    assert err.mean() == pytest.approx(0.0, abs=3 * sigma / np.sqrt(len(err)) + 1e-4)
    assert err.std() == pytest.approx(np.sqrt(sigma**2 + 0.001**2 / 12), rel=0.01)
    assert np.allclose(np.round(r * 1000), r * 1000, atol=1e-3)  # whole millimetres


def test_measure_is_deterministic_for_a_generator_state():
    s = Sensor()
    d = np.linspace(0.5, 7.5, 361)
    a = s.measure(d, np.random.default_rng(3))
    b = s.measure(d, np.random.default_rng(3))
    assert np.array_equal(a, b) and not np.array_equal(a, s.measure(d, np.random.default_rng(4)))
