"""Full-model scenarios of the paper: 'ride' (Belgian paving) and 'handling' (ISO 3888-1).

``run_scenario(name, x)`` simulates a batch of designs (normalised design vectors, paper
eqs. 4-8) and returns the objective f (eq. 9 or 10), the tyre-hop constraints g (eq. 11),
named metrics and decimated time histories.

- ride: straight run over the Belgian paving (config/road.yaml: a sett paving on the
  paper's ISO 8608 bed, G_d0 = 1e-4 m^3, w = 4) in the ride valve state (soft spring,
  low damping); the design sets the soft gas volume and the low-damping dpsf.  Metrics
  after ``settle_s``: BS 6841 W_b weighted RMS vertical acceleration at the driver and
  rear passenger seats (full integration rate, 500 Hz).
- handling: ISO 3888-1 double lane change at 65 km/h on a smooth road in the handling
  valve state (stiff spring, high damping); the design sets the stiff gas volume and the
  high-damping dpsf.  Preview steering driver (gains frozen in config/scenarios.yaml) and
  PI speed controller at 100 Hz.  Metrics: first roll peak in the first lane change
  (section 2 entry to section 3 exit) and RMS roll rate over the whole manoeuvre
  (lane 1 entry to section 6 exit).

Every run starts from the solved static equilibrium; the ride road is ramped in over its
first 5 m (config/road.yaml) and the first ``settle_s`` are discarded; the handling run
has a straight lead-in before lane 1.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from dataclasses import dataclass, field

import numpy as np

from . import _kernel as K  # noqa: N812
from . import comfort, design, manoeuvre, metrics
from . import road as road_mod
from .full_model import (
    FullVehicleModel,
    RoadInput,
    SimulationRecord,
    SuspensionSetting,
    ValveState,
    outputs_from_channels,
)
from .params import (
    VehicleParams,
    load_scenarios_config,
    load_vehicle_params,
    with_integrator,
)

SCENARIOS = ('ride', 'handling')


@dataclass
class ScenarioResult:
    """Result of one scenario for a batch of designs.

    Attributes
    ----------
    name : str
        Scenario name.
    x : np.ndarray
        Normalised designs (batch, n_vars).
    f : np.ndarray
        Objective (batch,): f_ride (eq. 9) or f_hand (eq. 10).
    g : np.ndarray
        Tyre-hop constraints (batch, 4) FL, FR, RL, RR (eq. 11), over the metric window.
    metrics : dict
        Named arrays (batch,) or (batch, 4).
    histories : dict
        Time histories at the decimated rate ('t_s' (m,), channels (batch, ..., m)).
    wall_time_s : float
        Wall-clock time of the simulation (excluding set-up) [s].
    simulated_time_s : float
        Simulated time per design [s].
    integrator : dict
        'method' ('fixed_step' or 'variable_step') and, for variable steps, 'stats'
        (``FullVehicleModel.integrator_stats``: step counts, step log).
    """

    name: str
    x: np.ndarray
    f: np.ndarray
    g: np.ndarray
    metrics: dict[str, np.ndarray]
    histories: dict[str, np.ndarray] = field(repr=False)
    wall_time_s: float
    simulated_time_s: float
    integrator: dict = field(default_factory=dict, repr=False)


#: Road beyond the rear axle's end position that a ride run needs, m: [E] the wheelbase
#: (2.794 m, Defender 110) and half a tyre contact patch, rounded up.
RIDE_ROAD_MARGIN_M = 5.0


def ride_road_spec(cfg: dict) -> road_mod.RoadSpec:
    """Road spec of the ride scenario: its road plus the overrides.

    ``cfg['road']`` names a road of config/road.yaml, a road file (.crg, .csv) or an
    entry of its own (:func:`~suspension_tuning.vehicle.road.resolve_road`).  A road
    file is checked against the run's length (start, speed x duration and
    :data:`RIDE_ROAD_MARGIN_M`): a shorter one is refused, or repeated when its entry
    says ``repeat: true`` (with a warning naming the period,
    :func:`~suspension_tuning.vehicle.road_files.fit_to_run`).
    """
    from .road_files import FileRoadSpec, fit_to_run

    spec = road_mod.resolve_road(cfg['road'])
    over = cfg.get('road_overrides') or {}
    spec = dataclasses.replace(spec, **over) if over else spec
    if isinstance(spec, FileRoadSpec):
        speed = float(cfg['speed_kmh']) / 3.6
        needed = (float(cfg['start_rear_axle_at_m']) + speed * float(cfg['duration_s'])
                  + RIDE_ROAD_MARGIN_M)
        spec = fit_to_run(spec, needed, speed, f"the ride run ({cfg['duration_s']:g} s at "
                                               f"{cfg['speed_kmh']:g} km/h)")
    return spec


@functools.lru_cache(maxsize=8)
def _ride_road(spec: road_mod.RoadSpec, contact_length_m: float) -> tuple[RoadInput, float]:
    prof = road_mod.synthesise_tracks(spec)
    return RoadInput.from_profile(prof, contact_length_m), prof.length_m


def _check_name(name: str) -> None:
    if name not in SCENARIOS:
        raise ValueError(f'unknown scenario {name!r}; valid scenarios: {", ".join(SCENARIOS)}')


def _settings(
    name: str, x: np.ndarray, n_vars: int | None, params: VehicleParams,
    space: design.DesignSpace | None = None,
) -> tuple[np.ndarray, SuspensionSetting]:
    if n_vars is None:
        n_vars = int(np.shape(x)[-1]) if np.ndim(x) >= 1 else -1
    xv = design.validate_design(x, n_vars)
    phys = design.to_physical(xv, n_vars, space)
    return xv, SuspensionSetting.from_design(phys, name, params)


def run_scenario(
    name: str,
    x: np.ndarray,
    params: VehicleParams | None = None,
    n_vars: int | None = None,
    config: dict | None = None,
    integrator: str | None = None,
    step_log_capacity: int = 0,
    space: design.DesignSpace | None = None,
) -> ScenarioResult:
    """Simulate a scenario for one or many designs.

    Parameters
    ----------
    name : {'ride', 'handling'}
        Scenario (every scenario, the closed-loop mixed one too:
        :func:`suspension_tuning.vehicle.runs.run_full`).
    x : np.ndarray
        Normalised design(s), shape (n_vars,) or (batch, n_vars), n_vars 2 or 4
        (paper eqs. 4-8; 0.001 <= x <= 1).
    params : VehicleParams, optional
        Vehicle parameters (default config/*.yaml).
    n_vars : int, optional
        Number of design variables (default: the length of x's last axis).
    config : dict, optional
        Scenario configuration (default config/scenarios.yaml).
    integrator : str, optional
        'fixed_step' (RK4) or 'variable_step' (Dormand-Prince 5(4) with error control);
        default ``params.integrator.method`` (config/vehicle.yaml: fixed_step).
    step_log_capacity : int
        Variable-step integrator: accepted steps logged per design (time, size) into
        ``result.integrator['stats']`` (0 = none).
    space : DesignSpace, optional
        The design space that turns x into physical settings (default
        config/design_space.yaml).

    Returns
    -------
    ScenarioResult
        f (batch,), g (batch, 4), metrics, histories, wall time.

    Raises
    ------
    ValueError
        Unknown scenario name, or a bad design vector (wrong length, NaN, out of bounds).
    """
    _check_name(name)
    params = with_integrator(params if params is not None else load_vehicle_params(), integrator)
    cfg = config if config is not None else load_scenarios_config()
    xv, setting = _settings(name, x, n_vars, params, space)
    if name == 'ride':
        return _run_ride(
            xv, setting, params, cfg['ride'], cfg['handling']['speed_controller'],
            step_log_capacity,
        )  # fmt: skip
    return _run_handling(xv, setting, params, cfg['handling'], step_log_capacity)


def _integrator_info(rec: SimulationRecord) -> dict:
    info = {'method': rec.extra.get('integrator', 'fixed_step')}
    if 'integrator_stats' in rec.extra:
        info['stats'] = rec.extra['integrator_stats']
    return info


def decimated_histories(rec: SimulationRecord) -> dict[str, np.ndarray]:
    """Named outputs at the history rate, (batch, ..., m), plus the times t_s (m,)."""
    out = outputs_from_channels(rec.full[:, :, :: rec.decimation], rec.hist)
    m = rec.hist.shape[2]
    out = {k: v[..., :m] for k, v in out.items()}
    out['roll_deg'] = np.degrees(out.pop('roll_rad'))
    out['roll_rate_deg_s'] = np.degrees(out.pop('roll_rate_radps'))
    out['t_s'] = rec.t_hist_s
    return out


def _run_ride(
    x: np.ndarray,
    setting: SuspensionSetting,
    params: VehicleParams,
    cfg: dict,
    sc_cfg: dict,
    step_log_capacity: int = 0,
) -> ScenarioResult:
    road, road_len = _ride_road(ride_road_spec(cfg), params.tyre.contact_length_m)
    speed = float(cfg['speed_kmh']) / 3.6
    duration = float(cfg['duration_s'])
    settle = float(cfg['settle_s'])
    x0 = float(cfg['start_rear_axle_at_m']) + params.b_m
    if x0 + params.a_m + speed * duration > road_len:
        raise ValueError(
            f'ride run ({speed * duration:.0f} m) is longer than the road ({road_len:.0f} m)'
        )
    batch = x.shape[0]
    sc = manoeuvre.SpeedController.from_yaml_dict(sc_cfg, speed)
    model = FullVehicleModel(params, road, step_log_capacity=step_log_capacity)
    model.reset(setting, ValveState.ride(batch), speed, x0_m=x0, speed_controller=sc)
    rec = model.simulate(duration)
    full = outputs_from_channels(rec.full, rec.hist[:, :, :0])
    f, g, met = ride_objective(full['acc_driver_mps2'], full['acc_passenger_mps2'],
                               full['tyre_fz_n'], rec.dt_s, settle, full['roll_rad'],
                               full['roll_rate_radps'])
    hist = decimated_histories(rec)
    met['strut_stroke_max_m'] = np.max(np.abs(hist['strut_stroke_m']), axis=-1)
    met['speed_mean_mps'] = np.mean(hist['speed_mps'], axis=-1)
    return ScenarioResult(
        'ride', x, f, g, met, hist, rec.wall_time_s, duration, _integrator_info(rec)
    )


def ride_objective(
    acc_driver_mps2: np.ndarray,
    acc_passenger_mps2: np.ndarray,
    tyre_fz_n: np.ndarray,
    dt_s: float,
    settle_s: float,
    roll_rad: np.ndarray | None = None,
    roll_rate_radps: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Ride objective (eq. 9), tyre-hop constraints (eq. 11) and metrics of a run.

    The same code serves every full model (the built-in one and an FMU's): BS 6841 W_b
    weighted RMS seat accelerations after ``settle_s``, and the constraints over the
    same window.

    Parameters
    ----------
    acc_driver_mps2, acc_passenger_mps2 : np.ndarray
        Seat vertical accelerations (batch, n) in m/s^2, sampled every ``dt_s`` from t = 0.
    tyre_fz_n : np.ndarray
        Tyre normal forces (batch, 4, n) in N, FL, FR, RL, RR.
    dt_s : float
        Sample interval in s.
    settle_s : float
        Initial time discarded from every metric, s.
    roll_rad, roll_rate_radps : np.ndarray, optional
        Body roll angle and rate (batch, n); their RMS metrics are left out without them.

    Returns
    -------
    (np.ndarray, np.ndarray, dict)
        f (batch,), g (batch, 4) and the named metrics.
    """
    fs = 1.0 / dt_s
    a_d = comfort.weighted_rms(acc_driver_mps2, fs, t_settle_s=settle_s)
    a_p = comfort.weighted_rms(acc_passenger_mps2, fs, t_settle_s=settle_s)
    keep = np.arange(np.shape(tyre_fz_n)[-1]) * dt_s >= settle_s
    fz = np.asarray(tyre_fz_n, dtype=float)[..., keep]
    g = metrics.tyre_hop_constraints(fz, dt_s)
    met = {'a_rms_driver_mps2': np.asarray(a_d), 'a_rms_passenger_mps2': np.asarray(a_p)}
    if roll_rad is not None:
        met['roll_rms_deg'] = metrics.rms(np.degrees(np.asarray(roll_rad)[..., keep]))
    if roll_rate_radps is not None:
        met['roll_rate_rms_deg_s'] = metrics.rms(
            np.degrees(np.asarray(roll_rate_radps)[..., keep]))
    met['tyre_lift_off_fraction'] = np.mean(fz <= metrics.FZ_CONTACT_THRESHOLD_N, axis=-1)
    return np.asarray(metrics.f_ride(a_d, a_p)), g, met


def handling_setup(
    params: VehicleParams, cfg: dict
) -> tuple[manoeuvre.DlcTrack, manoeuvre.PreviewDriver, manoeuvre.SpeedController, float]:
    """Build the ISO 3888-1 track, the frozen driver and the speed controller from config."""
    t = cfg['track']
    track = manoeuvre.dlc_cones(
        t['vehicle_width_m'], t['offset_m'], t['offset_is_centreline'], t['path_shape']
    )
    driver = manoeuvre.PreviewDriver.from_yaml_dict(cfg['driver'], track, params.wheelbase_m)
    speed = float(cfg['speed_kmh']) / 3.6
    sc = manoeuvre.SpeedController.from_yaml_dict(cfg['speed_controller'], speed)
    return track, driver, sc, speed


def dlc_controller(
    driver: manoeuvre.PreviewDriver, sc: manoeuvre.SpeedController, batch: int, period_s: float
):
    """Return a Python controller (preview steering + PI speed) for FullVehicleModel.

    Reference for the kernel's internal controllers (same algorithms, zero-order hold).
    """
    integral = np.zeros(batch)

    def ctrl(model: FullVehicleModel) -> tuple[np.ndarray, np.ndarray]:
        s = model._state
        u = s[:, K.I_U]
        steer = driver.steer(s[:, K.I_X], s[:, K.I_Y], s[:, K.I_PSI], u, s[:, K.I_R])
        force = sc.force(u, integral)
        integral[:] += sc.integral_rate(u, integral) * period_s
        return steer, force

    return ctrl


def crossing_time(x_hist: np.ndarray, t: np.ndarray, x_target: float) -> np.ndarray:
    """Time at which each design's x (batch, m) first reaches ``x_target`` (batch,), s."""
    return np.array([np.interp(x_target, np.maximum.accumulate(xh), t) for xh in x_hist])


def _run_handling(
    x: np.ndarray,
    setting: SuspensionSetting,
    params: VehicleParams,
    cfg: dict,
    step_log_capacity: int = 0,
) -> ScenarioResult:
    track, driver, sc, speed = handling_setup(params, cfg)
    lead, run_out = float(cfg['lead_in_m']), float(cfg['run_out_m'])
    duration = (lead + track.x_end_m + run_out) / speed
    batch = x.shape[0]
    model = FullVehicleModel(params, None, step_log_capacity=step_log_capacity)
    model.reset(
        setting, ValveState.handling(batch), speed, x0_m=-lead, driver=driver, speed_controller=sc
    )
    rec = model.simulate(duration)
    hist = decimated_histories(rec)
    th = hist['t_s']
    x0_lc, x1_lc = track.first_lane_change_x_m
    t_lc = (crossing_time(hist['x_m'], th, x0_lc), crossing_time(hist['x_m'], th, x1_lc))
    t_man = (crossing_time(hist['x_m'], th, 0.0), crossing_time(hist['x_m'], th, track.x_end_m))
    full = outputs_from_channels(rec.full, rec.hist[:, :, :0])
    f, g, shared = handling_objective(full['roll_rad'], full['roll_rate_radps'],
                                      full['tyre_fz_n'], rec.t_full_s, t_lc, t_man)
    on_track = (hist['x_m'] >= 0.0) & (hist['x_m'] <= track.x_end_m)
    path_err = hist['y_m'] - track.y_ref(np.clip(hist['x_m'], 0.0, track.x_end_m))
    hist['path_error_m'] = path_err
    tcfg = cfg['track']
    ref_front = params.a_m + 0.5 * (tcfg['vehicle_length_m'] - params.wheelbase_m)
    xs = np.where(on_track, hist['x_m'], np.nan)
    cone = np.array(
        [
            track.cone_violation(
                xs[b][on_track[b]],
                hist['y_m'][b][on_track[b]],
                hist['yaw_rad'][b][on_track[b]],
                tcfg['vehicle_width_m'],
                tcfg['vehicle_length_m'],
                ref_front,
            )
            for b in range(batch)
        ]
    )
    met = {
        'roll_first_peak_deg': shared['roll_first_peak_deg'],
        'roll_rate_rms_deg_s': shared['roll_rate_rms_deg_s'],
        'roll_max_deg': shared['roll_max_deg'],
        'lateral_accel_max_mps2': np.max(np.abs(hist['lateral_accel_mps2']), axis=-1),
        'path_error_max_m': np.max(np.abs(np.where(on_track, path_err, 0.0)), axis=-1),
        'cone_violation_m': cone,
        'steer_max_deg': np.degrees(np.max(np.abs(hist['steer_rad']), axis=-1)),
        'tyre_lift_off_fraction': shared['tyre_lift_off_fraction'],
        'speed_min_mps': np.min(hist['speed_mps'], axis=-1),
        't_first_lane_change_s': shared['t_first_lane_change_s'],
        't_manoeuvre_s': shared['t_manoeuvre_s'],
    }
    return ScenarioResult(
        'handling', x, f, g, met, hist, rec.wall_time_s, duration, _integrator_info(rec)
    )


def handling_objective(
    roll_rad: np.ndarray,
    roll_rate_radps: np.ndarray,
    tyre_fz_n: np.ndarray,
    t_s: np.ndarray,
    first_lane_change_s: tuple[np.ndarray, np.ndarray],
    manoeuvre_s: tuple[np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Handling objective (eq. 10), tyre-hop constraints (eq. 11) and metrics of a run.

    The same code serves every full model (the built-in one and an FMU's): the first
    roll peak in the first lane change, the RMS roll rate and the tyre lift-off over
    the whole manoeuvre.

    Parameters
    ----------
    roll_rad, roll_rate_radps : np.ndarray
        Body roll angle and rate (batch, n), rad and rad/s.
    tyre_fz_n : np.ndarray
        Tyre normal forces (batch, 4, n) in N, FL, FR, RL, RR.
    t_s : np.ndarray
        Uniform sample times (n,), s.
    first_lane_change_s, manoeuvre_s : (np.ndarray, np.ndarray)
        Start and end times (batch,) of the first lane change and of the manoeuvre, s.

    Returns
    -------
    (np.ndarray, np.ndarray, dict)
        f (batch,), g (batch, 4) and the named metrics.
    """
    tf = np.asarray(t_s, dtype=float)
    t_lc = tuple(np.asarray(t, dtype=float) for t in first_lane_change_s)
    t_man = tuple(np.asarray(t, dtype=float) for t in manoeuvre_s)
    roll_deg = np.degrees(roll_rad)
    peak = metrics.first_peak(roll_deg, tf, t_lc)
    rate_rms = metrics.roll_rate_rms(np.degrees(roll_rate_radps), tf, t_man)
    in_man = (tf[None, :] >= t_man[0][:, None]) & (tf[None, :] <= t_man[1][:, None])
    fz = np.asarray(tyre_fz_n, dtype=float)
    lift = np.where(in_man[:, None, :], fz <= metrics.FZ_CONTACT_THRESHOLD_N, False)
    frac = lift.sum(-1) / in_man.sum(-1)[:, None]
    g = 10.0 * (frac - 0.1)
    met = {
        'roll_first_peak_deg': peak,
        'roll_rate_rms_deg_s': rate_rms,
        'roll_max_deg': np.max(np.abs(roll_deg), axis=-1),
        'tyre_lift_off_fraction': frac,
        't_first_lane_change_s': np.stack(t_lc, axis=1),
        't_manoeuvre_s': np.stack(t_man, axis=1),
    }
    return np.asarray(metrics.f_hand(rate_rms, peak)), g, met


def simulate_timed(
    name: str, x: np.ndarray, params: VehicleParams | None = None
) -> tuple[ScenarioResult, float]:
    """Run a scenario and return it with the total wall time including set-up [s]."""
    t0 = time.perf_counter()
    res = run_scenario(name, x, params)
    return res, time.perf_counter() - t0
