"""Tests of the paper's objective and constraint functions, eqs. 9-11."""

import numpy as np
import pytest

from suspension_tuning.vehicle.metrics import (
    f_hand,
    f_ride,
    first_peak,
    objective_scaling,
    rms,
    roll_rate_rms,
    tyre_hop_constraints,
)


def test_f_ride_is_zero_and_one_at_the_paper_corner_values():
    # eq. 9: both accelerations at 0.7 m/s^2 -> 0, both at 4.4 m/s^2 -> 1
    assert f_ride(0.7, 0.7) == pytest.approx(0.0, abs=1e-15)
    assert f_ride(4.4, 4.4) == pytest.approx(1.0, abs=1e-15)


def test_f_ride_hand_value():
    # eq. 9: ((1.44 - 0.7)/3.7 + (2.55 - 0.7)/3.7)/2 = (0.2 + 0.5)/2 = 0.35
    assert f_ride(1.44, 2.55) == pytest.approx(0.35, abs=1e-12)


def test_f_ride_broadcasts_over_batch():
    out = f_ride(np.array([0.7, 4.4]), np.array([0.7, 4.4]))
    np.testing.assert_allclose(out, [0.0, 1.0], atol=1e-15)


def test_f_hand_includes_the_0_9_and_0_1_terms():
    # eq. 10: each term is 0.1 at the minimum, so f = (0.1 + 0.1)/2 = 0.1
    assert f_hand(0.8, 1.4) == pytest.approx(0.1, abs=1e-15)
    # each term is 0.9 + 0.1 = 1.0 at the maximum, so f = 1
    assert f_hand(5.7, 12.2) == pytest.approx(1.0, abs=1e-15)


def test_f_hand_hand_value():
    # eq. 10: r = 3.25 deg/s -> (2.45*0.9/4.9) + 0.1 = 0.55 ;
    # p = 6.8 deg -> (5.4*0.9/10.8) + 0.1 = 0.55 ; f = (0.55 + 0.55)/2 = 0.55
    assert f_hand(3.25, 6.8) == pytest.approx(0.55, abs=1e-12)
    # r = 0.8 (term 0.1), p = 12.2 (term 1.0): f = 0.55 as well
    assert f_hand(0.8, 12.2) == pytest.approx(0.55, abs=1e-12)


def test_the_normalisation_of_eqs_9_and_10_comes_from_config(monkeypatch):
    # the shipped config/scenarios.yaml holds the paper's reference values
    assert objective_scaling('ride') == {'a_min_mps2': 0.7, 'a_max_mps2': 4.4}
    assert objective_scaling('handling') == {
        'roll_rate_min_deg_s': 0.8, 'roll_rate_max_deg_s': 5.7, 'roll_peak_min_deg': 1.4,
        'roll_peak_max_deg': 12.2}
    from suspension_tuning.vehicle import params

    # another vehicle's range: 0.2-1.2 m/s^2 and 1-4 deg/s, 1-5 deg
    monkeypatch.setattr(params, 'load_scenarios_config', lambda: {
        'ride': {'objective_scaling': {'a_min_mps2': 0.2, 'a_max_mps2': 1.2}},
        'handling': {'objective_scaling': {
            'roll_rate_min_deg_s': 1.0, 'roll_rate_max_deg_s': 4.0, 'roll_peak_min_deg': 1.0,
            'roll_peak_max_deg': 5.0}}})
    assert f_ride(0.7, 1.2) == pytest.approx(0.75, abs=1e-12)  # (0.5 + 1.0) / 2
    assert f_hand(2.5, 3.0) == pytest.approx(0.55, abs=1e-12)  # (0.55 + 0.55) / 2
    assert f_ride(0.7, 1.2, 0.7, 4.4) == pytest.approx(0.0676, abs=1e-4)  # explicit wins
    monkeypatch.setattr(params, 'load_scenarios_config', lambda: {'ride': {}})
    with pytest.raises(ValueError, match='ride.objective_scaling.a_min_mps2: expected a '
                                         'number, got None'):
        f_ride(1.0, 1.0)


def test_rms_of_sine_is_amplitude_over_root_two():
    t = np.arange(0, 10, 1e-3)  # 10 s, whole number of periods of 2 Hz
    x = 3.0 * np.sin(2 * np.pi * 2.0 * t)
    # RMS of A sin over whole periods = A/sqrt(2) = 2.1213...
    assert rms(x) == pytest.approx(3.0 / np.sqrt(2.0), rel=1e-9)


