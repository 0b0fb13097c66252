"""Tests of the simplified handling model (paper section 6.1, eqs. 12-14)."""

from __future__ import annotations

import numpy as np
import pytest

from suspension_tuning.vehicle import _simplified_kernel as sk
from suspension_tuning.vehicle import strut
from suspension_tuning.vehicle.design import AxleSettings, to_physical
from suspension_tuning.vehicle.handling_model import (
    HandlingInputs,
    HandlingModel,
    derivative_numpy,
)
from suspension_tuning.vehicle.params import load_vehicle_params
from suspension_tuning.vehicle.pitch_plane import axle_strut_states
from suspension_tuning.vehicle.tyre import pacejka89_lateral

P = load_vehicle_params()


def _inputs(slip_deg=-0.3, duration_s=8.0, dt=0.004, steer=0.0):
    t = np.arange(int(round(duration_s / dt)) + 1) * dt
    slip = np.full((4, t.size), np.radians(slip_deg))
    return HandlingInputs(t, 65 / 3.6, np.full(t.size, steer), slip, (1.0, 4.0), (0.5, 7.5))


@pytest.mark.parametrize(
    'options',
    [
        {},
        {'slip_angles': 'own', 'gravity_roll_moment': True, 'anti_roll_bar': True},
        {'roll_moment_arm': 'roll_axis'},
    ],
)
@pytest.mark.parametrize('spring', ['volume', 'stiffness'])
def test_compiled_derivative_matches_numpy_reference(options, spring):
    # kernel (numba) and reference (strut.strut_force, tyre.pacejka89_lateral) implement
    # the same eqs. 12-14 for every option and both spring laws (the 4S4 gas spring, a
    # coil spring of a design space whose spring is a stiffness, 20-80 kN/m); random
    # states with roll up to 0.1 rad
    rng = np.random.default_rng(3)
    model = HandlingModel(P, options)
    springs = (1e-4, 6e-4) if spring == 'volume' else (20e3, 80e3)
    settings = AxleSettings.of(
        {'front': rng.uniform(0.1, 3, 5), 'rear': rng.uniform(0.1, 3, 5)},
        {'front': rng.uniform(*springs, 5), 'rear': rng.uniform(*springs, 5)}, spring)
    # the bars are per design in the strut states (the option adds the vehicle's)
    ss = axle_strut_states(settings, P, vehicle_bars=model.options['anti_roll_bar'])
    Pv = model._P.copy()
    Pv[sk.HP_U] = 18.0
    for b in range(5):
        s = np.array([0.3, 0.05, *rng.normal(0, 0.5, 2), rng.uniform(-0.1, 0.1), rng.normal()])
        slip = rng.normal(0, 0.05, 4)
        steer = rng.normal(0, 0.05)
        d = np.empty(6)
        out = np.empty(sk.N_H_OUT)
        sk.h_deriv(s, ss[b], Pv, model._dk, model._dv, model._ds, model._pc, slip, steer, d,
                   out, True)  # fmt: skip
        one = AxleSettings.of({a: settings.dpsf(a)[b] for a in ('front', 'rear')},
                              {a: settings.spring(a)[b] for a in ('front', 'rear')}, spring)
        ref = derivative_numpy(s[None], one, slip, steer, 18.0, model)[0]
        np.testing.assert_allclose(d, ref, rtol=1e-9, atol=1e-9)


def test_steady_roll_matches_hand_calculation():
    # constant slip angles -0.3 deg on all tyres: constant left force; after the roll
    # transient has decayed (dpsf 1, 8 s) eq. 14 balances
    #   (k_f + k_r) t_s^2 / 2 * phi = h_cg (m_b / m_v) sum(F_y)
    # with the tangent gas stiffness k = n p_s A^2 / V_s (physics-ref 3.2).  The gas
    # spring is odd-symmetric left/right to first order; its cubic term changes the roll
    # stiffness by ~(A x / V)^2 < 0.5 % at these strokes (~3 mm): tolerance 1 %.
    model = HandlingModel(P)
    settings = to_physical(np.array([[0.31, 0.5]]))
    rec = model.simulate(settings, _inputs())
    phi = rec.roll_rad[0, -1]
    sum_fy = rec.tyre_fy_n[0, :, -1].sum()
    kf = strut.gas_stiffness_n_per_m(
        settings.gas_volume_front_m3[0], P.static_strut_load_front_n, P
    )
    kr = strut.gas_stiffness_n_per_m(settings.gas_volume_rear_m3[0], P.static_strut_load_rear_n, P)
    hand = 0.95 * (1950 / 2400) * sum_fy / ((kf + kr) * 1.10**2 / 2)
    assert sum_fy > 0  # negative slip angle gives a leftward (positive) force, ISO
    assert phi > 0  # leftward tyre force rolls the body right side down: phi > 0 (ISO)
    np.testing.assert_allclose(phi, hand, rtol=0.01)
    # eq. 13: lateral acceleration = sum F_y / m_v
    np.testing.assert_allclose(rec.lateral_accel_mps2[0, -1], sum_fy / 2400.0, rtol=1e-12)


