"""Your own design space: bounds, names, units and baseline from config; a spring stiffness.

config/design_space.yaml holds the paper's design space (test_design.py); these tests
give the tool other ones: other bounds on the built-in model, and a coil-sprung vehicle
(an FMU) whose spring variable is a stiffness and whose damper variable reaches the FMU
through a linear map of the mapping.
"""

import os
import sys

import numpy as np
import pytest
import yaml

from suspension_tuning import evaluation
from suspension_tuning.fmu import FmuModel, parse_mapping
from suspension_tuning.optim.simplified_gradient import SimplifiedGradient
from suspension_tuning.tuning import FullEvaluation, TuningRequest, optimise, physical_settings
from suspension_tuning.vehicle import _simplified_kernel as sk
from suspension_tuning.vehicle import comfort, metrics
from suspension_tuning.vehicle.design import (
    X_LOWER,
    X_UPPER,
    AxleSettings,
    DesignSpace,
    load_design_space,
)
from suspension_tuning.vehicle.params import load_vehicle_params
from suspension_tuning.vehicle.pitch_plane import (
    PitchPlaneModel,
    axle_strut_states,
    derivative_numpy,
    natural_frequencies_hz,
)

sys.path.insert(0, os.path.join(os.path.dirname(__file__), 'fixtures', 'fmu'))
import plate_ride  # noqa: E402  (the coil FMU's model, run directly as the reference)

P = load_vehicle_params()

#: Narrower than the paper's 0.1-3 and 0.1-0.6 L, and different per axle (4 variables).
NARROW = {
    'damper': {'name': 'dpsf', 'unit': '-', 'front': {'low': 0.5, 'high': 2.0, 'baseline': 1.0},
               'rear': {'low': 0.8, 'high': 2.5, 'baseline': 1.0}},
    'spring': {'name': 'gas_volume', 'quantity': 'volume', 'unit': 'L',
               'front': {'low': 0.2, 'high': 0.4, 'baseline': 0.3},
               'rear': {'low': 0.25, 'high': 0.5, 'baseline': 0.3}},
}

#: A coil-sprung vehicle: a damper scale 0.5-2 (the dampers range over 0.5-2x) and a
#: spring rate per strut in kN/m around plate_ride's ~35-45 kN/m gas springs.
COIL = {
    'damper': {'name': 'damping_scale', 'unit': '-',
               'front': {'low': 0.5, 'high': 2.0, 'baseline': 1.0},
               'rear': {'low': 0.5, 'high': 2.0, 'baseline': 1.0}},
    'spring': {'name': 'spring_rate', 'quantity': 'stiffness', 'unit': 'kN/m',
               'front': {'low': 30.0, 'high': 60.0, 'baseline': 45.0},
               'rear': {'low': 30.0, 'high': 60.0, 'baseline': 40.0}},
}


#: COIL for 2 variables, which set both axles alike (eq. 5): equal front and rear entries.
COIL2 = {**COIL, 'spring': {**COIL['spring'], 'rear': COIL['spring']['front']}}


def space(d=NARROW) -> DesignSpace:
    return DesignSpace.from_mapping(yaml.safe_load(yaml.safe_dump(d)), 'test design space')


def test_the_design_space_gives_names_with_units_si_bounds_and_the_baseline():
    coil = space(COIL)
    assert coil.names(4) == ('damping_scale_front', 'spring_rate_front_kn_per_m',
                             'damping_scale_rear', 'spring_rate_rear_kn_per_m')
    assert space(COIL2).names(2) == ('damping_scale', 'spring_rate_kn_per_m')
    low, high = coil.bounds(4)  # SI: kN/m -> N/m
    np.testing.assert_array_equal(low, [0.5, 30e3, 0.5, 30e3])
    np.testing.assert_array_equal(high, [2.0, 60e3, 2.0, 60e3])
    # eq. 4 on the configured ranges: 45 kN/m in 30-60 -> 0.5; 40 in 30-60 -> 1/3
    np.testing.assert_allclose(coil.baseline_x(4), [1 / 3, 0.5, 1 / 3, 1 / 3], rtol=1e-12)
    settings = coil.to_physical([X_UPPER, X_UPPER, X_LOWER, X_LOWER])
    assert settings.spring_quantity == 'stiffness' and settings.gas_volume_front_m3 is None
    assert settings.stiffness_front_n_per_m[0] == 60e3  # x = 1: the upper end exactly
    assert physical_settings([X_UPPER, X_UPPER, 0.5, 0.5], coil) == pytest.approx(
        {'damping_scale_front': 2.0, 'spring_rate_front_kn_per_m': 60.0,
         'damping_scale_rear': 1.25, 'spring_rate_rear_kn_per_m': 45.0}, rel=1e-12)
    # the shipped file is the paper's: names and units every report used so far
    assert load_design_space().physical_names() == (
        'dpsf_front', 'gas_volume_front_l', 'dpsf_rear', 'gas_volume_rear_l')


