"""Tests of the roll-and-pitch ride model (the pitch-plane model of section 6.2 with roll)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from suspension_tuning.vehicle import simplified
from suspension_tuning.vehicle.design import load_design_space, to_physical
from suspension_tuning.vehicle.full_model import RoadInput
from suspension_tuning.vehicle.params import load_vehicle_params
from suspension_tuning.vehicle.pitch_plane import (
    PitchPlaneModel,
    RideSetup,
    load_simplified_config,
    static_tyre_deflections_m,
)
from suspension_tuning.vehicle.road import load_road_spec, synthesise_tracks
from suspension_tuning.vehicle.roll_pitch import RollPitchModel
from suspension_tuning.vehicle.runs import run_full

P = load_vehicle_params()
# the 8-variable ride design of benchmarks/references.json (ride_8var): damping
# compression/rebound and gas volume per axle, then the front and rear bar, normalised
RIDE8_REFERENCE = np.array([0.5535, 0.0916, 0.9986, 0.7416, 0.1087, 1.0, 0.1696, 0.397])


def test_static_equilibrium_is_kept_on_a_flat_road():
    # zero stroke gives the static strut load and each tyre carries its static load at
    # delta_stat (as in the pitch-plane model), whatever the bars: the model stays at rest
    model = RollPitchModel(P, RideSetup(RoadInput.flat(), 13.9, 2.0, 1.0, 0.0))
    rec = model.simulate(to_physical(np.array([[0.001, 0.001], [1.0, 1.0]])))
    for channel in (rec.heave_m, rec.pitch_rad, rec.roll_rad):
        assert np.max(np.abs(channel)) < 1e-9
    dstf, dstr = static_tyre_deflections_m(P)
    k_t = P.tyre.vertical_stiffness_n_per_m
    np.testing.assert_allclose(rec.tyre_fz_n[:, :2], dstf * k_t, rtol=1e-9)
    np.testing.assert_allclose(rec.tyre_fz_n[:, 2:], dstr * k_t, rtol=1e-9)


def test_identical_tracks_reduce_it_to_the_pitch_plane_model():
    # with the same road under the left and right wheels every left force equals its right
    # one, so roll and axle roll stay zero (bars and seat offsets do nothing) and the
    # vertical equations are eqs. 15-21: f and g must be the pitch-plane model's to
    # rounding
    spec = dataclasses.replace(load_road_spec('belgian_paving'), coherence_model='identical',
                               length_m=120.0)
    road = RoadInput.from_profile(synthesise_tracks(spec), P.tyre.contact_length_m)
    setup = RideSetup(road, 50 / 3.6, 6.0, 1.0, 0.5 + P.b_m)
    x = np.array([[0.5, 0.5, 0.5, 0.5], [0.05, 0.9, 0.05, 0.2], [1.0, 0.1, 0.3, 1.0]])
    rp = RollPitchModel(P, setup)
    rec = rp.simulate(to_physical(x, 4))
    assert np.max(np.abs(rec.roll_rad)) == 0.0
    ours = rp.evaluate(x, 4)
    ref = PitchPlaneModel(P, setup).evaluate(x, 4)
    np.testing.assert_allclose(ours['f'], ref['f'], rtol=1e-9)
    np.testing.assert_allclose(ours['g'], ref['g'], atol=1e-12)
    assert np.max(ref['g']) > -0.9  # the designs lift a tyre off at times: g is tested


def test_tyre_hop_per_tyre_follows_the_full_model_and_sees_the_bars():
    # on the ride road the left and right tracks differ: the full model's eq. 11 at the
    # 8-variable reference is -0.004 / -0.094 / 0.000 / -0.053 (FL, FR, RL, RR), the left
    # tyres on the boundary.  The pitch-plane model (the tracks' average) gives -0.84 at
    # every tyre; this model must be within 0.06 of the full model at each tyre (measured
    # 0.01-0.05: no body torsion, roll axis or lateral motion here) and move g with the
    # bar in the full model's direction
    space = load_design_space()
    ride8 = RollPitchModel().evaluate(RIDE8_REFERENCE, 8, space)
    full = np.asarray(run_full('ride', RIDE8_REFERENCE[None, :]).g)[0]
    np.testing.assert_allclose(ride8['g'][0], full, atol=0.06)
    soft_rear, stiff_rear = RIDE8_REFERENCE.copy(), RIDE8_REFERENCE.copy()
    soft_rear[7], stiff_rear[7] = 0.05, 1.0
    x = np.stack([soft_rear, stiff_rear])
    ours = RollPitchModel().evaluate(x, 8, space)['g']
    theirs = np.asarray(run_full('ride', x).g)
    moved = np.abs(theirs[1] - theirs[0]) > 0.01
    assert moved.any()
    assert np.all(np.sign(ours[1] - ours[0])[moved] == np.sign(theirs[1] - theirs[0])[moved])
    pitch = PitchPlaneModel().evaluate(x, 8, space)['g']
    np.testing.assert_array_equal(pitch[0], pitch[1])  # the pitch plane cannot see the bar


def test_ride_model_auto_takes_roll_and_pitch_only_for_a_variable_acting_in_roll():
    # config/simplified_models.yaml ride_model: auto.  The paper's 2 and 4 variables keep
    # the pitch-plane model (eqs. 15-24); the 8-variable ride preset has both bars
    assert load_simplified_config()['ride_model'] == 'auto'
    assert simplified.ride_model_kind(2) == 'pitch_plane'
    assert simplified.ride_model_kind(4) == 'pitch_plane'
    assert simplified.ride_model_kind(8) == 'roll_pitch'
    out = simplified.run_simplified('ride', RIDE8_REFERENCE, 8)
    np.testing.assert_allclose(out['g'], RollPitchModel().evaluate(RIDE8_REFERENCE, 8)['g'])


def test_an_unknown_ride_model_is_refused_naming_the_key(tmp_path):
    path = tmp_path / 'simplified_models.yaml'
    path.write_text('ride_model: full_car\n')
    with pytest.raises(ValueError, match=r'ride_model: unknown model .full_car.; valid: auto'):
        load_simplified_config(path)
