"""Tests of the BS 6841 W_b weighting (physics-reference section 5)."""

import numpy as np
import pytest

from suspension_tuning.vehicle.comfort import (
    WB,
    digital_gain,
    wb_analogue_gain,
    wb_sos,
    weighted_rms,
)

# physics-reference 5.2 check-value table: |W_b| at the standard's one-third-octave
# frequencies (three decimals, so the table itself is good to +/- 0.0005 -> < 0.02 dB
# at the smallest value 0.239)
F_TABLE_HZ = np.array([0.5, 1, 2, 4, 5, 6.3, 8, 10, 16, 20, 31.5, 63])
WB_TABLE = np.array(
    [0.334, 0.385, 0.417, 0.889, 1.025, 1.055, 1.025, 0.974, 0.810, 0.708, 0.492, 0.239]
)
TOL_DB = 0.5  # requirement from the issue


def _db(ratio):
    return 20.0 * np.log10(ratio)


def test_analogue_gain_matches_check_table_within_half_db():
    err = _db(wb_analogue_gain(F_TABLE_HZ) / WB_TABLE)
    assert np.max(np.abs(err)) < TOL_DB
    # the table has 3 decimals, so the analogue function should in fact agree to the
    # table's rounding: |gain - table| <= 0.0005 (+1e-6 float slack)
    np.testing.assert_allclose(wb_analogue_gain(F_TABLE_HZ), WB_TABLE, atol=0.0005 + 1e-6)


def test_wk_code_path_reproduces_iso_2631_table_values():
    # ISO 2631-1 Table 3 W_k values quoted in physics-reference 5.2:
    # 0.482 at 1 Hz, 0.967 at 4 Hz, 1.036 at 8 Hz, 0.768 at 16 Hz (table to +/- 0.001)
    g = wb_analogue_gain([1.0, 4.0, 8.0, 16.0], weighting='Wk')
    np.testing.assert_allclose(g, [0.482, 0.967, 1.036, 0.768], atol=0.001)


def test_wb_asymptotes_and_peak():
    # step term: K = 0.4 at low frequency, 0.4*(4/2.5)^2 = 1.024 at high frequency
    # (the HVLab "x 1.024" note, physics-reference 5.1)
    assert WB.gain_k * (WB.f6_hz / WB.f5_hz) ** 2 == pytest.approx(1.024)
    f = np.linspace(3.0, 10.0, 7001)
    g = wb_analogue_gain(f)
    # physics-reference 5.1: W_b peaks at 1.055 near 6.1 Hz
    assert g.max() == pytest.approx(1.055, abs=0.001)
    assert f[np.argmax(g)] == pytest.approx(6.1, abs=0.1)


def test_digital_gain_at_1khz_within_half_db_at_all_table_frequencies():
    # 1 kHz is the simulation output rate; the bilinear transform's warping error grows
    # with f/fs, so the highest tabulated frequency (63 Hz) is the worst case: measured
    # -0.14 dB, without pre-warping
    err = _db(digital_gain(F_TABLE_HZ, 1000.0) / WB_TABLE)
    assert np.max(np.abs(err)) < TOL_DB


def test_digital_gain_at_500hz_within_half_db_up_to_31_5hz():
    # at 500 Hz the warping error at 63 Hz is -0.60 dB (> 0.5 dB), so 500 Hz is only
    # accurate to 0.5 dB up to 31.5 Hz (measured -0.10 dB there); BS 6841 ride content
    # of a vehicle body is far below 31.5 Hz
    sel = F_TABLE_HZ <= 31.5
    err = _db(digital_gain(F_TABLE_HZ[sel], 500.0) / WB_TABLE[sel])
    assert np.max(np.abs(err)) < TOL_DB
    err63 = _db(digital_gain([63.0], 500.0) / wb_analogue_gain([63.0]))
    assert err63[0] < -TOL_DB  # documents why 500 Hz is not enough at 63 Hz


def test_prewarping_makes_gain_exact_at_chosen_frequency():
    g = digital_gain([63.0], 500.0, prewarp_hz=63.0)
    # pre-warping maps 63 Hz exactly: error only float round-off (< 1e-6 dB)
    assert abs(_db(g / wb_analogue_gain([63.0]))[0]) < 1e-6


def test_sos_shape_and_stability():
    sos = wb_sos(1000.0)
    assert sos.shape[1] == 6
    # 8 analogue poles -> 4 second-order sections; all digital poles inside unit circle
    assert sos.shape[0] == 4
    poles = np.concatenate([np.roots(s[3:]) for s in sos])
    assert np.all(np.abs(poles) < 1.0)


def test_weighted_rms_of_sine_equals_gain_times_amplitude_over_root_two():
    fs = 1000.0
    t = np.arange(0, 13.0, 1 / fs)
    f = np.array([[1.0], [4.0], [8.0]])  # batch of three sines
    acc = 2.0 * np.sin(2 * np.pi * f * t)
    out = weighted_rms(acc, fs, t_settle_s=3.0)
    # steady state: RMS = 2/sqrt(2) * |W_b(f)| ; table values 0.385, 0.889, 1.025 give
    # 0.5445, 1.2572, 1.4496 m/s^2 ; 0.5 % covers the settling remnant and table rounding
    expected = 2.0 / np.sqrt(2.0) * np.array([0.385, 0.889, 1.025])
    assert out.shape == (3,)
    np.testing.assert_allclose(out, expected, rtol=0.005)


def test_weighted_rms_scalar_for_1d_input():
    fs = 1000.0
    t = np.arange(0, 5.0, 1 / fs)
    out = weighted_rms(np.sin(2 * np.pi * 5.0 * t), fs)
    assert isinstance(out, float)


def test_weighted_rms_rejects_bad_input():
    with pytest.raises(ValueError, match='t_settle_s'):
        weighted_rms(np.zeros(100), 1000.0, t_settle_s=3.0)
    with pytest.raises(ValueError, match='NaN'):
        weighted_rms(np.full(5000, np.nan), 1000.0)
    with pytest.raises(ValueError, match='fs_hz'):
        wb_sos(150.0)
    with pytest.raises(ValueError, match='unknown weighting'):
        wb_analogue_gain(1.0, weighting='Wz')
