"""Tests of the 4S4 strut model (strut.py) against hand calculations."""

import numpy as np
import pytest

from suspension_tuning.vehicle import strut
from suspension_tuning.vehicle.params import load_vehicle_params

P = load_vehicle_params()
SP = P.strut
A = np.pi / 4 * 0.05**2  # piston area for the 50 mm piston of strut_4s4.yaml [m^2]
P_ATM = 101325.0
LOAD = 5000.0  # [N] a round static load close to the front strut's 5.01 kN


def test_gas_force_equals_static_load_at_zero_stroke():
    for v_l in (0.1, 0.3, 0.6):
        f = strut.gas_force_n(0.0, v_l * 1e-3, LOAD, P)
        assert f == pytest.approx(LOAD, rel=1e-12)  # static gas volume at static load


def test_gas_force_follows_polytropic_law_hand_calculation():
    # p_s = 5000 / A + p_atm = 2.6478 MPa; x = 0.03 m, V = 0.3 L, n = 1.4:
    # p = p_s (V / (V - A x))^1.4, F = (p - p_atm) A
    p_s = LOAD / A + P_ATM
    v = 0.3e-3
    expected = (p_s * (v / (v - A * 0.03)) ** 1.4 - P_ATM) * A
    assert strut.gas_force_n(0.03, v, LOAD, P) == pytest.approx(expected, rel=1e-12)
    # hand value: V - A x = 0.2411 L, ratio 1.2443^1.4 = 1.3582, p = 3.596 MPa -> 6861 N
    assert expected == pytest.approx(6861.3, rel=1e-4)


def test_gas_stiffness_matches_formula_and_is_inverse_in_volume():
    # k = n p_s A^2 / V: 1.4 x 2.6478e6 x 3.855e-6 / 0.3e-3 = 47.63 kN/m
    k = strut.gas_stiffness_n_per_m(0.3e-3, LOAD, P)
    assert k == pytest.approx(47.63e3, rel=1e-3)
    # central difference of the force agrees with the tangent formula
    h = 1e-6
    fd = (strut.gas_force_n(h, 0.3e-3, LOAD, P) - strut.gas_force_n(-h, 0.3e-3, LOAD, P)) / (2 * h)
    assert fd == pytest.approx(k, rel=1e-6)
    # paper Fig. 5 / physics-ref 3.2: stiffness inversely proportional to gas volume
    assert strut.gas_stiffness_n_per_m(0.1e-3, LOAD, P) == pytest.approx(
        6 * strut.gas_stiffness_n_per_m(0.6e-3, LOAD, P)
    )


def test_gas_guard_keeps_force_finite_and_continuous_beyond_collapse():
    v = 0.1e-3
    x_collapse = v / A  # 0.0509 m: the gas volume would reach zero
    x = np.linspace(0.0, 1.2 * x_collapse, 2001)
    f = strut.gas_force_n(x, v, LOAD, P)
    assert np.all(np.isfinite(f)) and np.all(np.diff(f) > 0)
    # C1: no jump in slope at the guard volume (5 % of V): second differences stay small
    assert np.max(np.abs(np.diff(f, 2))) < 0.05 * np.max(np.abs(np.diff(f)))


def test_damper_is_scaled_standard_characteristic_with_strut_sign():
    # table (rebound +): v = 0.1 -> 400 N, v = -0.1 -> -150 N.  Strut stroke rate is
    # compression positive, force positive pushing apart, so compression 0.1 m/s -> +150 N
    # and extension 0.1 m/s (stroke rate -0.1) -> -400 N
    f = strut.damper_force_n(np.array([0.1, -0.1, 0.5, -0.5]), 1.0, P)
    np.testing.assert_allclose(f, [150.0, -400.0, 550.0, -1400.0], atol=1e-9)
    np.testing.assert_allclose(
        strut.damper_force_n(0.3, 2.5, P), 2.5 * strut.damper_force_n(0.3, 1.0, P)
    )  # eq. 5 dpsf scale
    # C1 (PCHIP): left and right slopes at the 0.1 m/s knee agree
    h = 1e-7
    left = (strut.damper_force_n(0.1, 1, P) - strut.damper_force_n(0.1 - h, 1, P)) / h
    right = (strut.damper_force_n(0.1 + h, 1, P) - strut.damper_force_n(0.1, 1, P)) / h
    assert left == pytest.approx(right, rel=1e-4)
    # beyond the table: linear with the end slope (compression 2 m/s: 1050 + 1000 x 1)
    assert strut.damper_force_n(2.0, 1.0, P) == pytest.approx(2050.0)


