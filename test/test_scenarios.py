"""Tests of the ride and handling scenarios (scenarios.py) of the full vehicle model."""

import numpy as np
import pytest

from suspension_tuning.vehicle import scenarios
from suspension_tuning.vehicle.params import load_scenarios_config, load_vehicle_params

P = load_vehicle_params()
# 2-variable design corners (dpsf, gvol), normalised (eqs. 5-6): low/low, low/high, ...
CORNERS = np.array([[0.001, 0.001], [0.001, 1.0], [1.0, 0.001], [1.0, 1.0]])
LOW_D_STIFF, LOW_D_SOFT, HIGH_D_STIFF, HIGH_D_SOFT = range(4)
# baseline design (config/scenarios.yaml): dpsf 1.0, gvol 0.3 L -> eq. 5
X_BASELINE = np.array([(1.0 - 0.1) / 2.9, (0.3 - 0.1) / 0.5])


@pytest.fixture(scope='module')
def handling_corners():
    return scenarios.run_scenario('handling', CORNERS, P)


@pytest.fixture(scope='module')
def ride_corners():
    return scenarios.run_scenario('ride', CORNERS, P)


def test_unknown_scenario_and_bad_designs_raise_value_error():
    with pytest.raises(ValueError, match='ride, handling'):
        scenarios.run_scenario('slalom', X_BASELINE, P)
    with pytest.raises(ValueError):
        scenarios.run_scenario('ride', np.array([0.5, 0.5, 0.5]), P)  # 3 variables
    with pytest.raises(ValueError):
        scenarios.run_scenario('ride', np.array([0.5, np.nan]), P)
    with pytest.raises(ValueError):
        scenarios.run_scenario('handling', np.array([0.5, 1.2]), P)  # above X_UPPER = 1


def test_dlc_track_is_iso_3888_1_for_the_defender_width():
    cfg = load_scenarios_config()['handling']
    track, _, _, speed = scenarios.handling_setup(P, cfg)
    b = 1.79  # [m] Defender 110 width (vehicle.yaml body_width_m)
    assert cfg['track']['vehicle_width_m'] == P.body_width_m == b
    # ISO 3888-1: section lengths 15/30/25/25/15/15 m, lane widths 1.1b+0.25,
    # 1.2b+0.25, 1.3b+0.25 = 2.219 / 2.398 / 2.577 m, lateral offset 3.5 m
    np.testing.assert_allclose(np.diff(track.section_bounds_m), [15, 30, 25, 25, 15, 15])
    widths = [lane.width_m for lane in track.lanes]
    np.testing.assert_allclose(widths[:3], [2.219, 2.398, 2.577], atol=1e-9)
    assert track.y_ref(np.array([57.5]))[0] == pytest.approx(3.5)  # middle of lane 3
    assert speed == pytest.approx(65 / 3.6)  # paper section 4.1


def test_driver_keeps_baseline_vehicle_inside_the_cones_at_65_kmh():
    res = scenarios.run_scenario('handling', X_BASELINE, P)
    assert res.metrics['cone_violation_m'][0] < 0.0  # footprint inside all lane sections
    # speed held by the controller: within 0.5 km/h of 65 km/h throughout
    assert res.metrics['speed_min_mps'][0] > (65 - 0.5) / 3.6
    assert res.f.shape == (1,) and res.g.shape == (1, 4)


def test_handling_corners_have_sensible_trends(handling_corners):
    m = handling_corners.metrics
    peak, rate = m['roll_first_peak_deg'], m['roll_rate_rms_deg_s']
    # trends: a stiffer spring (small gvol) rolls less, more damping rolls less
    assert peak[LOW_D_STIFF] < peak[LOW_D_SOFT] and peak[HIGH_D_STIFF] < peak[HIGH_D_SOFT]
    assert peak[HIGH_D_SOFT] < peak[LOW_D_SOFT] and rate[HIGH_D_SOFT] < rate[LOW_D_SOFT]
    assert rate[HIGH_D_STIFF] < rate[LOW_D_STIFF]
    # the handling optimum lies at high damping and the small gas volume (Els et al. 2007)
    assert np.argmin(handling_corners.f) == HIGH_D_STIFF
    assert np.all(m['cone_violation_m'] <= 0.0)  # every corner completes the manoeuvre
    # quasi-static check of the stiffest corner: K_phi ~ 2 x 143 kN/m x 1.1^2/2 x 2 axles
    # + 15 kN m/rad bar, in series with the tyres, less m g h ~ 8.6 kN m/rad ~ 160 kN m/rad;
    # roll moment m_s h a_y = 1950 x 0.45 x 4.4 = 3.9 kN m -> ~1.4 deg; the first peak
    # includes some overshoot and the lateral acceleration varies: allow 1.0-2.0 deg
    assert 1.0 < peak[HIGH_D_STIFF] < 2.0


@pytest.mark.xfail(
    strict=True,
    reason=(
        'model disagrees with the paper: corner first roll peaks 1.27-8.74 deg (paper '
        '1.4-12.2: the stiff/high-damping corner is 9 % below) and RMS roll rate 4.5-20.6 '
        'deg/s (paper 0.8-5.7).  No window or definition reproduces the paper: over the '
        'first lane change, the whole run or up to 20 s after the manoeuvre the corner '
        'ratio stays 4.6-4.7 (paper 7.1), and rescaling by the window alone would need '
        '218 s for the smallest corner but 91 s for the largest, against a 7 s manoeuvre '
        '(studies/roll_rate_window.py); vehicle parameters not tuned'
    ),
)
def test_handling_corners_in_paper_ranges(handling_corners):
    m = handling_corners.metrics
    peak, rate = m['roll_first_peak_deg'], m['roll_rate_rms_deg_s']
    assert np.all((peak >= 1.4) & (peak <= 12.2))
    assert np.all((rate >= 0.8) & (rate <= 5.7))