@pytest.mark.parametrize('edit, message', [
    (lambda d: d['spring'].update(unit='N/m'), "spring.unit: 'N/m' is not a unit of volume"),
    (lambda d: d['damper']['front'].update(low=2.5), 'need 0 < low < high'),
    (lambda d: d['spring']['rear'].update(baseline=0.7),
     'spring.rear.baseline: 0.7 lies outside 0.25-0.5 L'),
    (lambda d: d['spring'].update(quantity='pressure'), "'pressure' is not one of"),
    (lambda d: d['damper'].update(colour='red'), "damper: unknown key(s) ['colour']"),
])
def test_a_bad_design_space_is_refused_naming_the_key(edit, message):
    d = yaml.safe_load(yaml.safe_dump(NARROW))
    edit(d)
    with pytest.raises(ValueError, match='test design space') as error:
        space(d)
    assert message in str(error.value)


def test_two_variables_need_equal_axles_and_say_so():
    with pytest.raises(ValueError, match=r'front and rear entries of dpsf differ \(0.5-2, '
                                         r'baseline 1; 0.8-2.5, baseline 1\)'):
        space().to_physical([0.5, 0.5])


def test_a_start_point_in_physical_units_by_name():
    from suspension_tuning.tune import start_point

    narrow = space()
    x = start_point(['dpsf_front=1.25', 'gas_volume_front_l=0.3', 'dpsf_rear=1.65',
                     'gas_volume_rear_l=0.375'], 4, narrow)
    np.testing.assert_allclose(x, [0.5, 0.5, 0.5, 0.5], rtol=1e-12)  # the range centres
    with pytest.raises(ValueError, match=r'gas_volume_front_l = 0.6 lies outside its range '
                                         r'0.2-0.4 L'):
        start_point(['dpsf_front=1', 'gas_volume_front_l=0.6', 'dpsf_rear=1',
                     'gas_volume_rear_l=0.3'], 4, narrow)
    with pytest.raises(ValueError, match='missing gas_volume_rear_l'):
        start_point(['dpsf_front=1', 'gas_volume_front_l=0.3', 'dpsf_rear=1'], 4, narrow)
    with pytest.raises(ValueError, match='expected NAME=VALUE'):
        start_point(['dpsf_front'], 4, narrow)


def test_an_optimisation_on_other_bounds_reports_a_design_within_them():
    """The built-in model, handling, 4 variables on NARROW: every iterate and the
    reported design lie within its ranges, and the model ran the physical settings of
    that space (the same run as the paper's space at the same physical design)."""
    narrow = space()
    model = evaluation.in_process_model('handling', space=narrow)
    request = TuningRequest('handling', 4, None, 'full', {'maxiter': 3})
    result = optimise(request, model)
    for record in result.history:
        values = physical_settings(record['x'], narrow)
        assert 0.5 <= values['dpsf_front'] <= 2.0 and 0.8 <= values['dpsf_rear'] <= 2.5
        assert 0.2 <= values['gas_volume_front_l'] <= 0.4
        assert 0.25 <= values['gas_volume_rear_l'] <= 0.5
    reported = physical_settings(result.x_best, narrow)
    assert 0.5 <= reported['dpsf_front'] <= 2.0 and 0.25 <= reported['gas_volume_rear_l'] <= 0.5
    # The run at x_best is the paper's-space run of the same physical design: eq. 4 on
    # the other ranges changed x, not the physics (rounding of the two maps aside).
    paper = load_design_space()
    x_paper = paper.from_physical(narrow.to_physical(result.x_best, 4), 4)
    same = evaluation.evaluate('handling', x_paper)
    np.testing.assert_allclose(same.f[0], result.f_best, rtol=1e-9)
    # the reported design's named metrics came with it (roll in deg, lift-off fraction)
    assert result.metrics_best['roll_first_peak_deg'] == pytest.approx(
        same.metrics[0, same.metric_names.index('roll_first_peak_deg')], rel=1e-9)