def test_tyre_forces_are_pacejka_of_static_share_of_side_strut_force():
    model = HandlingModel(P)
    settings = to_physical(np.array([[0.5, 0.2]]))
    rec = model.simulate(settings, _inputs(slip_deg=-2.0))
    fz, fy = rec.tyre_fz_n[0, :, -1], rec.tyre_fy_n[0, :, -1]
    # Pacejka '89 of the loads with the input slip angle (shared tyre.py)
    np.testing.assert_allclose(fy, pacejka89_lateral(np.radians(-2.0), fz, P), rtol=1e-10)
    # loads [P s.6.1]: static front share b/L (rear a/L) of the side's summed strut force,
    # plus half the axle weight; strut forces from strut.strut_force at the roll strokes
    # -/+ (t_s / 2) phi of the left/right struts
    phi, phid = rec.roll_rad[0, -1], rec.roll_rate_radps[0, -1]
    x, xd = 0.55 * phi, 0.55 * phid

    def side(sign):
        return sum(
            strut.strut_force(sign * x, sign * xd, vol, dpsf, load, P)
            for vol, dpsf, load in (
                (
                    settings.gas_volume_front_m3[0],
                    settings.dpsf_front[0],
                    P.static_strut_load_front_n,
                ),
                (
                    settings.gas_volume_rear_m3[0],
                    settings.dpsf_rear[0],
                    P.static_strut_load_rear_n,
                ),
            )
        )

    f_left, f_right = side(-1.0), side(1.0)
    share_f = (2.794 - 1.33) / 2.794
    expect = [
        share_f * f_left + 230 * 9.81 / 2,
        share_f * f_right + 230 * 9.81 / 2,
        (1 - share_f) * f_left + 220 * 9.81 / 2,
        (1 - share_f) * f_right + 220 * 9.81 / 2,
    ]
    np.testing.assert_allclose(fz, expect, rtol=1e-9)
    assert fz[1] > fz[0]  # right (outer) tyres loaded more with a leftward tyre force
    # the paper's model has no heave DOF: the progressive gas springs make the summed
    # loads exceed the weight at large roll (here phi ~ 0.1 rad) - a documented limitation
    assert fz.sum() > 2400 * 9.81


def test_own_slip_angles_without_steering_give_no_roll():
    # with 'own' slip angles the inputs' slip histories are ignored; zero steer on a
    # straight line gives zero slip, zero force and no roll
    model = HandlingModel(P, {'slip_angles': 'own'})
    rec = model.simulate(to_physical(np.array([[0.5, 0.5]])), _inputs(slip_deg=-3.0))
    assert np.max(np.abs(rec.roll_rad)) < 1e-12


def test_handling_inputs_are_checked():
    t = np.arange(10) * 0.004
    ok = dict(t_s=t, speed_mps=18.0, steer_rad=np.zeros(10), slip_angle_rad=np.zeros((4, 10)),
              first_lane_change_s=(0.0, 0.02), manoeuvre_s=(0.0, 0.03))  # fmt: skip
    HandlingInputs(**ok)
    with pytest.raises(ValueError, match='slip_angle_rad'):
        HandlingInputs(**{**ok, 'slip_angle_rad': np.zeros((3, 10))})
    with pytest.raises(ValueError, match='NaN'):
        HandlingInputs(**{**ok, 'steer_rad': np.full(10, np.nan)})
    with pytest.raises(ValueError, match='uniform'):
        HandlingInputs(**{**ok, 't_s': t**2})
    with pytest.raises(ValueError, match='manoeuvre_s'):
        HandlingInputs(**{**ok, 'manoeuvre_s': (0.03, 0.0)})
    with pytest.raises(ValueError, match='slip_angles'):
        HandlingModel(P, {'slip_angles': 'magic'})
