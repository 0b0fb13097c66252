"""Telemetry messages of a full-model run, on the standard types ROS tools plot (no rclpy).

:func:`telemetry_messages` turns the decimated time histories of one design
(:func:`suspension_tuning.vehicle.scenarios.decimated_histories`) into messages per
topic, stamped with simulated time.  Topic names are relative to the simulation
node (``~/telemetry/<name>``):

=====================  ==============================  ======================================
name                   type                            content
=====================  ==============================  ======================================
``imu``                sensor_msgs/Imu                 body at its centre of mass, frame
                                                       ``base_link`` (x forward, y left, z up):
                                                       orientation (roll, pitch, yaw),
                                                       angular velocity (roll, pitch, yaw
                                                       rate, rad/s), linear acceleration
                                                       (longitudinal, lateral, vertical, m/s^2,
                                                       gravity removed)
``attitude``           geometry_msgs/Vector3Stamped    the body's roll (x), pitch (y) and
                                                       yaw (z) angles, rad, frame
                                                       ``base_link``: the Imu's orientation
                                                       as angles a plot shows directly
``seat/driver``        geometry_msgs/AccelStamped      driver's seat vertical acceleration,
                                                       unweighted, m/s^2 (frame
                                                       ``driver_seat``, ``accel.linear.z``)
``seat/passenger``     geometry_msgs/AccelStamped      the same at the rear passenger's seat
                                                       (frame ``passenger_seat``)
``seat/driver_wb``     geometry_msgs/AccelStamped      driver's seat, BS 6841 W_b weighted
                                                       (the signal of eq. 9), m/s^2
``seat/passenger_wb``  geometry_msgs/AccelStamped      passenger's seat, W_b weighted
``struts``             sensor_msgs/JointState          per strut (``strut_front_left``, ...):
                                                       position = stroke m (compression
                                                       positive), effort = force N
``tyres``              sensor_msgs/JointState          per tyre (``tyre_front_left``, ...):
                                                       position = slip angle rad, effort =
                                                       normal force N
``steering``           sensor_msgs/JointState          ``front_road_wheel``: position = angle
                                                       rad, velocity = rate rad/s
=====================  ==============================  ======================================

Every quantity the Imu carries is provided, so its covariances are zero ("unknown",
sensor_msgs/Imu); a simulation has no sensor noise to state.  The accelerations are
kinematic (gravity removed), the ride-comfort convention of BS 6841 and ISO 2631, not
an accelerometer's specific force.  The W_b weighting runs from rest at the history
rate (250 Hz, config/vehicle.yaml), as :func:`~suspension_tuning.vehicle.comfort.weighted`
does at 500 Hz for eq. 9: its first second or so is the filter settling.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import AccelStamped, Vector3Stamped
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Header

from suspension_tuning.vehicle import comfort

CORNERS = ('front_left', 'front_right', 'rear_left', 'rear_right')
STRUTS = [f'strut_{corner}' for corner in CORNERS]
TYRES = [f'tyre_{corner}' for corner in CORNERS]
SEATS = {'driver': 'acc_driver_mps2', 'passenger': 'acc_passenger_mps2'}
#: Topic names (under ``~/telemetry/``) and their message types.
TOPICS: dict[str, type] = {
    'imu': Imu,
    'attitude': Vector3Stamped,
    **{f'seat/{seat}{suffix}': AccelStamped for seat in SEATS for suffix in ('', '_wb')},
    'struts': JointState, 'tyres': JointState, 'steering': JointState,
}


def stamp(t_s: float) -> Time:
    """builtin_interfaces/Time of simulated time ``t_s`` (s)."""
    sec = math.floor(t_s)
    return Time(sec=int(sec), nanosec=int(round((t_s - sec) * 1e9)) % 1_000_000_000)


def quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of body Euler angles roll-pitch-yaw (rad, ZYX convention)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def telemetry_messages(histories: Mapping[str, np.ndarray], index: int = 0,
                       decimation: int = 1) -> dict[str, list]:
    """Messages per telemetry topic for design ``index`` of a run's histories.

    Parameters
    ----------
    histories : mapping
        Decimated histories (``t_s`` (m,) and channels (batch, ..., m)), as in
        :class:`~suspension_tuning.vehicle.scenarios.ScenarioResult`.
    index : int
        Design of the batch.
    decimation : int
        Publish every ``decimation``-th history sample (the W_b weighting runs on all).

    Returns
    -------
    dict
        Topic name (see the module docstring) -> messages in time order.
    """
    t_s = np.asarray(histories['t_s'], dtype=float)
    h = {name: np.asarray(value)[index] for name, value in histories.items() if name != 't_s'}
    fs_hz = 1.0 / float(t_s[1] - t_s[0]) if len(t_s) > 1 else 0.0
    seats = {seat: np.asarray(h[channel], dtype=float) for seat, channel in SEATS.items()}
    if len(t_s) > 1:
        seats.update({f'{seat}_wb': comfort.weighted(acc, fs_hz) for seat, acc in
                      list(seats.items())})
    else:  # one sample: nothing to filter
        seats.update({f'{seat}_wb': np.zeros_like(acc) for seat, acc in list(seats.items())})
    out: dict[str, list] = {name: [] for name in TOPICS}
    for k in range(0, len(t_s), max(1, int(decimation))):
        now = stamp(float(t_s[k]))
        imu = Imu(header=Header(stamp=now, frame_id='base_link'))
        (imu.orientation.x, imu.orientation.y, imu.orientation.z,
         imu.orientation.w) = quaternion(math.radians(h['roll_deg'][k]),
                                         float(h['pitch_rad'][k]), float(h['yaw_rad'][k]))
        imu.angular_velocity.x = math.radians(h['roll_rate_deg_s'][k])
        imu.angular_velocity.y = float(h['pitch_rate_radps'][k])
        imu.angular_velocity.z = float(h['yaw_rate_radps'][k])
        imu.linear_acceleration.x = float(h['longitudinal_accel_mps2'][k])
        imu.linear_acceleration.y = float(h['lateral_accel_mps2'][k])
        imu.linear_acceleration.z = float(h['vertical_accel_mps2'][k])
        out['imu'].append(imu)
        attitude = Vector3Stamped(header=Header(stamp=now, frame_id='base_link'))
        attitude.vector.x = math.radians(h['roll_deg'][k])
        attitude.vector.y = float(h['pitch_rad'][k])
        attitude.vector.z = float(h['yaw_rad'][k])
        out['attitude'].append(attitude)
        for seat, acc in seats.items():
            message = AccelStamped(header=Header(
                stamp=now, frame_id=f'{seat.removesuffix("_wb")}_seat'))
            message.accel.linear.z = float(acc[k])
            out[f'seat/{seat}'].append(message)
        body = Header(stamp=now, frame_id='base_link')
        out['struts'].append(JointState(header=body, name=STRUTS,
                                        position=h['strut_stroke_m'][:, k].tolist(),
                                        effort=h['strut_force_n'][:, k].tolist()))
        out['tyres'].append(JointState(header=body, name=TYRES,
                                       position=h['slip_angle_rad'][:, k].tolist(),
                                       effort=h['tyre_fz_n'][:, k].tolist()))
        out['steering'].append(JointState(header=body, name=['front_road_wheel'],
                                          position=[float(h['steer_rad'][k])],
                                          velocity=[float(h['steer_rate_radps'][k])]))
    return out
