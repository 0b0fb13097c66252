"""Pitch-plane ride model of Thoresson et al. (2009) Part 1, section 6.2 (eqs. 15-24).

Four degrees of freedom: body heave ``z_s`` and pitch ``theta`` (nose down positive), front
and rear axle heave ``z_af``, ``z_ar``; all vertical positions up positive and measured
from static equilibrium on a flat road.  Each axle carries two 4S4 struts
(``strut.strut_force``, the full model's strut) and two point-follower tyres that lose
contact (eq. 19, ``tyre.vertical_force``).  The road is the left/right average of the
tracks that the full model's wheels see (``full_model.RoadInput``: the same seeded road,
enveloped over the tyre contact length) [P s.6.2]; the vehicle runs at the scenario's
constant speed.

Sign conventions differ from the paper's eqs. 15-22 (which mix z-down for the body and
z-up for the axles); the equations are the same:

* strut stroke (compression positive) ``x_f = z_af - (z_s - a theta)``,
  ``x_r = z_ar - (z_s + b theta)`` (eqs. 17-18);
* ``m_b z_s'' = 2 f_f + 2 f_r - m_b g`` (eq. 20),
  ``I_y theta'' = -2 a f_f + 2 b f_r`` (eq. 21),
  ``m_tf z_af'' = 2 F_tf - 2 f_f - m_tf g`` (eq. 15, likewise eq. 16),
  with the strut force including its static load and the tyre force
  ``F_t = max(0, k_t d + c_t d')`` while the deflection ``d = delta_stat + z_road - z_a``
  is positive (eq. 19).

The objective (eq. 9) and tyre-hop constraints (eq. 11) are computed exactly as for the
full model (``comfort.weighted_rms``, ``metrics.f_ride``, ``metrics.tyre_hop_constraints``);
the pitch-plane front (rear) tyre supplies the constraints of both front (rear) tyres, in
the full model's corner order FL, FR, RL, RR.

Integration: fixed-step RK4 compiled with numba (``_simplified_kernel``), vectorised over
a leading design axis; :func:`derivative_numpy` is the plain numpy reference of the same
equations built on the shared strut and tyre functions.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from suspension_tuning.paths import read_yaml

from . import _simplified_kernel as SK  # noqa: N812
from . import strut as strut_mod
from .comfort import weighted_rms
from .design import AxleSettings, DesignSpace, to_physical, validate_design
from .full_model import RoadInput
from .metrics import f_ride, soft_tyre_hop_constraints, tyre_hop_constraints
from .params import CONFIG_DIR, VehicleParams, load_scenarios_config, load_vehicle_params
from .road import RoadProfile, RoadSpec, synthesise_tracks
from .scenarios import ride_road_spec
from .tyre import vertical_force

SIMPLIFIED_CONFIG_PATH = CONFIG_DIR / 'simplified_models.yaml'
KMH = 1.0 / 3.6  # [m/s per km/h]


#: Values of config/simplified_models.yaml ``ride_model``.
RIDE_MODELS = ('auto', 'pitch_plane', 'roll_pitch')


def load_simplified_config(path: str | Path | None = None) -> dict[str, Any]:
    """Load config/simplified_models.yaml as a plain mapping (units in the key names).

    Raises ValueError naming the key when ``ride_model`` is not one of RIDE_MODELS.
    """
    config = read_yaml(Path(path) if path is not None else SIMPLIFIED_CONFIG_PATH)
    kind = config.setdefault('ride_model', 'pitch_plane')
    if kind not in RIDE_MODELS:
        raise ValueError(f'simplified_models.yaml ride_model: unknown model {kind!r}; valid: '
                         + ', '.join(RIDE_MODELS))
    return config


@functools.lru_cache(maxsize=4)
def _scenario_road(spec: RoadSpec, contact_length_m: float) -> RoadInput:
    """The ride road as the full model sees it (same synthesis and enveloping, cached)."""
    return RoadInput.from_profile(synthesise_tracks(spec), contact_length_m)


def strut_block(params: VehicleParams) -> np.ndarray:
    """Strut parameter block of the compiled kernels (layout ``_simplified_kernel.S_*``)."""
    sp = params.strut
    return np.array(
        [
            sp.piston_area_m2,
            sp.polytropic_exponent,
            sp.atmospheric_pressure_pa,
            sp.bump_clearance_m,
            sp.bump_stiffness_n_per_m,
            sp.bump_cubic_n_per_m3,
            sp.bump_smoothing_m,
            sp.rebound_clearance_m,
            sp.rebound_stiffness_n_per_m,
            sp.rebound_cubic_n_per_m3,
            sp.rebound_smoothing_m,
        ]
    )


def axle_bars_nm_per_rad(settings: AxleSettings, params: VehicleParams,
                         vehicle_bars: bool) -> np.ndarray:
    """Anti-roll-bar stiffness per design and axle (batch, 2), N m/rad.

    The design's bar where it sets one (``AxleSettings.anti_roll_bar``); else
    config/vehicle.yaml's when ``vehicle_bars`` (the handling model's option
    ``anti_roll_bar``), else none (the paper's eq. 14 has only the struts).
    """
    batch = settings.batch_size
    out = np.zeros((batch, 2))
    vehicle = (params.arb_front_nm_per_rad, params.arb_rear_nm_per_rad)
    for j, axle in enumerate(('front', 'rear')):
        bar = settings.anti_roll_bar(axle)
        out[:, j] = bar if bar is not None else (vehicle[j] if vehicle_bars else 0.0)
    return out


def axle_strut_states(settings: AxleSettings, params: VehicleParams,
                      vehicle_bars: bool = False) -> np.ndarray:
    """Per-design, per-axle strut state (batch, 2, 8).

    Entries: K, V_s, guard volume, dpsf, k, F_s, rebound dpsf, anti-roll bar
    (:func:`axle_bars_nm_per_rad`; only the handling model uses it).

    Gas spring: ``K = V_s p_s^(1/n)`` with the static pressure of
    ``strut.static_pressure_pa`` at the axle's static strut load, so the gas force equals
    that load at zero stroke (as in ``strut.gas_force_n``); the coil rate k is 0.  Coil
    spring (a design space whose spring is a stiffness): k and the static load F_s
    (``strut.coil_force_n``), the gas entries unused.
    """
    sp = params.strut
    loads = np.array([params.static_strut_load_front_n, params.static_strut_load_rear_n])
    dpsf = np.stack([settings.dpsf_front, settings.dpsf_rear], axis=1)
    out = np.zeros(dpsf.shape + (SK.N_SS,))
    out[..., SK.SS_DPSF] = dpsf
    out[..., SK.SS_DPSF_REB] = np.stack([settings.dpsf_rebound('front'),
                                         settings.dpsf_rebound('rear')], axis=1)
    out[..., SK.SS_KARB] = axle_bars_nm_per_rad(settings, params, vehicle_bars)
    if settings.spring_quantity == 'stiffness':
        out[..., SK.SS_KC] = np.stack([settings.spring('front'), settings.spring('rear')], axis=1)
        out[..., SK.SS_F0] = loads
        out[..., SK.SS_K] = out[..., SK.SS_V] = 1.0  # unused by the coil spring
        return np.ascontiguousarray(out)
    p_s = strut_mod.static_pressure_pa(loads, sp)
    vol = np.stack([settings.gas_volume_front_m3, settings.gas_volume_rear_m3], axis=1)
    out[..., SK.SS_K] = vol * p_s ** (1.0 / sp.polytropic_exponent)
    out[..., SK.SS_V] = vol
    out[..., SK.SS_VG] = sp.min_volume_fraction * vol
    return np.ascontiguousarray(out)


def static_tyre_deflections_m(params: VehicleParams) -> tuple[float, float]:
    """Static tyre deflection front and rear [m]: (strut load + half axle weight) / k_t."""
    k = params.tyre.vertical_stiffness_n_per_m
    return params.static_tyre_load_front_n / k, params.static_tyre_load_rear_n / k


@dataclass(frozen=True)
class RideSetup:
    """Road and run settings of the ride scenario (config/scenarios.yaml 'ride').

    Attributes
    ----------
    road : RoadInput
        Left and right tracks as the full model sees them (enveloped).
    speed_mps : float
        Constant forward speed [m/s].
    duration_s : float
        Simulated time [s].
    settle_s : float
        Initial time discarded by the weighted RMS [s].
    x0_cg_m : float
        Initial position of the sprung cg along the road [m].
    """

    road: RoadInput
    speed_mps: float
    duration_s: float
    settle_s: float
    x0_cg_m: float

    @classmethod
    def from_scenario_config(
        cls,
        params: VehicleParams,
        scenarios: dict[str, Any] | None = None,
        road: RoadProfile | RoadInput | None = None,
    ) -> RideSetup:
        """Build from config/scenarios.yaml 'ride' (road synthesised from config/road.yaml).

        Parameters
        ----------
        params : VehicleParams
            Vehicle parameters (wheelbase, tyre contact length).
        scenarios : dict, optional
            Parsed scenarios config (default: config/scenarios.yaml).
        road : RoadProfile or RoadInput, optional
            Road to use instead of the configured one (a RoadProfile is enveloped over the
            tyre contact length like in the full model).
        """
        sc = (scenarios if scenarios is not None else load_scenarios_config())['ride']
        if road is None:
            road = _scenario_road(ride_road_spec(sc), params.tyre.contact_length_m)
        elif not isinstance(road, RoadInput):
            road = RoadInput.from_profile(road, params.tyre.contact_length_m)
        return cls(
            road=road,
            speed_mps=float(sc['speed_kmh']) * KMH,
            duration_s=float(sc['duration_s']),
            settle_s=float(sc['settle_s']),
            x0_cg_m=float(sc['start_rear_axle_at_m']) + params.b_m,
        )


@dataclass
class PitchPlaneRecord:
    """Outputs of a pitch-plane run, every integration step (leading design axis).

    Attributes
    ----------
    t_s : np.ndarray
        Times (n,) [s].
    acc_driver_mps2, acc_passenger_mps2 : np.ndarray
        Vertical seat accelerations (batch, n) [m/s^2].
    tyre_fz_n : np.ndarray
        Vertical force of one front and one rear tyre (batch, 2, n) [N].
    heave_m, pitch_rad : np.ndarray
        Body heave (up) and pitch (nose down) (batch, n).
    strut_force_n : np.ndarray
        Front and rear strut force (batch, 2, n) [N].
    road_m : np.ndarray
        Centreline road under the front and rear axle (2, n) [m].
    """

    t_s: np.ndarray
    acc_driver_mps2: np.ndarray
    acc_passenger_mps2: np.ndarray
    tyre_fz_n: np.ndarray
    heave_m: np.ndarray
    pitch_rad: np.ndarray
    strut_force_n: np.ndarray
    road_m: np.ndarray

    @property
    def dt_s(self) -> float:
        """Time step [s]."""
        return float(self.t_s[1] - self.t_s[0])


class PitchPlaneModel:
    """Batched pitch-plane ride model (eqs. 15-24) on the ride scenario's road.

    Parameters
    ----------
    params : VehicleParams, optional
        Vehicle parameters (default config/*.yaml).
    setup : RideSetup, optional
        Road, speed and duration (default: config/scenarios.yaml 'ride').
    dt_s : float, optional
        RK4 step [s] (default config/simplified_models.yaml pitch_plane.time_step_s).
    """

    def __init__(
        self,
        params: VehicleParams | None = None,
        setup: RideSetup | None = None,
        dt_s: float | None = None,
    ) -> None:
        self.params = params if params is not None else load_vehicle_params()
        self.setup = setup if setup is not None else RideSetup.from_scenario_config(self.params)
        config = load_simplified_config()
        cfg = config['pitch_plane']
        self.soft_load_fraction = float(config['tyre_hop_gradient']['load_fraction'])
        self.dt_s = float(dt_s if dt_s is not None else cfg['time_step_s'])
        if not np.isfinite(self.dt_s) or self.dt_s <= 0:
            raise ValueError(f'dt_s must be positive, got {self.dt_s}')
        p = self.params
        self._P = np.ascontiguousarray(np.concatenate([strut_block(p),
                                                       self._model_parameters()]))
        sp = p.strut
        self._dk = np.ascontiguousarray(sp.damper_velocity_mps)
        self._dv = np.ascontiguousarray(sp.damper_force_n)
        self._ds = np.ascontiguousarray(strut_mod.damper_knot_slopes(sp))
        self.n_steps = int(round(self.setup.duration_s / self.dt_s))
        if self.n_steps < 2:
            raise ValueError('ride duration shorter than two time steps')
        self._road = self._road_arrays()

    def _model_parameters(self) -> list[float]:
        """The kernel's parameters after the strut block (``_simplified_kernel`` PP_*)."""
        p = self.params
        dstf, dstr = static_tyre_deflections_m(p)
        return [
            p.g_mps2,
            p.a_m,
            p.b_m,
            p.mass_sprung_kg,
            p.i_pitch_sprung_kgm2,
            p.mass_axle_front_kg,
            p.mass_axle_rear_kg,
            p.tyre.vertical_stiffness_n_per_m,
            p.tyre.vertical_damping_ns_per_m,
            dstf,
            dstr,
            p.driver_x_m,
            p.passenger_x_m,
        ]

    def static_tyre_loads_n(self) -> np.ndarray:
        """Static load of each of the model's tyres [N]: one front, one rear."""
        return np.array([self.params.static_tyre_load_front_n,
                         self.params.static_tyre_load_rear_n])

    def _road_arrays(self) -> tuple[np.ndarray, ...]:
        """Centreline road and its rate under each axle at every half step."""
        st, p = self.setup, self.params
        t_half = np.arange(2 * self.n_steps + 1) * 0.5 * self.dt_s
        out = []
        for x_axle in (p.a_m, -p.b_m):
            x = st.x0_cg_m + x_axle + st.speed_mps * t_half
            zl, sl = st.road.elevation(x, 0)
            zr, sr = st.road.elevation(x, 1)
            out.append(np.ascontiguousarray(0.5 * (zl + zr)))
            out.append(np.ascontiguousarray(0.5 * (sl + sr) * st.speed_mps))
        return tuple(out)

    def simulate(self, settings: AxleSettings) -> PitchPlaneRecord:
        """Run every design of ``settings`` from static equilibrium over the ride road.

        Parameters
        ----------
        settings : AxleSettings
            Gas volume and dpsf per axle (batch,) each: in the ride scenario the design
            sets the soft (ride) gas volume and the low-damping dpsf, as in the full model.

        Returns
        -------
        PitchPlaneRecord
            Outputs at every step.
        """
        ss = axle_strut_states(settings.for_mode('ride'), self.params)
        b = ss.shape[0]
        states = np.zeros((b, SK.N_PP_STATE))
        out = np.empty((b, self.n_steps, SK.N_PP_OUT))
        zf, zfd, zr, zrd = self._road
        SK.pp_integrate(
            states, ss, self._P, self._dk, self._dv, self._ds, zf, zfd, zr, zrd,
            self.dt_s, self.n_steps, out,
        )  # fmt: skip
        if not np.all(np.isfinite(out)):
            raise RuntimeError('pitch-plane integration diverged (non-finite outputs)')
        out = out.transpose(0, 2, 1)  # (batch, channel, time) views
        return PitchPlaneRecord(
            t_s=np.arange(self.n_steps) * self.dt_s,
            acc_driver_mps2=out[:, SK.O_ACC_D],
            acc_passenger_mps2=out[:, SK.O_ACC_P],
            tyre_fz_n=out[:, SK.O_FZF : SK.O_FZR + 1],
            heave_m=out[:, SK.O_ZS],
            pitch_rad=out[:, SK.O_TH],
            strut_force_n=out[:, SK.O_FSF : SK.O_FSR + 1],
            road_m=np.stack([zf[0:-1:2], zr[0:-1:2]]),
        )

    def evaluate(self, x: np.ndarray, n_vars: int,
                 space: DesignSpace | None = None) -> dict[str, np.ndarray]:
        """Objective eq. 9 and constraints eq. 11 for normalised designs.

        Parameters
        ----------
        x : array_like
            Designs, shape (n_vars,) or (batch, n_vars), in [0.001, 1] (eqs. 5-8).
        n_vars : int
            2 or 4.
        space : DesignSpace, optional
            The design space (default config/design_space.yaml).

        Returns
        -------
        dict
            'f' (batch,), 'g' (batch, 4) in the order FL, FR, RL, RR, and the metrics
            'a_rms_driver_mps2', 'a_rms_passenger_mps2' (batch,).
        """
        xb = validate_design(x, n_vars)
        rec = self.simulate(to_physical(xb, n_vars, space))
        return ride_metrics(rec, self.setup.settle_s, self.static_tyre_loads_n(),
                            self.soft_load_fraction)


def ride_metrics(rec: PitchPlaneRecord, settle_s: float,
                 static_load_n: np.ndarray | None = None,
                 load_fraction: float | None = None) -> dict[str, np.ndarray]:
    """Eq. 9 objective and eq. 11 constraints of a pitch-plane record (full-model rules).

    With the static wheel loads (one per tyre of the record, N) and a load fraction, also
    'g_soft': :func:`~suspension_tuning.vehicle.metrics.soft_tyre_hop_constraints` per
    corner, the tyre-hop measure for gradients.  A record of one front and one rear
    tyre gives each corner its axle's value; a record of four tyres its own.
    """
    fs = 1.0 / rec.dt_s
    # one call for both seats: comfort.wb_sos designs the filter per call (~3 ms)
    acc = np.stack([rec.acc_driver_mps2, rec.acc_passenger_mps2])
    a_d, a_p = np.atleast_2d(weighted_rms(acc, fs, settle_s))
    keep = rec.t_s >= settle_s  # the full model counts lift-off after settling too
    corners = [0, 0, 1, 1] if rec.tyre_fz_n.shape[-2] == 2 else slice(None)
    g = tyre_hop_constraints(rec.tyre_fz_n[..., keep], rec.dt_s)
    out = {
        'f': f_ride(a_d, a_p),
        'g': g[:, corners],
        'a_rms_driver_mps2': a_d,
        'a_rms_passenger_mps2': a_p,
    }
    if static_load_n is not None and load_fraction is not None:
        soft = soft_tyre_hop_constraints(rec.tyre_fz_n[..., keep], static_load_n,
                                         load_fraction)
        out['g_soft'] = soft[:, corners]
    return out


def derivative_numpy(
    state: np.ndarray,
    settings: AxleSettings,
    road: np.ndarray,
    params: VehicleParams | None = None,
) -> np.ndarray:
    """Plain numpy reference of eqs. 15-21 on the shared strut and tyre functions.

    Parameters
    ----------
    state : np.ndarray
        (batch, 8): z_s, theta, z_af, z_ar and their rates [m, rad, m/s, rad/s].
    settings : AxleSettings
        Physical design (batch,).
    road : np.ndarray
        (4,): road elevation and rate under the front and rear axle
        (z_f, z_f', z_r, z_r') [m, m/s].
    params : VehicleParams, optional
        Parameters.

    Returns
    -------
    np.ndarray
        State derivative (batch, 8).
    """
    settings = settings.for_mode('ride')
    p = params if params is not None else load_vehicle_params()
    s = np.asarray(state, dtype=float)
    zs, th, zaf, zar, zsd, thd, zafd, zard = s.T
    a, b = p.a_m, p.b_m
    dstf, dstr = static_tyre_deflections_m(p)
    ff = strut_mod.strut_force(
        zaf - (zs - a * th), zafd - (zsd - a * thd), settings.gas_volume_front_m3,
        settings.dpsf_front, p.static_strut_load_front_n, p, settings.stiffness_front_n_per_m,
        settings.dpsf_rebound('front'),
    )  # fmt: skip
    fr = strut_mod.strut_force(
        zar - (zs + b * th), zard - (zsd + b * thd), settings.gas_volume_rear_m3,
        settings.dpsf_rear, p.static_strut_load_rear_n, p, settings.stiffness_rear_n_per_m,
        settings.dpsf_rebound('rear'),
    )  # fmt: skip
    k, c = p.tyre.vertical_stiffness_n_per_m, p.tyre.vertical_damping_ns_per_m
    tf = vertical_force(dstf + road[0] - zaf, road[1] - zafd, k, c)
    tr = vertical_force(dstr + road[2] - zar, road[3] - zard, k, c)
    g = p.g_mps2
    acc = np.stack(
        [
            (2 * ff + 2 * fr) / p.mass_sprung_kg - g,
            (-2 * a * ff + 2 * b * fr) / p.i_pitch_sprung_kgm2,
            (2 * tf - 2 * ff) / p.mass_axle_front_kg - g,
            (2 * tr - 2 * fr) / p.mass_axle_rear_kg - g,
        ],
        axis=1,
    )
    return np.concatenate([s[:, 4:], acc], axis=1)


def linear_mass_stiffness(
    settings: AxleSettings, params: VehicleParams | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Mass and tangent-stiffness matrices (4x4) of the first design about equilibrium.

    The stiffness is the negative Jacobian of the numpy reference's accelerations times the
    mass matrix (central differences, 1e-7 m), i.e. the linearisation of the model itself.

    Returns
    -------
    (M, K) : tuple of np.ndarray
        Diagonal mass matrix diag(m_b, I_y, m_tf, m_tr) and stiffness (N/m, N m/rad).
    """
    p = params if params is not None else load_vehicle_params()
    one = AxleSettings.of({a: settings.dpsf(a)[:1] for a in ('front', 'rear')},
                          {a: settings.spring(a)[:1] for a in ('front', 'rear')},
                          settings.spring_quantity)
    M = np.diag([p.mass_sprung_kg, p.i_pitch_sprung_kgm2, p.mass_axle_front_kg,
                 p.mass_axle_rear_kg])  # fmt: skip
    eps = 1e-7
    K = np.empty((4, 4))
    road = np.zeros(4)
    for j in range(4):
        sp_, sm_ = np.zeros((1, 8)), np.zeros((1, 8))
        sp_[0, j] += eps
        sm_[0, j] -= eps
        dp = derivative_numpy(sp_, one, road, p)[0, 4:]
        dm = derivative_numpy(sm_, one, road, p)[0, 4:]
        K[:, j] = -M @ (dp - dm) / (2 * eps)
    return M, K


def natural_frequencies_hz(
    settings: AxleSettings, params: VehicleParams | None = None
) -> np.ndarray:
    """Undamped natural frequencies [Hz] of the linearised pitch-plane model, ascending."""
    from scipy import linalg

    M, K = linear_mass_stiffness(settings, params)
    w2 = linalg.eigh(0.5 * (K + K.T), M, eigvals_only=True)
    return np.sqrt(np.maximum(w2, 0.0)) / (2.0 * np.pi)
