"""Parameters of the Defender 110 full-vehicle model, loaded from config/*.yaml.

All values are SI.  The YAML files carry the unit and source of every number; this module
only converts (litres -> m^3, diameter -> area) and derives quantities that follow from
the sourced ones (sprung mass, static loads).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from suspension_tuning.paths import config_dir, read_yaml

CONFIG_DIR = config_dir()
LITRE_M3 = 1.0e-3


@dataclass(frozen=True)
class StrutParams:
    """4S4 strut parameters (config/strut_4s4.yaml)."""

    piston_area_m2: float
    polytropic_exponent: float
    atmospheric_pressure_pa: float
    min_volume_fraction: float
    damper_velocity_mps: np.ndarray
    damper_force_n: np.ndarray
    bump_clearance_m: float
    bump_stiffness_n_per_m: float
    bump_cubic_n_per_m3: float
    bump_smoothing_m: float
    rebound_clearance_m: float
    rebound_stiffness_n_per_m: float
    rebound_cubic_n_per_m3: float
    rebound_smoothing_m: float
    gas_volume_soft_m3: float
    gas_volume_stiff_m3: float
    dpsf_low: float
    dpsf_high: float

    @classmethod
    def from_yaml_dict(cls, d: dict[str, Any]) -> StrutParams:
        """Build from the parsed config/strut_4s4.yaml mapping."""
        gas, bump, reb = d['gas'], d['bump_stop'], d['rebound_stop']
        base, tab = d['baseline_setting'], d['damper_table']
        v = np.asarray(tab['velocity_mps'], dtype=float)
        f = np.asarray(tab['force_n'], dtype=float)
        if v.shape != f.shape or v.size < 3 or np.any(np.diff(v) <= 0):
            raise ValueError('damper_table: velocity_mps must be increasing, same length as force')
        return cls(
            piston_area_m2=float(np.pi / 4.0 * gas['piston_diameter_m'] ** 2),
            polytropic_exponent=float(gas['polytropic_exponent']),
            atmospheric_pressure_pa=float(gas['atmospheric_pressure_pa']),
            min_volume_fraction=float(gas['min_volume_fraction']),
            damper_velocity_mps=v,
            damper_force_n=f,
            bump_clearance_m=float(bump['clearance_m']),
            bump_stiffness_n_per_m=float(bump['stiffness_n_per_m']),
            bump_cubic_n_per_m3=float(bump['cubic_stiffness_n_per_m3']),
            bump_smoothing_m=float(bump['smoothing_m']),
            rebound_clearance_m=float(reb['clearance_m']),
            rebound_stiffness_n_per_m=float(reb['stiffness_n_per_m']),
            rebound_cubic_n_per_m3=float(reb['cubic_stiffness_n_per_m3']),
            rebound_smoothing_m=float(reb['smoothing_m']),
            gas_volume_soft_m3=float(base['gas_volume_soft_l']) * LITRE_M3,
            gas_volume_stiff_m3=float(base['gas_volume_stiff_l']) * LITRE_M3,
            dpsf_low=float(base['dpsf_low']),
            dpsf_high=float(base['dpsf_high']),
        )


PACEJKA_KEYS = tuple(f'a{i}' for i in range(14))

#: Integrators of the full model: the fixed-step RK4 kernel (default) and the
#: error-controlled Dormand-Prince 5(4) pair of a multibody code.
INTEGRATORS = ('fixed_step', 'variable_step')
#: Embedded Runge-Kutta pairs of the variable-step integrator.
RK_PAIRS = ('dopri5', 'bs32')
#: How the variable-step integrator evaluates the driver and the speed controller.
CONTROLLER_MODES = ('continuous', 'sampled')


@dataclass(frozen=True)
class IntegratorSettings:
    """How the full model is integrated (config/vehicle.yaml ``integration``).

    Attributes
    ----------
    method : str
        'fixed_step' (classical RK4, ``dt_s``) or 'variable_step' (an embedded
        Runge-Kutta pair with step-size control and dense output onto the ``dt_s`` grid).
    pair : str
        'dopri5' (Dormand-Prince 5(4)) or 'bs32' (Bogacki-Shampine 3(2)).
    controllers : str
        Variable step only: 'continuous' (driver and speed controller evaluated at every
        stage, as control elements of a multibody model) or 'sampled' (zero-order hold
        at ``control_period_s`` as in the fixed-step kernel; the integrator stops at
        every sample).
    rtol, atol : float
        Relative and absolute local error tolerances of the variable-step integrator
        (SI units of each state: m, rad, m/s, rad/s).
    initial_step_s, min_step_s, max_step_s : float
        First proposed step, the step below which a run fails, the largest step [s].
    safety, fac_min, fac_max, beta : float
        Step-size controller: safety factor, smallest and largest step ratio, PI
        stabilisation exponent (Hairer-Norsett-Wanner IV.2).
    """

    method: str
    pair: str
    controllers: str
    rtol: float
    atol: float
    initial_step_s: float
    min_step_s: float
    max_step_s: float
    safety: float
    fac_min: float
    fac_max: float
    beta: float

    def __post_init__(self) -> None:
        """Validate (ValueError naming the setting)."""
        if self.method not in INTEGRATORS:
            raise ValueError(f'unknown integrator {self.method!r}; '
                             f'valid: {", ".join(INTEGRATORS)}')
        if self.controllers not in CONTROLLER_MODES:
            raise ValueError(f'unknown controller mode {self.controllers!r}; '
                             f'valid: {", ".join(CONTROLLER_MODES)}')
        if self.pair not in RK_PAIRS:
            raise ValueError(f'unknown Runge-Kutta pair {self.pair!r}; '
                             f'valid: {", ".join(RK_PAIRS)}')
        for name in ('rtol', 'atol', 'initial_step_s', 'min_step_s', 'max_step_s', 'safety'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f'integration.{name} must be positive and finite, got {value}')
        if not self.min_step_s <= self.initial_step_s <= self.max_step_s:
            raise ValueError('integration: need min_step_s <= initial_step_s <= max_step_s')
        if not (0.0 < self.fac_min < 1.0 < self.fac_max and 0.0 <= self.beta < 0.2):
            raise ValueError('integration: need 0 < fac_min < 1 < fac_max and 0 <= beta < 0.2')

    @classmethod
    def from_yaml_dict(cls, d: dict[str, Any]) -> IntegratorSettings:
        """Build from the ``integration`` mapping of config/vehicle.yaml."""
        v = d['variable_step']
        return cls(
            method=str(d['method']),
            pair=str(v['pair']),
            controllers=str(v['controllers']),
            rtol=float(v['rtol']),
            atol=float(v['atol']),
            initial_step_s=float(v['initial_step_s']),
            min_step_s=float(v['min_step_s']),
            max_step_s=float(v['max_step_s']),
            safety=float(v['safety']),
            fac_min=float(v['fac_min']),
            fac_max=float(v['fac_max']),
            beta=float(v['beta']),
        )


@dataclass(frozen=True)
class TyreParams:
    """Tyre parameters (config/tyre.yaml)."""

    unloaded_radius_m: float
    vertical_stiffness_n_per_m: float
    vertical_damping_ns_per_m: float
    contact_length_m: float
    pacejka: np.ndarray  # (14,) effective a0..a13 after the documented scalings

    @classmethod
    def from_yaml_dict(cls, d: dict[str, Any]) -> TyreParams:
        """Build from the parsed config/tyre.yaml mapping (applies the coefficient scales)."""
        pj = d['pacejka89']
        a = np.array([float(pj[k]) for k in PACEJKA_KEYS])
        a = scale_pacejka(
            a, pj.get('bcd_scale', 1.0), pj.get('d_scale', 1.0), pj.get('shift_scale', 1.0)
        )
        return cls(
            unloaded_radius_m=float(d['unloaded_radius_m']),
            vertical_stiffness_n_per_m=float(d['vertical_stiffness_n_per_m']),
            vertical_damping_ns_per_m=float(d['vertical_damping_ns_per_m']),
            contact_length_m=float(d['contact_length_m']),
            pacejka=a,
        )


def scale_pacejka(
    a: np.ndarray, bcd_scale: float = 1.0, d_scale: float = 1.0, shift_scale: float = 1.0
) -> np.ndarray:
    """Scale Pacejka '89 coefficients a0..a13.

    Parameters
    ----------
    a : np.ndarray
        Coefficients a0..a13 (Fz in kN, alpha in deg, Fy in N).
    bcd_scale : float
        Factor on a3 (cornering stiffness BCD).
    d_scale : float
        Factor on a1, a2 (peak force D, i.e. friction).
    shift_scale : float
        Factor on the shifts a8..a13 (Sh, Sv).

    Returns
    -------
    np.ndarray
        Scaled copy.
    """
    a = np.array(a, dtype=float).copy()
    a[1] *= d_scale
    a[2] *= d_scale
    a[3] *= bcd_scale
    a[8:14] *= shift_scale
    return a


@dataclass(frozen=True)
class VehicleParams:
    """Full-vehicle parameters (config/vehicle.yaml + strut + tyre)."""

    g_mps2: float
    wheelbase_m: float
    a_m: float  # sprung cg to front axle
    b_m: float  # sprung cg to rear axle
    cg_height_m: float
    track_m: float
    strut_track_m: float
    body_width_m: float
    body_length_m: float
    roll_centre_front_m: float
    roll_centre_rear_m: float
    axle_height_m: float
    mass_total_kg: float
    mass_axle_front_kg: float
    mass_axle_rear_kg: float
    mass_sprung_kg: float
    mass_wheel_kg: float
    i_roll_sprung_kgm2: float
    i_pitch_sprung_kgm2: float
    i_yaw_total_kgm2: float
    i_roll_axle_front_kgm2: float
    i_roll_axle_rear_kgm2: float
    torsion_stiffness_nm_per_rad: float
    torsion_damping_nms_per_rad: float
    front_half_cg_x_m: float
    arb_front_nm_per_rad: float
    arb_rear_nm_per_rad: float
    driver_x_m: float  # ahead of the sprung cg (negative = behind)
    driver_y_m: float
    passenger_x_m: float
    passenger_y_m: float
    steer_time_constant_s: float
    steer_max_rad: float
    rolling_resistance_coeff: float
    dt_s: float
    control_period_s: float
    history_decimation: int
    strut: StrutParams
    tyre: TyreParams
    integrator: IntegratorSettings
    source_files: tuple[str, ...] = field(default=())

    # ---- derived quantities -------------------------------------------------------------
    @property
    def mass_front_half_kg(self) -> float:
        """Sprung mass of the front body half [kg] (static front share b/L) [D]."""
        return self.mass_sprung_kg * self.b_m / self.wheelbase_m

    @property
    def mass_rear_half_kg(self) -> float:
        """Sprung mass of the rear body half [kg] [D]."""
        return self.mass_sprung_kg * self.a_m / self.wheelbase_m

    @property
    def rear_half_cg_x_m(self) -> float:
        """Rear half cg x [m] so that the halves' first moment about the cg is zero [D]."""
        return -self.mass_front_half_kg * self.front_half_cg_x_m / self.mass_rear_half_kg

    @property
    def static_strut_load_front_n(self) -> float:
        """Static load of one front strut [N] (sprung weight share, motion ratio 1) [D]."""
        return self.mass_sprung_kg * self.g_mps2 * self.b_m / self.wheelbase_m / 2.0

    @property
    def static_strut_load_rear_n(self) -> float:
        """Static load of one rear strut [N] [D]."""
        return self.mass_sprung_kg * self.g_mps2 * self.a_m / self.wheelbase_m / 2.0

    @property
    def static_tyre_load_front_n(self) -> float:
        """Static vertical load of one front tyre [N] [D]."""
        return self.static_strut_load_front_n + self.mass_axle_front_kg * self.g_mps2 / 2.0

    @property
    def static_tyre_load_rear_n(self) -> float:
        """Static vertical load of one rear tyre [N] [D]."""
        return self.static_strut_load_rear_n + self.mass_axle_rear_kg * self.g_mps2 / 2.0

    @property
    def h_roll_front_m(self) -> float:
        """Height of the sprung cg above the front roll centre [m] [D]."""
        return self.cg_height_m - self.roll_centre_front_m

    @property
    def h_roll_rear_m(self) -> float:
        """Height of the sprung cg above the rear roll centre [m] [D]."""
        return self.cg_height_m - self.roll_centre_rear_m


