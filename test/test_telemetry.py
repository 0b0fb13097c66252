"""Telemetry on the standard messages ROS tools plot (suspension_tuning.telemetry)."""

import numpy as np
import pytest

from suspension_tuning import evaluation
from suspension_tuning.telemetry import TOPICS, telemetry_messages


@pytest.fixture(scope='module')
def ride():
    """The ride run of the design-space centre (eqs. 6 and 8)."""
    return evaluation.evaluate('ride', np.array([[0.5, 0.5]])).result


def test_body_vertical_acceleration_is_the_second_derivative_of_heave():
    # On the paper-literal ISO 8608 road (long waves, config/road.yaml): the sett
    # paving's stone edges put content above what differences of a 250 Hz history
    # resolve.
    from suspension_tuning.vehicle.params import load_scenarios_config
    from suspension_tuning.vehicle.scenarios import run_scenario

    config = load_scenarios_config()
    config['ride'] = {**config['ride'], 'road': 'belgian_paving_paper_iso8608'}
    h = run_scenario('ride', np.array([[0.5, 0.5]]), config=config).histories
    t = h['t_s']
    dt = t[1] - t[0]
    az = h['vertical_accel_mps2'][0]
    zdd = np.gradient(np.gradient(h['heave_m'][0], dt), dt)
    keep = t > 3.0
    rms = np.sqrt(np.mean(az[keep] ** 2))
    assert rms > 0.05  # a rough road shakes the body: far from zero
    # Central differences of the 250 Hz history, O(dt^2): within 2 % of the signal.
    assert np.sqrt(np.mean((az - zdd)[keep] ** 2)) < 0.02 * rms
    theta_dot = np.gradient(h['pitch_rad'][0], dt)
    assert np.sqrt(np.mean((theta_dot - h['pitch_rate_radps'][0])[keep] ** 2)) < 0.02 * (
        np.sqrt(np.mean(theta_dot[keep] ** 2)))


def test_imu_and_seat_messages_carry_the_accelerations_of_the_run(ride):
    h = ride.histories
    messages = telemetry_messages(h, 0, decimation=2)
    assert set(messages) == set(TOPICS)
    t = h['t_s'][::2]
    assert all(len(m) == len(t) for m in messages.values())
    imu = messages['imu']
    np.testing.assert_array_equal([m.linear_acceleration.z for m in imu],
                                  h['vertical_accel_mps2'][0, ::2])
    np.testing.assert_array_equal([m.linear_acceleration.y for m in imu],
                                  h['lateral_accel_mps2'][0, ::2])
    # sensor_msgs/Imu: -1 in element 0 marks a quantity not provided; all three are.
    assert all(m.linear_acceleration_covariance[0] == 0.0
               and m.orientation_covariance[0] == 0.0
               and m.angular_velocity_covariance[0] == 0.0 for m in imu)
    driver = messages['seat/driver']
    assert {m.header.frame_id for m in driver} == {'driver_seat'}
    assert {m.header.frame_id for m in messages['seat/passenger_wb']} == {'passenger_seat'}
    np.testing.assert_array_equal([m.accel.linear.z for m in driver],
                                  h['acc_driver_mps2'][0, ::2])
    # The W_b-weighted seat signal is eq. 9's: its RMS after the settling time equals
    # the metric (weighted at 500 Hz) within 1 % (the same filter at 250 Hz).
    settle = t > 3.0  # config/scenarios.yaml ride settle_s
    for seat in ('driver', 'passenger'):
        weighted = np.array([m.accel.linear.z for m in messages[f'seat/{seat}_wb']])
        rms = np.sqrt(np.mean(weighted[settle] ** 2))
        assert rms == pytest.approx(float(ride.metrics[f'a_rms_{seat}_mps2'][0]), rel=0.01)
    struts = messages['struts'][0]
    assert struts.name == ['strut_front_left', 'strut_front_right', 'strut_rear_left',
                           'strut_rear_right']
    assert messages['tyres'][0].name[0] == 'tyre_front_left'