def test_the_builtin_model_refuses_a_stiffness_spring():
    with pytest.raises(ValueError, match="the built-in 4S4 model's springs are gas springs"):
        evaluation.evaluate('ride', np.array([[0.5, 0.5]]), space=space(COIL2))


def coil_settings(rate_front, rate_rear, dpsf_front=1.0, dpsf_rear=1.0):
    return AxleSettings.of({'front': dpsf_front, 'rear': dpsf_rear},
                           {'front': rate_front, 'rear': rate_rear}, 'stiffness')


def test_the_simplified_ride_model_uses_a_linear_spring_of_the_designed_rate():
    # kernel and numpy reference agree on a coil spring (strokes into the bump stop:
    # 0.1 m > the 0.08 m clearance, so the stop adds to the linear spring there)
    model = PitchPlaneModel(P, dt_s=0.004)
    settings = coil_settings(40e3, 55e3, 0.7, 1.6)
    ss = axle_strut_states(settings, P)
    rng = np.random.default_rng(2)
    for _ in range(4):
        s = np.concatenate([rng.uniform(-0.05, 0.05, 4), rng.normal(0, 0.5, 4)])
        d, out = np.empty(8), np.empty(sk.N_PP_OUT)
        road = rng.normal(0, 0.01, 4)
        sk.pp_deriv(s, ss[0], model._P, model._dk, model._dv, model._ds, *road, d, out, True)
        np.testing.assert_allclose(d, derivative_numpy(s[None], settings, road, P)[0],
                                   rtol=1e-10, atol=1e-8)
    # The linearised model's heave-pitch stiffness is the designed rates' exactly: two
    # struts of k_f at the front (lever a), two of k_r at the rear (lever b).
    kf, kr, a, b = 40e3, 55e3, P.a_m, P.b_m
    kt = P.tyre.vertical_stiffness_n_per_m
    cf, cr = np.array([-1.0, a, 1.0, 0.0]), np.array([-1.0, -b, 0.0, 1.0])
    K = 2 * kf * np.outer(cf, cf) + 2 * kr * np.outer(cr, cr) + np.diag([0, 0, 2 * kt, 2 * kt])
    M = np.diag([P.mass_sprung_kg, P.i_pitch_sprung_kgm2, P.mass_axle_front_kg,
                 P.mass_axle_rear_kg])
    from scipy import linalg
    hand = np.sqrt(linalg.eigh(K, M, eigvals_only=True)) / (2 * np.pi)
    np.testing.assert_allclose(natural_frequencies_hz(settings, P), hand, rtol=1e-5)


# ---- a coil-sprung vehicle as an FMU ------------------------------------------------
STOP_S, STEP_S, SETTLE_S = 4.0, 0.002, 2.0  # as test_fmu.py: short runs, W_b settled
CORNERS = ('fl', 'fr', 'rl', 'rr')
#: The damper variable (a scale factor) reaches the FMU's damping coefficient through a
#: linear map: c = 500 N s/m + 2500 N s/m x scale; the spring rate goes in N/mm.
DAMPING_OFFSET, DAMPING_SCALE = 500.0, 2500.0


def coil_mapping():
    linear = {'scale': DAMPING_SCALE, 'offset': DAMPING_OFFSET, 'unit': 'N.s/m'}
    return {
        'design': {'damping_scale_front': {'name': 'dampingF', **linear},
                   'damping_scale_rear': {'name': 'dampingR', **linear},
                   'spring_rate_front': {'name': 'springRateF', 'unit': 'N/mm'},
                   'spring_rate_rear': {'name': 'springRateR', 'unit': 'N/mm'}},
        'scenarios': {'ride': {
            'stop_time_s': STOP_S, 'step_size_s': STEP_S, 'settle_s': SETTLE_S,
            'speed_kmh': 50.0,
            'road': {'wheelbase_m': plate_ride.A_M + plate_ride.B_M,
                     'start_rear_axle_at_m': 0.5,
                     'inputs': {c: f'zRoad{c.upper()}' for c in CORNERS}},
            'outputs': {'acc_driver': 'seatDriverAz', 'acc_passenger': 'seatPassengerAz',
                        'tyre_fz': {c: f'Fz{c.upper()}' for c in CORNERS}}}},
    }


def coil_model(fmus, design_space=None):
    return FmuModel(fmus['coil'], parse_mapping(yaml.safe_dump(coil_mapping()),
                                                space=design_space or space(COIL)))


