"""The 'mixed' scenario: rough road, then the double lane change, valves closed-loop.

The 4S4 is meant to switch itself between its ride state (soft spring, low damping)
and its handling state (stiff spring, high damping) "provided an intelligent control
system can distinguish between the two different operating conditions" (paper
section 3).  This scenario drives the full model over the Belgian paving and then
through the ISO 3888-1 double lane change at 65 km/h while a valve controller decides
the state every control period from the vehicle state; each commanded change takes
effect after the valve's 50-100 ms switching delay.

The controller is a callable, so the same run can be closed through ROS topics (the
valve_controller node, step-locked on simulated time) or in-process
(:class:`~suspension_tuning.vehicle.valve_logic.ValveController`); both see the same
sequence of states and give the same bits.

The design x sets the ride state's settings (the soft gas volume and the low-damping
dpsf, as in the 'ride' scenario); the handling state keeps its baseline settings
(config/strut_4s4.yaml).  Outputs: f = (f_ride on the paving + f_hand in the lane
change) / 2 with eqs. 9 and 10, g = eq. 11 over the whole run, and the valve events.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from suspension_tuning.paths import config_dir, read_yaml
from suspension_tuning.vehicle import comfort, design, metrics
from suspension_tuning.vehicle import road as road_mod
from suspension_tuning.vehicle.full_model import (
    FullVehicleModel,
    RoadInput,
    SuspensionSetting,
    ValveState,
    outputs_from_channels,
)
from suspension_tuning.vehicle.params import (
    VehicleParams,
    load_scenarios_config,
    load_vehicle_params,
)
from suspension_tuning.vehicle.road_files import FileRoadSpec
from suspension_tuning.vehicle.scenarios import (
    ScenarioResult,
    crossing_time,
    decimated_histories,
    handling_setup,
    ride_road_spec,
)
from suspension_tuning.vehicle.valve_logic import (
    DAMPING_HIGH,
    RIDE_STATE,
    SPRING_SOFT,
    ValveController,
    ValveControllerParams,
)

#: A valve controller: (control step, vehicle state dict) -> actual valve state
#: (front_spring, front_damping, rear_spring, rear_damping).
Controller = Callable[[int, dict[str, Any]], tuple[int, int, int, int]]


def load_mixed_config(path: str | Path | None = None) -> dict[str, Any]:
    """Read config/mixed.yaml."""
    return read_yaml(Path(path or config_dir() / 'mixed.yaml'))


def in_process_controllers(batch: int, params: ValveControllerParams | None = None
                           ) -> list[ValveController]:
    """One in-process valve controller per design (config/valve_controller.yaml)."""
    params = params or ValveControllerParams.from_yaml(config_dir() / 'valve_controller.yaml')
    return [ValveController(params) for _ in range(batch)]


def mixed_road(cfg: dict[str, Any], params: VehicleParams, lead_in_m: float,
               road: str | None = None) -> RoadInput:
    """Belgian paving faded out into a smooth road before the lane change.

    The paving occupies x in [-(lead_in + fade + rough), -(lead_in + fade)], the fade
    the next ``fade_out_m``, then the road is flat from x = -lead_in onwards (lane 1
    starts at x = 0).  ``road``: the rough road in place of the ride scenario's (a
    name, a file or an entry, :func:`~suspension_tuning.vehicle.road.resolve_road`); a
    road file is driven as it is, flat after its end.
    """
    ride = load_scenarios_config()['ride']
    if road:
        ride['road'] = road
    spec = ride_road_spec(ride)
    rough, fade = float(cfg['rough_length_m']), float(cfg['fade_out_m'])
    track_end = handling_setup(params, load_scenarios_config()['handling'])[0].x_end_m
    length = rough + fade + lead_in_m + track_end + float(cfg['run_out_m']) + 20.0
    if isinstance(spec, FileRoadSpec):
        profile = road_mod.synthesise_tracks(spec)
        dx = float(profile.x_m[1] - profile.x_m[0])
        x = np.arange(int(np.ceil(max(length, profile.length_m) / dx)) + 1) * dx
        profile = road_mod.RoadProfile(
            x_m=x, z_left_m=np.interp(x, profile.x_m, profile.z_left_m, right=0.0),
            z_right_m=np.interp(x, profile.x_m, profile.z_right_m, right=0.0))
    else:
        spec = replace(spec, length_m=max(length, spec.length_m))
        profile = road_mod.synthesise_tracks(spec)
    x = np.asarray(profile.x_m, dtype=float)
    window = np.clip((rough + fade - x) / fade, 0.0, 1.0)
    window = 0.5 - 0.5 * np.cos(np.pi * window)
    faded = road_mod.RoadProfile(x_m=x - (rough + fade + lead_in_m),
                                 z_left_m=profile.z_left_m * window,
                                 z_right_m=profile.z_right_m * window)
    return RoadInput.from_profile(faded, params.tyre.contact_length_m)


def vehicle_state(outputs: dict[str, np.ndarray], index: int, step: int,
                  period_s: float) -> dict[str, Any]:
    """The valve controller's inputs of design ``index`` (VehicleState fields)."""
    return {'step': step, 't_s': step * period_s,
            'speed_mps': float(outputs['speed_mps'][index]),
            'lateral_acceleration_mps2': float(outputs['lateral_accel_mps2'][index]),
            'roll_angle_rad': float(outputs['roll_rad'][index]),
            'roll_rate_radps': float(outputs['roll_rate_radps'][index]),
            'steering_angle_rad': float(outputs['steer_rad'][index]),
            'steering_rate_radps': float(outputs['steer_rate_radps'][index]),
            'strut_pressure_pa': tuple(float(p) for p in outputs['strut_pressure_pa'][index])}