def test_roll_rate_rms_window_and_batch():
    t = np.arange(0, 4, 1e-3)
    # batch of two: a square wave of amplitude 2 deg/s (RMS 2) and a constant 1 deg/s
    sq = 2.0 * np.sign(np.sin(2 * np.pi * t + 0.1))
    p = np.stack([sq, np.ones_like(t)])
    np.testing.assert_allclose(roll_rate_rms(p), [2.0, 1.0], rtol=1e-12)
    # window 1-2 s: the constant signal still gives 1, the zeroed part is excluded
    q = np.where((t >= 1.0) & (t <= 2.0), 1.0, 0.0)
    assert roll_rate_rms(q, t, (1.0, 2.0)) == pytest.approx(1.0, rel=1e-12)


def test_first_peak_picks_first_swing_not_largest():
    t = np.arange(0, 6, 1e-3)
    # roll: +3 deg peak at t = 1 s (Gaussian), then -5 deg at t = 2.5 s
    roll = 3.0 * np.exp(-(((t - 1.0) / 0.3) ** 2)) - 5.0 * np.exp(-(((t - 2.5) / 0.3) ** 2))
    # window covering both swings: first significant peak (3 >= 0.5*5) is 3 deg
    assert first_peak(roll, t, (0.0, 4.0)) == pytest.approx(3.0, abs=1e-3)


def test_first_peak_ignores_small_ripple():
    t = np.arange(0, 6, 1e-3)
    ripple = 0.1 * np.sin(2 * np.pi * 8 * t)  # 0.1 deg at 8 Hz, < 0.5 * 4 deg
    roll = 4.0 * np.exp(-(((t - 2.0) / 0.4) ** 2)) + ripple
    # the ripple's maxima before the swing are ignored; peak ~ 4 deg (+/- 0.1 ripple)
    assert first_peak(roll, t, (0.0, 5.0)) == pytest.approx(4.0, abs=0.11)


def test_first_peak_still_rising_returns_window_max():
    t = np.linspace(0, 1, 101)
    roll = 2.0 * t  # rises to 1.6 deg at t = 0.8 s
    assert first_peak(roll, t, (0.0, 0.8)) == pytest.approx(1.6, abs=1e-12)


def test_first_peak_batch():
    t = np.arange(0, 4, 1e-2)
    r = np.stack([np.sin(np.pi * t / 2), -2 * np.sin(np.pi * t / 2)])  # peaks at t = 1 s
    np.testing.assert_allclose(first_peak(r, t, (0.0, 2.5)), [1.0, 2.0], atol=1e-9)


def test_tyre_hop_quarter_time_off_gives_1_5():
    n = 1000
    fz = np.full((4, n), 5000.0)
    fz[0, :250] = 0.0  # 25 % of the time off the ground
    g = tyre_hop_constraints(fz, dt_s=1e-3)
    # eq. 11: 10*(0.25 - 0.1) = 1.5 ; tyres always on ground: 10*(0 - 0.1) = -1
    np.testing.assert_allclose(g, [1.5, -1.0, -1.0, -1.0], atol=1e-12)


def test_tyre_hop_batch_shape_and_threshold():
    fz = np.full((3, 4, 200), 4000.0)
    fz[1, 2, :20] = 0.0  # 10 % off -> g = 0 (on the constraint boundary)
    fz[2, 3, :100] = 1e-4  # below the 1e-3 N threshold: counts as off, 50 % -> g = 4
    g = tyre_hop_constraints(fz, 1e-3)
    assert g.shape == (3, 4)
    assert g[1, 2] == pytest.approx(0.0, abs=1e-12)
    assert g[2, 3] == pytest.approx(4.0, abs=1e-12)
    assert g[0, 0] == pytest.approx(-1.0, abs=1e-12)


def test_tyre_hop_non_uniform_time_weights():
    fz = np.array([[0.0, 100.0, 100.0]])
    dt = np.array([0.5, 0.25, 0.25])  # the zero-force sample lasts half the record
    # eq. 11: 10*(0.5 - 0.1) = 4
    assert tyre_hop_constraints(fz, dt)[0] == pytest.approx(4.0)


def test_tyre_hop_rejects_bad_input():
    with pytest.raises(ValueError, match='n_tyres'):
        tyre_hop_constraints(np.zeros(10), 1e-3)
    with pytest.raises(ValueError, match='NaN'):
        tyre_hop_constraints(np.full((4, 10), np.nan), 1e-3)
    with pytest.raises(ValueError, match='dt_s'):
        tyre_hop_constraints(np.zeros((4, 10)), 0.0)