def test_ride_corners_physically_sensible_trends(ride_corners):
    m = ride_corners.metrics
    ad, ap = m['a_rms_driver_mps2'], m['a_rms_passenger_mps2']
    assert np.all(ad > 0.05) and np.all(ap > 0.05)
    # softer spring (larger gvol) -> lower weighted acceleration at either damping level
    assert ad[LOW_D_SOFT] < ad[LOW_D_STIFF] and ad[HIGH_D_SOFT] < ad[HIGH_D_STIFF]
    assert ap[LOW_D_SOFT] < ap[LOW_D_STIFF] and ap[HIGH_D_SOFT] < ap[HIGH_D_STIFF]
    # soft spring + little damping -> the largest strut strokes
    stroke = m['strut_stroke_max_m'].max(axis=1)
    assert np.argmax(stroke) == LOW_D_SOFT
    # eq. 9 and 11 shapes; eq. 11 is -1 when a tyre never leaves the ground
    assert ride_corners.f.shape == (4,) and ride_corners.g.shape == (4, 4)
    np.testing.assert_allclose(ride_corners.g, 10 * (m['tyre_lift_off_fraction'] - 0.1))


def test_ride_corners_span_the_papers_range(ride_corners):
    # paper section 5.2: the four corners of its validated model span 0.7-4.4 m/s^2.
    # The paving's stone height spread is identified from exactly these two numbers
    # (studies/road_identification.py, one parameter for two values), so this checks the
    # identified road on the scenario's own seed; 25 % is the identification's accepted
    # error (over 6 road seeds the smallest value scatters 0.67-0.84, the largest 3.8-4.6)
    m = ride_corners.metrics
    a = np.stack([m['a_rms_driver_mps2'], m['a_rms_passenger_mps2']])
    assert a.min() == pytest.approx(0.7, rel=0.25)
    assert a.max() == pytest.approx(4.4, rel=0.25)


def test_ride_wants_low_damping_until_the_tyres_hop(ride_corners):
    # on a rough paved track a little damping rides best (the damper transmits the
    # stones' harshness), and tyre hop is what limits it [P s.5.3, Figs 7, 8, 16]
    ad = ride_corners.metrics['a_rms_driver_mps2']
    assert ad[LOW_D_SOFT] < ad[HIGH_D_SOFT]
    g = ride_corners.g
    # eq. 11 infeasible (more than 10 % of the time off the ground) at a low-damping
    # corner, feasible at both high-damping corners
    assert g[LOW_D_SOFT].max() > 0.0 and g[LOW_D_STIFF].max() > 0.0
    assert g[HIGH_D_SOFT].max() <= 0.0 and g[HIGH_D_STIFF].max() <= 0.0
    # ... and feasible at the centre of the design space (dpsf 1.55, 0.35 L)
    centre = scenarios.run_scenario('ride', np.array([0.5, 0.5]), P)
    assert centre.g.max() <= 0.0
    # the constraint is active in between: some tyre leaves the ground at the centre
    assert centre.metrics['tyre_lift_off_fraction'].max() > 0.0


def test_histories_hold_the_channels_the_simplified_models_need(ride_corners):
    h = ride_corners.histories
    n = h['t_s'].size
    # decimated histories: vehicle.yaml time_step_s x history_decimation (2 ms x 2 = 4 ms)
    assert h['t_s'][1] - h['t_s'][0] == pytest.approx(P.dt_s * P.history_decimation)
    assert P.dt_s * P.history_decimation <= 0.01  # at least 100 Hz (lead's 100-200 Hz)
    for key in (
        'slip_angle_rad',
        'road_under_wheel_m',
        'strut_force_n',
        'strut_stroke_m',
        'tyre_fz_n',
    ):
        assert h[key].shape == (4, 4, n), key
    for key in (
        'steer_rad',
        'roll_deg',
        'roll_rate_deg_s',
        'acc_driver_mps2',
        'acc_passenger_mps2',
    ):
        assert h[key].shape == (4, n), key


def test_same_design_gives_same_bits_alone_and_in_a_batch(handling_corners):
    alone = scenarios.run_scenario('handling', CORNERS[2], P)
    assert alone.f[0] == handling_corners.f[2]
    np.testing.assert_array_equal(
        alone.histories['roll_deg'][0], handling_corners.histories['roll_deg'][2]
    )


def test_four_variable_design_with_equal_axles_equals_two_variable_design(handling_corners):
    # eqs. 5 and 7: (dpsf, gvol) applied to both axles == (dpsff, gvolf, dpsfr, gvolr) equal
    x4 = np.array([CORNERS[2, 0], CORNERS[2, 1], CORNERS[2, 0], CORNERS[2, 1]])
    res4 = scenarios.run_scenario('handling', x4, P)
    assert res4.x.shape == (1, 4)
    assert res4.f[0] == handling_corners.f[2]
    # and a stiffer rear axle changes the result (the variables are really uncoupled)
    x4b = x4.copy()
    x4b[3] = 1.0  # soft rear spring
    assert scenarios.run_scenario('handling', x4b, P).f[0] != res4.f[0]