def _diverged(outputs: dict[str, np.ndarray], x: np.ndarray, t_s: float
              ) -> ValueError | None:
    """The error of a run whose state is no longer finite (None while it is)."""
    batch = len(x)
    finite = np.all(np.isfinite(np.column_stack(
        [np.asarray(v, float).reshape(batch, -1) for v in outputs.values()])), axis=1)
    if finite.all():
        return None
    rows = ', '.join(f'{i} (x = {np.round(x[i], 4).tolist()})' for i in np.flatnonzero(~finite))
    return ValueError(f'the mixed run diverged at t = {t_s:.2f} s: the vehicle state of '
                      f'design {rows} is no longer finite (the strut gas pressure grows '
                      'without bound at the smallest gas volumes with the least damping)')


def run_mixed(x: np.ndarray, controllers: list[Controller] | None = None,
              params: VehicleParams | None = None, config: dict[str, Any] | None = None,
              valve_period_s: float | None = None,
              setting: SuspensionSetting | None = None,
              road: str | None = None,
              space: design.DesignSpace | None = None) -> ScenarioResult:
    """Simulate the mixed scenario with closed-loop valve control.

    Parameters
    ----------
    x : ndarray, shape (n_vars,) or (batch, n_vars)
        Normalised designs (eqs. 4-8) of the ride state's settings.
    controllers : list of callables, optional
        One per design: ``controller(step, state) -> actual valve state``; default
        in-process :class:`ValveController` objects.
    params : VehicleParams, optional
        Vehicle parameters (default config files).
    config : dict, optional
        Scenario configuration (default config/mixed.yaml).
    valve_period_s : float, optional
        Control period of the valves, s (default: the valve controller's, 5 ms).
    setting : SuspensionSetting, optional
        Both states' settings of every design, in place of x's ride state beside the
        baseline handling state (``vehicle.passive``: passive and switched settings);
        x is then only recorded.
    road : str, optional
        The rough road in place of the ride scenario's (:func:`mixed_road`).
    space : DesignSpace, optional
        The design space (default config/design_space.yaml).

    Returns
    -------
    ScenarioResult
        f (batch,), g (batch, 4), metrics (incl. valve switch counts), histories
        (incl. the actual valve state per history sample) and ``valve_events``.
    """
    params = params if params is not None else load_vehicle_params()
    cfg = config if config is not None else load_mixed_config()
    n_vars = int(np.shape(x)[-1]) if np.ndim(x) >= 1 else -1
    xv = design.validate_design(x, n_vars)
    batch = len(xv)
    if controllers is None:
        controllers = [c.update_from_state for c in in_process_controllers(batch)]
    if len(controllers) != batch:
        raise ValueError(f'need one valve controller per design ({batch}), '
                         f'got {len(controllers)}')
    period = valve_period_s or ValveControllerParams.from_yaml(
        config_dir() / 'valve_controller.yaml').control_period_s
    steps_per_period = int(round(period / params.dt_s))
    if abs(steps_per_period * params.dt_s - period) > 1e-12:
        raise ValueError(f'valve period {period} s is not a multiple of dt {params.dt_s} s')
    if setting is None:
        setting = SuspensionSetting.from_design(design.to_physical(xv, n_vars, space), 'ride',
                                             params)
    elif setting.batch_size != batch:
        raise ValueError(f'setting has {setting.batch_size} designs, x has {batch}')
    track, driver, speed_ctrl, _ = handling_setup(params, load_scenarios_config()['handling'])
    speed = float(cfg['speed_kmh']) / 3.6
    speed_ctrl = replace(speed_ctrl, target_speed_mps=speed)
    lead = float(cfg['lead_in_m'])
    start = -(float(cfg['rough_length_m']) + float(cfg['fade_out_m']) + lead)
    duration = (track.x_end_m + float(cfg['run_out_m']) - start) / speed
    model = FullVehicleModel(params, mixed_road(cfg, params, lead, road))
    model.reset(setting, ValveState.ride(batch), speed, x0_m=start + params.b_m,
                driver=driver, speed_controller=speed_ctrl)
    n_periods = int(round(duration / period))
    actual = np.tile(np.array(RIDE_STATE), (batch, 1))
    valve_log = np.empty((batch, 4, n_periods), dtype=np.int8)
    wall = time.perf_counter()
    for k in range(n_periods):
        outputs = model.outputs()
        try:
            new = np.array([controllers[i](k, vehicle_state(outputs, i, k, period))
                            for i in range(batch)])
        except ValueError as exc:
            raise _diverged(outputs, xv, k * period) or exc from exc
        if not np.array_equal(new, actual):
            model.set_valve_state(
                spring_soft=np.column_stack([new[:, 0] == SPRING_SOFT, new[:, 2] == SPRING_SOFT]),
                damping_high=np.column_stack([new[:, 1] == DAMPING_HIGH,
                                              new[:, 3] == DAMPING_HIGH]))
            actual = new
        valve_log[:, :, k] = actual
        model.step(steps_per_period)
    wall = time.perf_counter() - wall
    return _result(xv, model, track, cfg, valve_log, period, start, wall, duration)