def load_vehicle_params(
    path: str | Path | None = None,
    strut_path: str | Path | None = None,
    tyre_path: str | Path | None = None,
) -> VehicleParams:
    """Load the full-vehicle parameters.

    Parameters
    ----------
    path : str or Path, optional
        config/vehicle.yaml (default: the repository's config directory).
    strut_path, tyre_path : str or Path, optional
        config/strut_4s4.yaml and config/tyre.yaml.

    Returns
    -------
    VehicleParams
        Frozen dataclass of SI values.
    """
    path = Path(path) if path is not None else CONFIG_DIR / 'vehicle.yaml'
    strut_path = Path(strut_path) if strut_path is not None else path.parent / 'strut_4s4.yaml'
    tyre_path = Path(tyre_path) if tyre_path is not None else path.parent / 'tyre.yaml'
    d = read_yaml(path)
    strut = StrutParams.from_yaml_dict(read_yaml(strut_path))
    tyre = TyreParams.from_yaml_dict(read_yaml(tyre_path))
    geo, mass, inert = d['geometry'], d['mass'], d['inertia']
    tor, arb, seats = d['body_torsion'], d['anti_roll_bar'], d['seats']
    steer, lon, integ = d['steering'], d['longitudinal'], d['integration']
    wb = float(geo['wheelbase_m'])
    a = float(geo['cg_to_front_axle_m'])
    m_tot = float(mass['total_kg'])
    m_af, m_ar = float(mass['front_axle_kg']), float(mass['rear_axle_kg'])
    p = VehicleParams(
        g_mps2=float(d['gravity_mps2']),
        wheelbase_m=wb,
        a_m=a,
        b_m=wb - a,
        cg_height_m=float(geo['cg_height_m']),
        track_m=float(geo['track_m']),
        strut_track_m=float(geo['strut_track_m']),
        body_width_m=float(geo['body_width_m']),
        body_length_m=float(geo['body_length_m']),
        roll_centre_front_m=float(geo['roll_centre_height_front_m']),
        roll_centre_rear_m=float(geo['roll_centre_height_rear_m']),
        axle_height_m=float(geo['axle_height_m']),
        mass_total_kg=m_tot,
        mass_axle_front_kg=m_af,
        mass_axle_rear_kg=m_ar,
        mass_sprung_kg=m_tot - m_af - m_ar,
        mass_wheel_kg=float(mass['wheel_and_tyre_kg']),
        i_roll_sprung_kgm2=float(inert['roll_sprung_kgm2']),
        i_pitch_sprung_kgm2=float(inert['pitch_sprung_kgm2']),
        i_yaw_total_kgm2=float(inert['yaw_total_kgm2']),
        i_roll_axle_front_kgm2=float(inert['axle_roll_front_kgm2']),
        i_roll_axle_rear_kgm2=float(inert['axle_roll_rear_kgm2']),
        torsion_stiffness_nm_per_rad=float(tor['torsional_stiffness_nm_per_rad']),
        torsion_damping_nms_per_rad=float(tor['torsional_damping_nms_per_rad']),
        front_half_cg_x_m=float(tor['front_half_cg_ahead_of_cg_m']),
        arb_front_nm_per_rad=float(arb['front_stiffness_nm_per_rad']),
        arb_rear_nm_per_rad=float(arb['rear_stiffness_nm_per_rad']),
        driver_x_m=a - float(seats['driver_behind_front_axle_m']),
        driver_y_m=float(seats['driver_lateral_m']),
        passenger_x_m=a - float(seats['passenger_behind_front_axle_m']),
        passenger_y_m=float(seats['passenger_lateral_m']),
        steer_time_constant_s=float(steer['actuator_time_constant_s']),
        steer_max_rad=float(steer['max_road_wheel_angle_rad']),
        rolling_resistance_coeff=float(lon['rolling_resistance_coeff']),
        dt_s=float(integ['time_step_s']),
        control_period_s=float(integ['control_period_s']),
        history_decimation=int(integ['history_decimation']),
        strut=strut,
        tyre=tyre,
        integrator=IntegratorSettings.from_yaml_dict(integ),
        source_files=(str(path), str(strut_path), str(tyre_path)),
    )
    if not 0.0 < p.a_m < p.wheelbase_m:
        raise ValueError('cg_to_front_axle_m must lie between the axles')
    ratio = p.control_period_s / p.dt_s
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ValueError('control_period_s must be an integer multiple of time_step_s')
    return p


def with_integrator(
    params: VehicleParams, method: str | None = None, **settings: float
) -> VehicleParams:
    """Return ``params`` with another integrator and/or integrator settings.

    Parameters
    ----------
    params : VehicleParams
        Parameters.
    method : str, optional
        'fixed_step' or 'variable_step' (None: keep).
    **settings : float
        Fields of :class:`IntegratorSettings` to change (e.g. ``rtol=1e-6``).
    """
    changes = dict(settings)
    if method is not None:
        changes['method'] = method
    if not changes:
        return params
    return replace(params, integrator=replace(params.integrator, **changes))


def load_scenarios_config(path: str | Path | None = None) -> dict[str, Any]:
    """Load config/scenarios.yaml as a plain mapping (units in the key names)."""
    path = Path(path) if path is not None else CONFIG_DIR / 'scenarios.yaml'
    return read_yaml(path)


def integrator_name(integrator: str | None) -> str:
    """The integrator a run uses: the given one or config/vehicle.yaml's default."""
    if integrator is not None:
        return integrator
    return load_vehicle_params().integrator.method