def test_fmu_mapping_with_scale_and_offset_sets_the_parameters_it_says(fmus):
    """The linear map's FMU value is offset + scale x the variable (in its unit), and a
    stiffness in kN/m reaches an N/mm parameter converted: the FMU's scores equal those
    of its model run directly with those physical values."""
    from suspension_tuning.vehicle import road as road_mod
    from suspension_tuning.vehicle import scenarios as scen
    from suspension_tuning.vehicle.params import load_scenarios_config

    x = np.array([[0.2, 0.3, 0.9, 0.6]])  # 4 variables: each axle its own values
    with coil_model(fmus) as fmu:
        values = fmu._parameter_values(fmu.mapping.scenarios['ride'], x)[0]
        result = fmu.evaluate('ride', x)
    # scale 0.5 + 0.2 x 1.5 = 0.8 -> 500 + 2500 x 0.8 = 2500 N s/m; rear 0.5 + 0.9 x 1.5
    # = 1.85 -> 5125 N s/m; rates 30 + 0.3 x 30 = 39 kN/m = 39 N/mm, 30 + 0.6 x 30 = 48
    assert values['dampingF'] == pytest.approx(2500.0, rel=1e-12)
    assert values['dampingR'] == pytest.approx(5125.0, rel=1e-12)
    assert values['springRateF'] == pytest.approx(39.0, rel=1e-12)
    assert values['springRateR'] == pytest.approx(48.0, rel=1e-12)
    profile = road_mod.synthesise_tracks(scen.ride_road_spec(load_scenarios_config()['ride']))
    v, n = 50.0 / 3.6, int(round(STOP_S / STEP_S))
    m = plate_ride.coil_sprung(2500.0, 5125.0, 39e3, 48e3)
    seats = np.zeros((2, n + 1))
    for k in range(n + 1):
        seats[:, k] = m.seat_acc(plate_ride.DRIVER), m.seat_acc(plate_ride.PASSENGER)
        xr = 0.5 + v * k * STEP_S
        xf = xr + plate_ride.A_M + plate_ride.B_M
        road = (profile.elevation(xf, 'left'), profile.elevation(xf, 'right'),
                profile.elevation(xr, 'left'), profile.elevation(xr, 'right'))
        for _ in range(2 if k < n else 0):
            m.step(STEP_S / 2, road)
    a = comfort.weighted_rms(seats, 1.0 / STEP_S, t_settle_s=SETTLE_S)
    np.testing.assert_allclose(result.f, metrics.f_ride(a[0], a[1]), rtol=1e-9)


def test_fmu_coil_sprung_vehicle_optimised_on_its_spring_rate_stays_within_its_bounds(fmus):
    """Ride optimisation of the coil FMU on COIL's 2 variables with simplified-model
    gradients: the pitch-plane model with a linear spring of the iterate's rate (unscaled:
    no eq. 25 calibration, enough for a few iterations).  The reported design lies in
    the design space's ranges, in physical units."""
    coil = space(COIL2)
    with coil_model(fmus, coil) as fmu:

        def full_model(points):
            run = fmu.evaluate('ride', points)
            return FullEvaluation(run.f, run.g, metric_names=run.metric_names,
                                  metrics=run.metrics)

        request = TuningRequest('ride', 2, None, 'simplified', {'maxiter': 2})
        result = optimise(request, full_model, SimplifiedGradient('ride', 2, space=coil))
    assert result.n_simplified_runs > 0 and result.nit >= 1
    reported = physical_settings(result.x_best, coil)
    assert 0.5 <= reported['damping_scale_front'] <= 2.0
    assert 30.0 <= reported['spring_rate_front_kn_per_m'] <= 60.0
    assert reported['spring_rate_front_kn_per_m'] == reported['spring_rate_rear_kn_per_m']
    # the reported design's seat W_b RMS came with the result, in m/s^2
    assert 0.02 < result.metrics_best['a_rms_driver_mps2'] < 5.0


def _with_variables(entries, presets=None):
    from suspension_tuning.vehicle.design import load_design_space
    d = load_design_space().as_dict()
    d['variables'] = entries
    d['presets'] = presets or {'p3': [e['name'] for e in entries]}
    return d


BAR = {'name': 'bar_rear', 'target': 'anti_roll_bar', 'axle': 'rear', 'unit': 'kN.m/rad',
       'low': 0.0, 'high': 40.0, 'baseline': 15.0}
REBOUND = {'name': 'reb_front', 'target': 'dpsf_rebound', 'axle': 'front', 'unit': '-',
           'low': 0.1, 'high': 3.0, 'baseline': 1.0}