def test_bump_and_rebound_stops_hand_values():
    # inside the free travel: no force
    np.testing.assert_array_equal(strut.stop_force_n(np.array([0.0, 0.079, -0.129]), P), 0.0)
    # 0.1 m compression: penetration 0.02 m, smoothed d = 0.02 - 0.0025 = 0.0175 m;
    # F = 1e5 x 0.0175 + 5e7 x 0.0175^3 = 1750 + 267.97 = 2017.97 N (pushes apart)
    assert strut.stop_force_n(0.1, P) == pytest.approx(2017.97, rel=1e-4)
    # 0.15 m extension: same penetration beyond 0.13 m, pulls together
    assert strut.stop_force_n(-0.15, P) == pytest.approx(-2017.97, rel=1e-4)


def test_strut_force_is_sum_of_elements():
    x, xd = 0.09, 0.2
    total = strut.strut_force(x, xd, 0.4e-3, 1.5, LOAD, P)
    parts = (
        strut.gas_force_n(x, 0.4e-3, LOAD, P)
        + strut.damper_force_n(xd, 1.5, P)
        + strut.stop_force_n(x, P)
    )
    assert total == pytest.approx(parts, rel=1e-12)
    # broadcasting over a batch of designs
    f = strut.strut_force(
        np.zeros((3, 1)), 0.0, np.array([[0.1e-3], [0.3e-3], [0.6e-3]]), np.ones((3, 1)), LOAD, P
    )
    np.testing.assert_allclose(f, LOAD)


def test_two_accumulators_behave_as_one_volume_when_connected():
    # soft state: both accumulators at one pressure -> identical to one volume of 0.5 L
    k1, k2 = strut.accumulator_constants(0.5e-3, 0.1e-3, LOAD, P)
    x = 0.04
    p = strut.gas_pressure_pa(k1 + k2, 0.5e-3 - A * x, 0.5e-3, P)
    assert (p - P_ATM) * A == pytest.approx(strut.gas_force_n(x, 0.5e-3, LOAD, P), rel=1e-12)
    # stiff state: the small accumulator alone is a 0.1 L spring
    p1 = strut.gas_pressure_pa(k1, 0.1e-3 - A * x, 0.1e-3, P)
    assert (p1 - P_ATM) * A == pytest.approx(strut.gas_force_n(x, 0.1e-3, LOAD, P), rel=1e-12)
    # the split of gas follows the volumes at the common static pressure
    assert k1 / (k1 + k2) == pytest.approx(0.2)


def test_isentropic_reconnection_conserves_each_gas_mass():
    # small accumulator compressed alone to 3 MPa-ish, large one frozen at static state;
    # after reconnection p^(1/n) = (K1 + K2) / (V1 + V2) (strut.py closed form) and each
    # gas mass obeys p V_j^n = const
    n = SP.polytropic_exponent
    k1, k2 = strut.accumulator_constants(0.5e-3, 0.1e-3, LOAD, P)
    v1, v2 = 0.07e-3, 0.4e-3
    p1, p2 = (k1 / v1) ** n, (k2 / v2) ** n
    pe = ((k1 + k2) / (v1 + v2)) ** n
    v1e, v2e = v1 * (p1 / pe) ** (1 / n), v2 * (p2 / pe) ** (1 / n)
    assert v1e + v2e == pytest.approx(v1 + v2, rel=1e-12)  # total volume unchanged
    assert min(p1, p2) < pe < max(p1, p2)