def _result(xv, model, track, cfg, valve_log, period, start, wall, duration) -> ScenarioResult:
    rec = model.record()
    full = outputs_from_channels(rec.full, rec.hist[:, :, :0])
    tf = rec.t_full_s
    fs = 1.0 / rec.dt_s
    x_hist = outputs_from_channels(rec.full[..., :0], rec.hist)['x_m']
    x_full = np.array([np.interp(tf, rec.t_hist_s, xh) for xh in x_hist])
    rough_end = start + float(cfg['rough_length_m'])
    settle = float(cfg['settle_s'])
    # Ride part: W_b RMS on the paving after the settling time (eq. 9).
    on_paving = (tf[None, :] >= settle) & (x_full <= rough_end)
    acc_d = np.where(on_paving, comfort_filtered(full['acc_driver_mps2'], fs), 0.0)
    acc_p = np.where(on_paving, comfort_filtered(full['acc_passenger_mps2'], fs), 0.0)
    count = np.maximum(on_paving.sum(-1), 1)
    a_d = np.sqrt((acc_d ** 2).sum(-1) / count)
    a_p = np.sqrt((acc_p ** 2).sum(-1) / count)
    # Handling part: eq. 10 windows as in the handling scenario, from x crossings.
    x0_lc, x1_lc = track.first_lane_change_x_m
    t_lc = (crossing_time(x_full, tf, x0_lc), crossing_time(x_full, tf, x1_lc))
    t_man = (crossing_time(x_full, tf, 0.0), crossing_time(x_full, tf, track.x_end_m))
    roll_deg = np.degrees(full['roll_rad'])
    peak = metrics.first_peak(roll_deg, tf, t_lc)
    rate_rms = metrics.roll_rate_rms(np.degrees(full['roll_rate_radps']), tf, t_man)
    g = metrics.tyre_hop_constraints(full['tyre_fz_n'][..., tf >= settle], rec.dt_s)
    f = 0.5 * (np.asarray(metrics.f_ride(a_d, a_p)) + np.asarray(metrics.f_hand(rate_rms, peak)))
    switches = (np.diff(valve_log.astype(int), axis=-1) != 0).any(axis=1).sum(-1)
    handling_share = (valve_log[:, 0, :] != SPRING_SOFT).mean(-1)
    met = {'a_rms_driver_mps2': a_d, 'a_rms_passenger_mps2': a_p,
           'roll_first_peak_deg': peak, 'roll_rate_rms_deg_s': rate_rms,
           'valve_switches': switches.astype(float),
           'handling_state_fraction': handling_share,
           't_first_lane_change_s': np.stack(t_lc, axis=1),
           't_manoeuvre_s': np.stack(t_man, axis=1)}
    t_hist = rec.t_hist_s
    hists = decimated_histories(rec)
    idx = np.minimum((t_hist / period).astype(int), valve_log.shape[-1] - 1)
    hists['valve_state'] = valve_log[:, :, idx]
    result = ScenarioResult('mixed', xv, f, g, met, hists, wall, duration)
    result.valve_log = valve_log
    result.valve_period_s = period
    return result


def comfort_filtered(acc: np.ndarray, fs: float) -> np.ndarray:
    """W_b-weighted acceleration (BS 6841) along the last axis."""
    from scipy import signal

    return signal.sosfilt(comfort.wb_sos(fs), acc, axis=-1)
