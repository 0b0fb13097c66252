"""Tests of the tyre model (tyre.py): Pacejka '89 lateral force and vertical contact."""

import numpy as np
import pytest

from suspension_tuning.vehicle import tyre
from suspension_tuning.vehicle.params import load_vehicle_params, scale_pacejka

# Adams/Tire PAC89 example coefficients, physics-reference 8.2 "Set A" [S]
SET_A = np.array(
    [
        1.65,
        -34,
        1250,
        3036,
        12.8,
        0.00501,
        -0.02103,
        0.77394,
        0.002289,
        0.013442,
        0.003709,
        19.1656,
        1.21356,
        6.26206,
    ]
)


@pytest.mark.parametrize(
    ('fz_n', 'fy_2deg_n', 'fy_5deg_n', 'c_alpha_n_per_deg'),
    [
        # physics-reference 8.2 check values for Set A [D]: F_y(2 deg), F_y(5 deg), BCD
        (4000.0, 2924.0, 4268.0, 1729.0),
        (6000.0, 4045.0, 5987.0, 2334.0),
        (8000.0, 4877.0, 7395.0, 2729.0),
    ],
)
def test_pacejka_set_a_reproduces_reference_check_values(
    fz_n, fy_2deg_n, fy_5deg_n, c_alpha_n_per_deg
):
    fy = tyre.pacejka89_lateral(np.radians([2.0, 5.0]), fz_n, SET_A)
    # ISO sign: positive slip gives negative force; table values are magnitudes (1 N rounding)
    np.testing.assert_allclose(-fy, [fy_2deg_n, fy_5deg_n], atol=1.0)
    c_alpha = tyre.cornering_stiffness_n_per_rad(fz_n, SET_A) * np.pi / 180.0
    assert c_alpha == pytest.approx(c_alpha_n_per_deg, abs=1.0)


def test_lateral_force_has_iso_sign_and_is_odd_without_shifts():
    p = load_vehicle_params()
    alpha = np.radians([-8.0, -1.0, 1.0, 8.0])
    fy = tyre.pacejka89_lateral(alpha, 5000.0, p)
    # ISO 8855: positive slip angle -> negative (rightward) lateral force
    assert fy[2] < 0 < fy[1] and fy[3] < 0 < fy[0]
    # configured shifts are switched off (tyre.yaml shift_scale 0): odd function exactly
    np.testing.assert_allclose(fy[::-1], -fy, rtol=0, atol=1e-9)
    assert tyre.pacejka89_lateral(0.0, 5000.0, p) == 0.0


def test_configured_tyre_has_recommended_stiffness_and_friction():
    p = load_vehicle_params()
    # physics-reference 8.2 recommendation: C_alpha ~ 60 kN/rad at 4.5 kN (7.50R16 LT,
    # 50-80 kN/rad) from a3 x 0.5: 0.5 x 3036 x sin(2 atan(4.5/12.8)) [= 0.6258] x 180/pi
    # = 54.43 kN/rad
    assert tyre.cornering_stiffness_n_per_rad(4500.0, p) == pytest.approx(54.43e3, rel=1e-3)
    # peak friction ~ 0.9 at 5 kN: D = 0.84 (a1 Fz^2 + a2 Fz) = 0.84 x 5400 = 4536 N
    fy_peak = np.max(
        np.abs(tyre.pacejka89_lateral(np.radians(np.linspace(0, 30, 301)), 5000.0, p))
    )
    assert fy_peak / 5000.0 == pytest.approx(0.9, abs=0.02)


def test_no_lateral_force_without_vertical_load():
    p = load_vehicle_params()
    fy = tyre.pacejka89_lateral(np.radians([3.0, -3.0]), np.array([0.0, -10.0]), p)
    np.testing.assert_array_equal(fy, [0.0, 0.0])


def test_vertical_force_is_spring_damper_in_contact_and_never_pulls():
    k, c = 3.5e5, 300.0  # tyre.yaml values
    # in contact: k d + c d' = 3.5e5 x 0.01 + 300 x 0.2 = 3560 N
    assert tyre.vertical_force(0.01, 0.2, k, c) == pytest.approx(3560.0)
    # off the ground (d <= 0): zero whatever the rate
    np.testing.assert_array_equal(tyre.vertical_force([-0.01, 0.0], [5.0, -5.0], k, c), [0, 0])
    # unloading fast while still deflected: damper would pull, force clipped at 0
    assert tyre.vertical_force(0.001, -10.0, k, c) == 0.0


def test_scale_pacejka_scales_only_the_named_coefficients():
    a = scale_pacejka(SET_A, bcd_scale=0.5, d_scale=0.84, shift_scale=0.0)
    assert a[3] == pytest.approx(0.5 * 3036)
    assert a[1] == pytest.approx(0.84 * -34) and a[2] == pytest.approx(0.84 * 1250)
    np.testing.assert_array_equal(a[8:], 0.0)
    np.testing.assert_array_equal(a[[0, 4, 5, 6, 7]], SET_A[[0, 4, 5, 6, 7]])


def test_wrong_coefficient_count_raises():
    with pytest.raises(ValueError, match='14 coefficients'):
        tyre.pacejka89_lateral(0.01, 5000.0, np.ones(13))