COMP = {'name': 'comp_front', 'target': 'dpsf_compression', 'axle': 'front', 'unit': '-',
        'low': 0.1, 'high': 3.0, 'baseline': 1.0}


@pytest.mark.parametrize('change, key', [
    ({'target': 'spring_preload'}, r'variables\[0\] \(bar_rear\)\.target: unknown target'),
    ({'low': 40.0}, r'variables\[0\] \(bar_rear\)\.low: empty or invalid range'),
    ({'baseline': 50.0}, r'variables\[0\] \(bar_rear\)\.baseline: 50 lies outside'),
    ({'unit': 'N/m'}, r'variables\[0\] \(bar_rear\)\.unit'),
])
def test_a_bad_variable_is_refused_naming_its_key(change, key):
    from suspension_tuning.vehicle.design import DesignSpace
    d = _with_variables([{**BAR, **change}, REBOUND, COMP])
    with pytest.raises(ValueError, match=key):
        DesignSpace.from_mapping(d, 'config/design_space.yaml')


def test_a_bad_preset_is_refused_naming_its_key():
    from suspension_tuning.vehicle.design import DesignSpace
    with pytest.raises(ValueError, match=r'presets\.p3: unknown variable'):
        DesignSpace.from_mapping(_with_variables([BAR, REBOUND, COMP],
                                                 {'p3': ['bar_rear', 'reb_front', 'x']}))
    with pytest.raises(ValueError, match=r"presets\.p2: 2 variables: 2 and 4 are the paper"):
        DesignSpace.from_mapping(_with_variables([BAR, REBOUND, COMP],
                                                 {'p2': ['bar_rear', 'reb_front']}))


def test_a_preset_maps_x_to_its_targets_and_back():
    # eq. 4 per variable; a bar range may start at 0 (an axle without a bar)
    from suspension_tuning.vehicle.design import DesignSpace
    space = DesignSpace.from_mapping(_with_variables([BAR, REBOUND, COMP]))
    assert space.sizes == (2, 3, 4)
    assert space.names(3) == ('bar_rear_knm_per_rad', 'reb_front', 'comp_front')
    x = np.array([0.5, 0.25, 0.75])
    settings = space.to_physical(x)
    assert settings.anti_roll_bar('rear')[0] == pytest.approx(20e3)  # 0.5 x 40 kN m/rad
    assert settings.anti_roll_bar('front') is None  # config/vehicle.yaml's bar
    assert settings.dpsf_rebound('front')[0] == pytest.approx(0.1 + 0.25 * 2.9)
    assert settings.dpsf('front')[0] == pytest.approx(0.1 + 0.75 * 2.9)
    assert settings.dpsf_rebound('rear')[0] == pytest.approx(1.0)  # damper baseline
    np.testing.assert_allclose(space.from_physical(settings, 3)[0], x)
    assert space.x_from_values(space.physical_values(x), 3) == pytest.approx(x)


def test_the_shipped_ride8_preset_changes_the_full_model_through_every_variable():
    # each of the 8 variables moved by 0.3 (normalised) from the baseline changes the
    # full model's handling f (eq. 10): the split damper, gas volumes and both bars
    # all reach the model (none is silently dropped)
    from suspension_tuning.vehicle.design import load_design_space
    from suspension_tuning.vehicle.scenarios import run_scenario
    x0 = load_design_space().baseline_x(8)
    X = np.tile(x0, (9, 1))
    for i in range(8):
        X[i + 1, i] = x0[i] + 0.3
    f = run_scenario('handling', X, n_vars=8).f
    assert np.all(np.abs(f[1:] - f[0]) > 1e-4)


def test_tune_start_with_the_eight_names_of_ride8_picks_that_design():
    # --start with the preset's names and no --n-vars: the size follows from the names;
    # each value maps by eq. 4 on its own range (dpsf 0.1-3, 0.1-0.6 L, 0-40 kN m/rad)
    from suspension_tuning.tune import start_point
    from suspension_tuning.vehicle.design import load_design_space

    names = load_design_space().names(8)
    values = ['1.55', '1.55', '0.35', '1.55', '1.55', '0.35', '20', '20']
    x = start_point([f'{n}={v}' for n, v in zip(names, values)], None)
    np.testing.assert_allclose(x, [0.5] * 8, rtol=1e-12)  # every range's centre
    with pytest.raises(ValueError, match='missing anti_roll_bar_rear_knm_per_rad'):
        start_point([f'{n}={v}' for n, v in zip(names[:7], values)], 8)
