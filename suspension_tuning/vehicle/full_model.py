"""Full nonlinear Land Rover Defender 110 model with 4S4 struts (paper section 4).

Degrees of freedom (per design; a leading batch axis runs many designs at once):

- vehicle planar motion: position X, Y, yaw psi, longitudinal speed u (held by a speed
  controller, paper section 4), lateral velocity v, yaw rate r;
- sprung body as two rigid halves (front, rear) joined along the roll axis by a revolute
  joint with a torsional spring-damper (body torsion, paper section 4): common heave zs and
  pitch theta, separate roll phi_f, phi_r about the roll axis through the roll centres;
- front and rear beam axles: vertical z_a and roll phi_a;
- road-wheel steer angle delta (first-order steering actuator lag).

Wheel spin and longitudinal tyre slip are left out, as in the paper ("longitudinal dynamic
behaviour of the tyres and vehicle is not considered").  Struts are vertical between body
and axle at +-strut_track/2 (motion ratio 1).  Lateral tyre forces reach the sprung mass
through the axle links at the roll centres; each axle carries the roll moment of its
lateral forces about its roll centre (geometric load transfer).  Body roll about the roll
axis couples with lateral and yaw acceleration through a constant mass matrix
(small roll/pitch angles in the inertia terms; the pendulum term m g h sin(phi) is kept).
Longitudinal load transfer is neglected (speed is nearly constant).  Tyre
lateral forces follow the kinematic slip angles without relaxation length (no lag; fine
at 65 km/h, where the relaxation time is ~0.03 s) and camber from axle roll is ignored.
The road under each wheel is the track profile averaged over the tyre contact length.
The rear anti-roll bar is a torsional spring between the rear body half and the rear axle
(paper section 4).

Equations are written as ``M acc = Q(state)`` with constant M; see ``mass_matrix`` and
``generalised_forces_numpy``.  The compiled kernel (``_kernel.py``) evaluates the same
equations; ``derivative_numpy`` is the plain numpy reference the tests compare it with.

Integration (config/vehicle.yaml ``integration.method``, selectable per model):

- ``fixed_step`` (default): classical RK4 with a fixed step (2 ms), independent per
  design, so a design gives the same bits alone, in any batch, and whether it is run in
  one call or in chunks of steps;
- ``variable_step``: the Dormand-Prince 5(4) pair with error control and dense output
  onto the same 2 ms output grid (``_variable_step.py``), as a multibody code integrates;
  same bits alone or in any batch, and in chunks that end on control ticks.

Driver and speed controller act at a fixed control period (zero-order hold) aligned to
absolute step counts of the output grid.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numba
import numpy as np
from scipy import linalg, ndimage, optimize

from . import _kernel as K  # noqa: N812
from . import _variable_step as VS  # noqa: N812
from . import strut as strut_mod
from . import tyre as tyre_mod
from ._buffers import RECORDING
from .params import IntegratorSettings, VehicleParams, load_vehicle_params, with_integrator

CORNERS = ('FL', 'FR', 'RL', 'RR')
AXLES = ('front', 'rear')
VERTICAL_DOFS = ('zs', 'theta', 'phi_f', 'phi_r', 'zaf', 'phiaf', 'zar', 'phiar')
#: A kernel call of fewer design-steps (designs x steps) than this runs on one thread.
#: The kernels' parallel loop is over designs, and starting its threads costs 50 us on
#: an idle two-core machine and up to 3 ms on a loaded one, against about 3 us of work
#: a design-step: step-locked runs (the closed-loop scenario, a model behind an FMU)
#: call the kernel every control period or every step, and ran up to 300 times slower
#: on two threads (measured: 2.7 ms against 9 us a step of one design).  1000
#: design-steps are a few ms of work, where a second thread saves at most half.  The
#: bits do not depend on it: designs are independent.
SERIAL_BELOW_DESIGN_STEPS = 1000
PATH_TABLE_DX_M = 0.05  # [m] tabulation step of the driver's reference path (C1 path:
# linear-interpolation error ~ dx^2 y''/8, below 1e-5 m for the ISO 3888-1 transitions)
FULL_CHANNELS = (
    'acc_driver',
    'acc_passenger',
    'roll',
    'roll_rate',
    'fz_FL',
    'fz_FR',
    'fz_RL',
    'fz_RR',
)


# ---- suspension settings and valve states ----------------------------------------------
@dataclass(frozen=True)
class SuspensionSetting:
    """4S4 settings per design and axle (arrays of shape (batch, 2): front, rear).

    Attributes
    ----------
    gas_volume_soft_m3 : np.ndarray
        Static gas volume with both accumulators connected (soft spring) [m^3].
    gas_volume_stiff_m3 : np.ndarray
        Static gas volume of the small accumulator alone (stiff spring) [m^3].
    dpsf_low, dpsf_high : np.ndarray
        Damper scale factors of the low-damping (bypass open) and high-damping states [-]:
        of the compression half of the table when the rebound factors are given, else of
        the whole table.
    dpsf_low_rebound, dpsf_high_rebound : np.ndarray or None
        Scale factors of the rebound half of the table in each damping state [-]; None:
        as ``dpsf_low`` and ``dpsf_high``.
    arb_nm_per_rad : np.ndarray or None
        Anti-roll-bar stiffness per design and axle [N m/rad]; None: config/vehicle.yaml's.
    """

    gas_volume_soft_m3: np.ndarray
    gas_volume_stiff_m3: np.ndarray
    dpsf_low: np.ndarray
    dpsf_high: np.ndarray
    dpsf_low_rebound: np.ndarray | None = None
    dpsf_high_rebound: np.ndarray | None = None
    arb_nm_per_rad: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Validate shapes and values (ValueError naming the field)."""
        shape = np.shape(self.gas_volume_soft_m3)
        if self.dpsf_low_rebound is None:
            object.__setattr__(self, 'dpsf_low_rebound', self.dpsf_low)
        if self.dpsf_high_rebound is None:
            object.__setattr__(self, 'dpsf_high_rebound', self.dpsf_high)
        for name in ('gas_volume_soft_m3', 'gas_volume_stiff_m3', 'dpsf_low', 'dpsf_high',
                     'dpsf_low_rebound', 'dpsf_high_rebound', 'arb_nm_per_rad'):
            if getattr(self, name) is None:
                continue
            val = np.asarray(getattr(self, name), dtype=float)
            if val.ndim != 2 or val.shape[1] != 2 or val.shape != shape:
                raise ValueError(
                    f'SuspensionSetting.{name} must have shape (batch, 2), got {val.shape}'
                )
            bad = np.any(val < 0) if name == 'arb_nm_per_rad' else np.any(val <= 0)
            if not np.all(np.isfinite(val)) or bad:
                raise ValueError(f'SuspensionSetting.{name} must be positive and finite')
            object.__setattr__(self, name, val)

    @property
    def batch_size(self) -> int:
        """Number of designs."""
        return self.gas_volume_soft_m3.shape[0]

    @classmethod
    def baseline(cls, params: VehicleParams, batch: int = 1) -> SuspensionSetting:
        """Baseline settings of config/strut_4s4.yaml for every design."""
        sp = params.strut
        one = np.ones((batch, 2))
        return cls(
            sp.gas_volume_soft_m3 * one,
            sp.gas_volume_stiff_m3 * one,
            sp.dpsf_low * one,
            sp.dpsf_high * one,
        )

    @classmethod
    def from_design(cls, axle_settings, mode: str, params: VehicleParams) -> SuspensionSetting:
        """Build settings where the design replaces the setting optimised in ``mode``.

        Parameters
        ----------
        axle_settings : design.AxleSettings
            Physical design (dpsf and gas volume front/rear, each (batch,)); a design
            whose spring is a stiffness is refused (ValueError): the 4S4 strut has gas
            springs.  Its ``extra`` settings act as their targets say
            (``design.TARGETS``): a rebound dpsf on the mode's damping state, an
            anti-roll bar, or one 4S4 state set explicitly (``gas_volume_stiff``,
            ``dpsf_low``...) whatever the mode.
        mode : {'ride', 'handling'}
            'ride': the design sets the soft gas volume and the low-damping dpsf;
            'handling': the stiff gas volume and the high-damping dpsf.  The other state
            keeps the baseline (a baseline stiff volume above the soft one is capped at the
            soft one, the large accumulator is then empty).
        params : VehicleParams
            Parameters (baseline settings).
        """
        if axle_settings.spring_quantity != 'volume':
            raise ValueError(
                "the built-in 4S4 model's springs are gas springs (a static gas volume per "
                'axle); a design space whose spring is a stiffness (config/design_space.yaml) '
                'needs a full model of a coil-sprung vehicle: run it as an FMU (docs/fmu.md)')
        dpsf = np.stack([axle_settings.dpsf_front, axle_settings.dpsf_rear], axis=1)
        gvol = np.stack(
            [axle_settings.gas_volume_front_m3, axle_settings.gas_volume_rear_m3], axis=1
        )
        base = cls.baseline(params, dpsf.shape[0])
        extra = axle_settings.extra
        if not extra:  # the paper's design (eqs. 4-8)
            if mode == 'ride':
                return cls(gvol, np.minimum(base.gas_volume_stiff_m3, gvol), dpsf,
                           base.dpsf_high)
            if mode == 'handling':
                return cls(np.maximum(base.gas_volume_soft_m3, gvol), gvol, base.dpsf_low, dpsf)
            raise ValueError(f"mode must be 'ride' or 'handling', got {mode!r}")
        if mode not in ('ride', 'handling'):
            raise ValueError(f"mode must be 'ride' or 'handling', got {mode!r}")

        def pair(key: str, default: np.ndarray) -> np.ndarray:
            out = np.array(default, dtype=float)
            for j, axle in enumerate(('front', 'rear')):
                if f'{key}_{axle}' in extra:
                    out[:, j] = extra[f'{key}_{axle}']
            return out

        rebound = np.stack([axle_settings.dpsf_rebound('front'),
                            axle_settings.dpsf_rebound('rear')], axis=1)
        explicit = [k for k in extra if not k.startswith(('dpsf_rebound', 'anti_roll_bar'))]
        if mode == 'ride':
            soft, low, low_reb = gvol, dpsf, rebound
            stiff, high, high_reb = (base.gas_volume_stiff_m3, base.dpsf_high,
                                     base.dpsf_high)
        else:
            stiff, high, high_reb = gvol, dpsf, rebound
            soft, low, low_reb = base.gas_volume_soft_m3, base.dpsf_low, base.dpsf_low
        if explicit:  # a state set explicitly overrides the mode's and the baseline's
            soft = pair('gas_volume_soft', soft)
            stiff = pair('gas_volume_stiff', stiff)
            low, low_reb = np.array(low, dtype=float), np.array(low_reb, dtype=float)
            high, high_reb = np.array(high, dtype=float), np.array(high_reb, dtype=float)
            for j, axle in enumerate(('front', 'rear')):
                for key, comp, reb in (('dpsf_low', low, low_reb),
                                       ('dpsf_high', high, high_reb)):
                    if f'{key}_{axle}' in extra:  # both halves of that state's table
                        comp[:, j] = reb[:, j] = extra[f'{key}_{axle}']
        if mode == 'ride':
            stiff = np.minimum(stiff, soft)
        else:
            soft = np.maximum(soft, stiff)
        arb = None
        if any(k.startswith('anti_roll_bar') for k in extra):
            arb = pair('anti_roll_bar', np.tile([params.arb_front_nm_per_rad,
                                                 params.arb_rear_nm_per_rad],
                                                (dpsf.shape[0], 1)))
        return cls(soft, stiff, low, high, low_reb, high_reb, arb)


@dataclass(frozen=True)
class ValveState:
    """Valve state per design and axle: ``spring_soft`` and ``damping_high`` (batch, 2)."""

    spring_soft: np.ndarray
    damping_high: np.ndarray

    @classmethod
    def uniform(cls, batch: int, spring: str, damping: str) -> ValveState:
        """Return one state for all axles: spring 'soft'/'stiff', damping 'low'/'high'."""
        if spring not in ('soft', 'stiff'):
            raise ValueError(f"spring state must be 'soft' or 'stiff', got {spring!r}")
        if damping not in ('low', 'high'):
            raise ValueError(f"damping state must be 'low' or 'high', got {damping!r}")
        return cls(np.full((batch, 2), spring == 'soft'), np.full((batch, 2), damping == 'high'))

    @classmethod
    def ride(cls, batch: int) -> ValveState:
        """Return the ride setting: soft spring, low damping (paper section 3)."""
        return cls.uniform(batch, 'soft', 'low')

    @classmethod
    def handling(cls, batch: int) -> ValveState:
        """Return the handling setting: stiff spring, high damping (paper section 3)."""
        return cls.uniform(batch, 'stiff', 'high')


# ---- constant model matrices -----------------------------------------------------------
def mass_matrix(params: VehicleParams) -> np.ndarray:
    """Constant 11x11 mass matrix of [vdot, rdot, udot, zs, theta, phi_f, phi_r, zaf, phiaf,
    zar, phiar] (kg, kg m, kg m^2 entries), see the module docstring.
    """  # noqa: D205
    p = params
    mf, mr = p.mass_front_half_kg, p.mass_rear_half_kg
    hf, hr = p.h_roll_front_m, p.h_roll_rear_m
    xf, xr = p.front_half_cg_x_m, p.rear_half_cg_x_m
    i_f = p.i_roll_sprung_kgm2 * mf / p.mass_sprung_kg
    i_r = p.i_roll_sprung_kgm2 * mr / p.mass_sprung_kg
    lf = p.roll_centre_front_m - p.axle_height_m
    lr = p.roll_centre_rear_m - p.axle_height_m
    M = np.zeros((11, 11))
    M[0, 0] = p.mass_total_kg
    M[0, 5], M[0, 6] = -mf * hf, -mr * hr
    M[1, 1] = p.i_yaw_total_kgm2
    M[1, 5], M[1, 6] = -mf * xf * hf, -mr * xr * hr
    M[2, 2] = p.mass_total_kg
    M[3, 3] = p.mass_sprung_kg
    M[4, 4] = p.i_pitch_sprung_kgm2
    M[5, 0], M[5, 1], M[5, 5] = -mf * hf, -mf * xf * hf, i_f + mf * hf**2
    M[6, 0], M[6, 1], M[6, 6] = -mr * hr, -mr * xr * hr, i_r + mr * hr**2
    M[7, 7] = p.mass_axle_front_kg
    M[8, 0], M[8, 1] = p.mass_axle_front_kg * lf, p.mass_axle_front_kg * lf * p.a_m
    M[8, 8] = p.i_roll_axle_front_kgm2
    M[9, 9] = p.mass_axle_rear_kg
    M[10, 0], M[10, 1] = p.mass_axle_rear_kg * lr, -p.mass_axle_rear_kg * lr * p.b_m
    M[10, 10] = p.i_roll_axle_rear_kgm2
    return M


def param_vector(params: VehicleParams) -> np.ndarray:
    """Flat parameter vector for the compiled kernel (index names ``_kernel.P_*``)."""
    p, sp, tp = params, params.strut, params.tyre
    P = np.zeros(K.N_PAR)
    P[K.P_G] = p.g_mps2
    P[K.P_A], P[K.P_B] = p.a_m, p.b_m
    P[K.P_T2], P[K.P_TS2] = p.track_m / 2, p.strut_track_m / 2
    P[K.P_MV], P[K.P_MS] = p.mass_total_kg, p.mass_sprung_kg
    P[K.P_MF], P[K.P_MR] = p.mass_front_half_kg, p.mass_rear_half_kg
    P[K.P_MAF], P[K.P_MAR] = p.mass_axle_front_kg, p.mass_axle_rear_kg
    P[K.P_HF], P[K.P_HR] = p.h_roll_front_m, p.h_roll_rear_m
    P[K.P_HRCF], P[K.P_HRCR] = p.roll_centre_front_m, p.roll_centre_rear_m
    P[K.P_RAX] = p.axle_height_m
    P[K.P_KTOR], P[K.P_CTOR] = p.torsion_stiffness_nm_per_rad, p.torsion_damping_nms_per_rad
    P[K.P_KARBF], P[K.P_KARBR] = p.arb_front_nm_per_rad, p.arb_rear_nm_per_rad
    P[K.P_KT], P[K.P_CT] = tp.vertical_stiffness_n_per_m, tp.vertical_damping_ns_per_m
    P[K.P_DSTF] = p.static_tyre_load_front_n / tp.vertical_stiffness_n_per_m
    P[K.P_DSTR] = p.static_tyre_load_rear_n / tp.vertical_stiffness_n_per_m
    P[K.P_AP], P[K.P_N], P[K.P_PATM] = (
        sp.piston_area_m2,
        sp.polytropic_exponent,
        sp.atmospheric_pressure_pa,
    )
    P[K.P_BCL], P[K.P_BK], P[K.P_BK3], P[K.P_BS] = (
        sp.bump_clearance_m,
        sp.bump_stiffness_n_per_m,
        sp.bump_cubic_n_per_m3,
        sp.bump_smoothing_m,
    )
    P[K.P_RCL], P[K.P_RK], P[K.P_RK3], P[K.P_RS] = (
        sp.rebound_clearance_m,
        sp.rebound_stiffness_n_per_m,
        sp.rebound_cubic_n_per_m3,
        sp.rebound_smoothing_m,
    )
    P[K.P_TAU], P[K.P_DMAX] = p.steer_time_constant_s, p.steer_max_rad
    P[K.P_FRR] = p.rolling_resistance_coeff
    P[K.P_XD], P[K.P_YD] = p.driver_x_m, p.driver_y_m
    P[K.P_XP], P[K.P_YP] = p.passenger_x_m, p.passenger_y_m
    P[K.P_IZ] = p.i_yaw_total_kgm2
    P[K.P_XF], P[K.P_XR] = p.front_half_cg_x_m, p.rear_half_cg_x_m
    return P


def static_strut_loads_n(params: VehicleParams) -> np.ndarray:
    """Return static strut loads FL, FR, RL, RR [N] (sprung weight split by a, b) [D]."""
    f, r = params.static_strut_load_front_n, params.static_strut_load_rear_n
    return np.array([f, f, r, r])


# ---- road input --------------------------------------------------------------------------
@dataclass(frozen=True)
class RoadInput:
    """Road under the left and right wheel tracks on a uniform grid (already enveloped)."""

    x0_m: float
    dx_m: float
    z_left_m: np.ndarray
    z_right_m: np.ndarray

    @classmethod
    def flat(cls) -> RoadInput:
        """Return a flat road (zero elevation everywhere)."""
        return cls(0.0, 1.0, np.zeros(2), np.zeros(2))

    @classmethod
    def from_profile(cls, profile, contact_length_m: float = 0.0) -> RoadInput:
        """Build from a ``road.RoadProfile`` (uniform x_m), averaging each track over the
        tyre contact length (simple enveloping filter of the point follower).
        """  # noqa: D205
        x = np.asarray(profile.x_m, dtype=float)
        dx = float(x[1] - x[0])
        if not np.allclose(np.diff(x), dx, rtol=1e-6, atol=1e-12):
            raise ValueError('road profile x_m must be uniformly spaced')
        zl = np.asarray(profile.z_left_m, dtype=float)
        zr = np.asarray(profile.z_right_m, dtype=float)
        n_avg = int(round(contact_length_m / dx))
        if n_avg > 1:
            zl = ndimage.uniform_filter1d(zl, n_avg, mode='nearest')
            zr = ndimage.uniform_filter1d(zr, n_avg, mode='nearest')
        return cls(float(x[0]), dx, np.ascontiguousarray(zl), np.ascontiguousarray(zr))

    def elevation(self, x_m: np.ndarray, side: int) -> tuple[np.ndarray, np.ndarray]:
        """Elevation [m] and slope [-] of track ``side`` (0 left, 1 right) at ``x_m``."""
        z = self.z_left_m if side == 0 else self.z_right_m
        n = z.size
        f = (np.asarray(x_m, dtype=float) - self.x0_m) / self.dx_m
        inside = (f > 0) & (f < n - 1)
        i = np.clip(np.floor(f).astype(int), 0, n - 2)
        t = np.clip(f - i, 0.0, 1.0)
        t = np.where(f <= 0, 0.0, t)
        slope = np.where(inside, (z[i + 1] - z[i]) / self.dx_m, 0.0)
        return z[i] + t * (z[i + 1] - z[i]), slope


# ---- plain numpy reference of the equations ------------------------------------------
def generalised_forces_numpy(
    s: np.ndarray,
    ss: np.ndarray,
    u_in: np.ndarray,
    params: VehicleParams,
    road: RoadInput | None = None,
) -> dict[str, np.ndarray]:
    """Right-hand side Q of ``M acc = Q`` and the force elements, plain numpy.

    Built from ``strut.py`` and ``tyre.py`` independently of the compiled kernel.

    Parameters
    ----------
    s : np.ndarray
        States (batch, N_STATE), layout as in ``_kernel``.
    ss : np.ndarray
        Strut states (batch, 4, N_SS).
    u_in : np.ndarray
        Inputs (batch, N_IN).
    params : VehicleParams
        Parameters.
    road : RoadInput, optional
        Road (flat if None).

    Returns
    -------
    dict
        'Q' (batch, 11) and per-corner 'fz', 'fy', 'alpha', 'strut_force', 'stroke'
        (batch, 4).
    """
    p, sp, tp = params, params.strut, params.tyre
    road = road if road is not None else RoadInput.flat()
    s = np.atleast_2d(s)
    a, b, t2, ts2 = p.a_m, p.b_m, p.track_m / 2, p.strut_track_m / 2
    X, psi, u, v, r, delta = (
        s[:, K.I_X],
        s[:, K.I_PSI],
        s[:, K.I_U],
        s[:, K.I_V],
        s[:, K.I_R],
        s[:, K.I_DELTA],
    )
    pos = s[:, K.I_ZS : K.I_ZS + 8]
    vel = s[:, K.I_VEL0 : K.I_VEL0 + 8]
    zs, th, phf, phr, zaf, paf, zar, par = pos.T
    zsd, thd, phfd, phrd, zafd, pafd, zard, pard = vel.T
    xa = np.array([a, a, -b, -b])
    sy = np.array([1.0, -1.0, 1.0, -1.0])
    yw, ysw = sy * t2, sy * ts2
    za = np.stack([zaf, zaf, zar, zar], 1)
    pa = np.stack([paf, paf, par, par], 1)
    zad = np.stack([zafd, zafd, zard, zard], 1)
    pad = np.stack([pafd, pafd, pard, pard], 1)
    phb = np.stack([phf, phf, phr, phr], 1)
    phbd = np.stack([phfd, phfd, phrd, phrd], 1)
    dst = np.array([p.static_tyre_load_front_n] * 2 + [p.static_tyre_load_rear_n] * 2)
    dst = dst / tp.vertical_stiffness_n_per_m
    cpsi, spsi = np.cos(psi)[:, None], np.sin(psi)[:, None]
    Xd = (u * np.cos(psi) - v * np.sin(psi))[:, None]
    xw = X[:, None] + xa * cpsi - yw * spsi
    xwd = Xd - (xa * spsi + yw * cpsi) * r[:, None]
    zroad = np.empty_like(xw)
    slope = np.empty_like(xw)
    for side in (0, 1):
        cols = [side, side + 2]
        zroad[:, cols], slope[:, cols] = road.elevation(xw[:, cols], side)
    defl = dst + zroad - (za + yw * pa)
    defl_d = slope * xwd - (zad + yw * pad)
    fz = tyre_mod.vertical_force(
        defl, defl_d, tp.vertical_stiffness_n_per_m, tp.vertical_damping_ns_per_m
    )
    zb = zs[:, None] - xa * th[:, None] + ysw * phb
    zbd = zsd[:, None] - xa * thd[:, None] + ysw * phbd
    stroke = za + ysw * pa - zb
    stroke_d = zad + ysw * pad - zbd
    p_gas = strut_mod.gas_pressure_pa(
        ss[:, :, K.SS_KSUM],
        ss[:, :, K.SS_VREF] - sp.piston_area_m2 * stroke,
        ss[:, :, K.SS_VGUARD] / sp.min_volume_fraction,
        sp,
    )
    f_s = (
        (p_gas - sp.atmospheric_pressure_pa) * sp.piston_area_m2
        + strut_mod.damper_force_n(stroke_d, ss[:, :, K.SS_DPSF], sp, ss[:, :, K.SS_DPSF_REB])
        + strut_mod.stop_force_n(stroke, sp)
    )
    vx = np.maximum(u[:, None] - yw * r[:, None], 0.1)
    vy = v[:, None] + xa * r[:, None]
    steer = np.stack([delta, delta, 0 * delta, 0 * delta], 1)
    alpha = np.arctan2(vy, vx) - steer
    fy = tyre_mod.pacejka89_lateral(alpha, fz, tp)
    f_rr = -p.rolling_resistance_coeff * fz
    fxb = f_rr * np.cos(steer) - fy * np.sin(steer)
    fyb = f_rr * np.sin(steer) + fy * np.cos(steer)
    mf, mr = p.mass_front_half_kg, p.mass_rear_half_kg
    hf, hr = p.h_roll_front_m, p.h_roll_rear_m
    g = p.g_mps2
    m_tor = p.torsion_stiffness_nm_per_rad * (phr - phf) + p.torsion_damping_nms_per_rad * (
        phrd - phfd
    )
    arb_f = ss[:, 0, K.SS_KARB] * (phf - paf)
    arb_r = ss[:, 2, K.SS_KARB] * (phr - par)
    ur = u * r
    lf = p.roll_centre_front_m - p.axle_height_m
    lr = p.roll_centre_rear_m - p.axle_height_m
    Q = np.empty((s.shape[0], 11))
    Q[:, 0] = fyb.sum(1) - p.mass_total_kg * ur
    Q[:, 1] = (xa * fyb - yw * fxb).sum(1)
    Q[:, 2] = u_in[:, K.IN_FDRIVE] + fxb.sum(1) + p.mass_total_kg * v * r
    Q[:, 3] = f_s.sum(1) - p.mass_sprung_kg * g
    Q[:, 4] = -(xa * f_s).sum(1)
    Q[:, 5] = (
        ts2 * (f_s[:, 0] - f_s[:, 1]) + mf * g * hf * np.sin(phf) + m_tor - arb_f + mf * hf * ur
    )
    Q[:, 6] = (
        ts2 * (f_s[:, 2] - f_s[:, 3]) + mr * g * hr * np.sin(phr) - m_tor - arb_r + mr * hr * ur
    )
    Q[:, 7] = fz[:, 0] + fz[:, 1] - f_s[:, 0] - f_s[:, 1] - p.mass_axle_front_kg * g
    Q[:, 8] = (
        t2 * (fz[:, 0] - fz[:, 1])
        - ts2 * (f_s[:, 0] - f_s[:, 1])
        + p.roll_centre_front_m * fyb[:, :2].sum(1)
        + arb_f
        - p.mass_axle_front_kg * lf * ur
    )
    Q[:, 9] = fz[:, 2] + fz[:, 3] - f_s[:, 2] - f_s[:, 3] - p.mass_axle_rear_kg * g
    Q[:, 10] = (
        t2 * (fz[:, 2] - fz[:, 3])
        - ts2 * (f_s[:, 2] - f_s[:, 3])
        + p.roll_centre_rear_m * fyb[:, 2:].sum(1)
        + arb_r
        - p.mass_axle_rear_kg * lr * ur
    )
    return {
        'Q': Q,
        'fz': fz,
        'fy': fy,
        'alpha': alpha,
        'strut_force': f_s,
        'stroke': stroke,
        'pressure_pa': p_gas,
        'road': zroad,
    }


def derivative_numpy(
    s: np.ndarray,
    ss: np.ndarray,
    u_in: np.ndarray,
    params: VehicleParams,
    road: RoadInput | None = None,
) -> np.ndarray:
    """State derivative (batch, N_STATE), plain numpy reference of the kernel."""
    s = np.atleast_2d(s)
    Q = generalised_forces_numpy(s, ss, u_in, params, road)['Q']
    acc = np.linalg.solve(mass_matrix(params), Q.T).T
    d = np.empty_like(s)
    psi, u, v, r = s[:, K.I_PSI], s[:, K.I_U], s[:, K.I_V], s[:, K.I_R]
    d[:, K.I_X] = u * np.cos(psi) - v * np.sin(psi)
    d[:, K.I_Y] = u * np.sin(psi) + v * np.cos(psi)
    d[:, K.I_PSI] = r
    d[:, K.I_U], d[:, K.I_V], d[:, K.I_R] = acc[:, 2], acc[:, 0], acc[:, 1]
    d[:, K.I_ZS : K.I_ZS + 8] = s[:, K.I_VEL0 : K.I_VEL0 + 8]
    d[:, K.I_VEL0 : K.I_VEL0 + 8] = acc[:, 3:]
    dmax = params.steer_max_rad
    cmd = np.clip(u_in[:, K.IN_DELTA_CMD], -dmax, dmax)
    d[:, K.I_DELTA] = (cmd - s[:, K.I_DELTA]) / params.steer_time_constant_s
    return d


# ---- strut gas states and valve switching ------------------------------------------------
def strut_states(
    setting: SuspensionSetting, valves: ValveState, params: VehicleParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the initial strut states at static equilibrium.

    Returns
    -------
    ss : np.ndarray
        (batch, 4, N_SS) kernel strut states.
    k_acc : np.ndarray
        (batch, 4, 2) gas constants K of the small and large accumulators.
    v_large_frozen : np.ndarray
        (batch, 4) gas volume of the large accumulator when disconnected [m^3].
    """
    corner_axle = np.array([0, 0, 1, 1])
    load = static_strut_loads_n(params)[None, :]
    v_soft = setting.gas_volume_soft_m3[:, corner_axle]
    v_stiff = setting.gas_volume_stiff_m3[:, corner_axle]
    k1, k2 = strut_mod.accumulator_constants(v_soft, v_stiff, load, params)
    soft = valves.spring_soft[:, corner_axle]
    high = valves.damping_high[:, corner_axle]
    v1 = np.minimum(v_stiff, v_soft)
    ss = np.empty((setting.batch_size, 4, K.N_SS))
    ss[:, :, K.SS_KSUM] = np.where(soft, k1 + k2, k1)
    ss[:, :, K.SS_VREF] = np.where(soft, v_soft, v1)
    ss[:, :, K.SS_VGUARD] = params.strut.min_volume_fraction * ss[:, :, K.SS_VREF]
    ss[:, :, K.SS_DPSF] = np.where(
        high, setting.dpsf_high[:, corner_axle], setting.dpsf_low[:, corner_axle]
    )
    ss[:, :, K.SS_DPSF_REB] = np.where(
        high, setting.dpsf_high_rebound[:, corner_axle], setting.dpsf_low_rebound[:, corner_axle]
    )
    arb = (setting.arb_nm_per_rad if setting.arb_nm_per_rad is not None
           else np.tile([params.arb_front_nm_per_rad, params.arb_rear_nm_per_rad],
                        (setting.batch_size, 1)))
    ss[:, :, K.SS_KARB] = arb[:, corner_axle]
    return ss, np.stack([k1, k2], axis=2), v_soft - v1


# ---- the model ------------------------------------------------------------------------
Controller = Callable[['FullVehicleModel'], tuple[np.ndarray, np.ndarray]]


@dataclass
class SimulationRecord:
    """Recorded outputs of a run.

    ``full`` (batch, N_FULL, n) at every step (channels ``FULL_CHANNELS``), ``hist``
    (batch, N_HIST, m) every ``decimation`` steps (indices ``_kernel.H_*``).
    """

    dt_s: float
    decimation: int
    full: np.ndarray
    hist: np.ndarray
    t_full_s: np.ndarray
    t_hist_s: np.ndarray
    wall_time_s: float = 0.0
    extra: dict = field(default_factory=dict)


class FullVehicleModel:
    """Batched full vehicle model with a fixed-step stepping API.

    Typical use::

        model = FullVehicleModel(params, road)
        model.reset(setting, ValveState.ride(batch), speed_mps=13.9)
        model.step(1000)            # advance 1000 fixed steps
        model.set_valve_state(...)  # any time between steps
        rec = model.record()

    Parameters
    ----------
    params : VehicleParams, optional
        Parameters (default: config/*.yaml).
    road : RoadInput or road.RoadProfile, optional
        Road under the two wheel tracks (default flat).  A RoadProfile is enveloped over the
        tyre contact length.
    integrator : str, optional
        'fixed_step' or 'variable_step' (default: ``params.integrator.method``, from
        config/vehicle.yaml); the variable-step settings come from ``params.integrator``.
    step_log_capacity : int
        Accepted steps of the variable-step integrator logged per design (time, size),
        for plots; 0 = none.
    """

    def __init__(
        self,
        params: VehicleParams | None = None,
        road=None,
        integrator: str | None = None,
        step_log_capacity: int = 0,
    ) -> None:
        params = params if params is not None else load_vehicle_params()
        self.params = with_integrator(params, integrator)
        self.integrator: IntegratorSettings = self.params.integrator
        self.step_log_capacity = int(step_log_capacity)
        if road is None:
            road = RoadInput.flat()
        elif not isinstance(road, RoadInput):
            road = RoadInput.from_profile(road, self.params.tyre.contact_length_m)
        self.road = road
        self._P = param_vector(self.params)
        self._Minv = np.ascontiguousarray(np.linalg.inv(mass_matrix(self.params)))
        self._pc = np.ascontiguousarray(self.params.tyre.pacejka)
        sp = self.params.strut
        self._dk = np.ascontiguousarray(sp.damper_velocity_mps)
        self._dv = np.ascontiguousarray(sp.damper_force_n)
        self._ds = np.ascontiguousarray(strut_mod.damper_knot_slopes(sp))
        self.dt_s = self.params.dt_s
        self.steps_per_control = int(round(self.params.control_period_s / self.dt_s))
        self.decimation = self.params.history_decimation
        self._state = None

    # -- set-up --------------------------------------------------------------------------
    def reset(
        self,
        setting: SuspensionSetting,
        valves: ValveState,
        speed_mps: float | np.ndarray,
        x0_m: float = 0.0,
        y0_m: float = 0.0,
        yaw0_rad: float = 0.0,
        controller: Controller | None = None,
        record: bool = True,
        solve_equilibrium: bool = True,
        driver=None,
        speed_controller=None,
    ) -> None:
        """Put every design at static equilibrium at the given speed.

        Parameters
        ----------
        setting : SuspensionSetting
            4S4 settings (batch, 2).
        valves : ValveState
            Initial valve state (batch, 2).
        speed_mps : float or np.ndarray
            Initial (and, without controller, nominal) forward speed [m/s].
        x0_m, y0_m, yaw0_rad : float
            Initial position of the sprung cg and heading.
        controller : callable, optional
            ``controller(model) -> (steer_cmd_rad (batch,), drive_force_n (batch,))`` called
            every control period (zero-order hold), in Python.  Default: no steering and a
            drive force equal to the rolling resistance at static load.
        record : bool
            Record outputs.
        solve_equilibrium : bool
            Solve the static equilibrium numerically (else use the analytic one: zero
            displacements, which is exact by construction of the static gas volume).
        driver : manoeuvre.PreviewDriver, optional
            Preview steering driver run inside the compiled kernel (same algorithm as
            ``PreviewDriver.steer``; reference path tabulated every PATH_TABLE_DX_M).
        speed_controller : manoeuvre.SpeedController, optional
            PI speed controller run inside the compiled kernel (same algorithm as
            ``SpeedController.force`` / ``integral_rate``, integral updated each period).
        """
        batch = setting.batch_size
        if valves.spring_soft.shape != (batch, 2) or valves.damping_high.shape != (batch, 2):
            raise ValueError('valve state arrays must have shape (batch, 2)')
        self.setting = setting
        self._ss, self._k_acc, self._v_large = strut_states(setting, valves, self.params)
        self.valves = ValveState(valves.spring_soft.copy(), valves.damping_high.copy())
        s = np.zeros((batch, K.N_STATE))
        s[:, K.I_X], s[:, K.I_Y], s[:, K.I_PSI] = x0_m, y0_m, yaw0_rad
        s[:, K.I_U] = speed_mps
        if solve_equilibrium:
            s[:, K.I_ZS : K.I_ZS + 8] = self.static_equilibrium(s)
        self._state = np.ascontiguousarray(s)
        self._inputs = np.zeros((batch, K.N_IN))
        w = self.params.mass_total_kg * self.params.g_mps2
        self._inputs[:, K.IN_FDRIVE] = self.params.rolling_resistance_coeff * w
        self.controller = controller
        if controller is not None and (driver is not None or speed_controller is not None):
            raise ValueError('give either a Python controller or driver/speed_controller')
        c = np.zeros(K.N_CTRL)
        c[K.C_SPC] = self.steps_per_control
        c[K.C_TC] = self.steps_per_control * self.dt_s
        self._ytab = np.zeros((3, 2))
        self._cstates = np.zeros((batch, 1))
        if driver is not None:
            c[K.C_STEER_ON] = 1.0
            c[K.C_TP], c[K.C_LPMIN] = driver.preview_time_s, driver.preview_min_m
            c[K.C_KLAT], c[K.C_TFF] = driver.lateral_gain_rad_per_m, driver.feedforward_time_s
            c[K.C_KFF] = driver.k_feedforward
            c[K.C_KUS] = driver.understeer_gradient_rad_per_mps2
            c[K.C_KR], c[K.C_DMAX] = driver.yaw_rate_gain_s, driver.max_steer_rad
            c[K.C_WB] = driver.wheelbase_m
            x_lo = driver.track.section_bounds_m[0] - 1.0
            x_hi = driver.track.x_end_m + 1.0
            n = int(np.ceil((x_hi - x_lo) / PATH_TABLE_DX_M)) + 1
            xs = x_lo + PATH_TABLE_DX_M * np.arange(n)
            tr = driver.track
            self._ytab = np.ascontiguousarray(
                np.stack([tr.y_ref(xs), tr.heading_ref(xs), tr.curvature_ref(xs)]), dtype=float
            )
            c[K.C_TAB_X0], c[K.C_TAB_DX] = x_lo, PATH_TABLE_DX_M
        if speed_controller is not None:
            c[K.C_SPEED_ON] = 1.0
            c[K.C_VT] = speed_controller.target_speed_mps
            c[K.C_KP], c[K.C_KI] = speed_controller.kp_n_per_mps, speed_controller.ki_n_per_m
            c[K.C_FLIM] = speed_controller.force_limit_n
        self._C = c
        it = self.integrator
        self._ctl = np.zeros(VS.N_TOL)
        self._ctl[VS.T_RTOL], self._ctl[VS.T_ATOL] = it.rtol, it.atol
        self._ctl[VS.T_HMIN], self._ctl[VS.T_HMAX] = it.min_step_s, it.max_step_s
        self._ctl[VS.T_SAFETY], self._ctl[VS.T_FACMIN] = it.safety, it.fac_min
        self._ctl[VS.T_FACMAX], self._ctl[VS.T_BETA] = it.fac_max, it.beta
        self._hstate = np.full(batch, it.initial_step_s)
        self._vstats = np.zeros((batch, VS.N_STATS))
        self._step_log = np.zeros((batch, 2, self.step_log_capacity))
        self.step_index = 0
        self._record = record
        self._full_chunks: list[np.ndarray] = []
        self._hist_chunks: list[np.ndarray] = []
        self._wall = 0.0
        self.switch_log: list[tuple[int, np.ndarray, np.ndarray]] = []

    def static_equilibrium(self, s0: np.ndarray, tol: float = 1e-10) -> np.ndarray:
        """Solve the vertical static equilibrium (8 positions) of each design.

        Zero velocities and inputs; Newton iteration (scipy ``root``) on the generalised
        forces of the vertical DOFs.  Returns positions (batch, 8) [m, rad].
        """
        out = np.empty((s0.shape[0], 8))
        idx = [3, 4, 5, 6, 7, 8, 9, 10]
        # Locals, not ``self``: with ``self`` in these closures a finished model (and
        # its recorded arrays) stayed alive until the cyclic garbage collector ran,
        # so the recording pool (_buffers.RECORDING) could not hand its arrays out.
        ss, params, road = self._ss, self.params, self.road
        for bi in range(s0.shape[0]):
            base = s0[bi].copy()
            base[K.I_VEL0 : K.I_VEL0 + 8] = 0.0
            base[K.I_U] = 0.0

            def resid(q, base=base, bi=bi):
                st = base.copy()
                st[K.I_ZS : K.I_ZS + 8] = q
                Q = generalised_forces_numpy(
                    st[None], ss[bi : bi + 1], np.zeros((1, K.N_IN)), params, road
                )['Q'][0]
                return Q[idx] / np.array([1e4, 1e4, 1e4, 1e4, 1e3, 1e3, 1e3, 1e3])

            if np.max(np.abs(resid(np.zeros(8)))) < tol:
                out[bi] = 0.0
                continue
            sol = optimize.root(resid, np.zeros(8), tol=tol)
            if np.max(np.abs(resid(sol.x))) > 1e-6:
                raise RuntimeError(f'static equilibrium not found for design {bi}: {sol.message}')
            out[bi] = sol.x
        return out

    # -- stepping ------------------------------------------------------------------------
    @property
    def batch_size(self) -> int:
        """Number of designs."""
        return self._state.shape[0]

    @property
    def t_s(self) -> float:
        """Simulated time [s]."""
        return self.step_index * self.dt_s

    @property
    def state(self) -> np.ndarray:
        """Copy of the state (batch, N_STATE)."""
        return self._state.copy()

    def set_inputs(
        self, steer_cmd_rad: np.ndarray | None = None, drive_force_n: np.ndarray | None = None
    ) -> None:
        """Set the held inputs (used when no controller is given)."""
        if steer_cmd_rad is not None:
            self._inputs[:, K.IN_DELTA_CMD] = steer_cmd_rad
        if drive_force_n is not None:
            self._inputs[:, K.IN_FDRIVE] = drive_force_n

    def step(self, n_steps: int = 1) -> None:
        """Advance ``n_steps`` fixed steps of ``dt_s``.

        The controller (if any) runs at absolute step counts divisible by the control
        period, so splitting a run into chunks gives the same bits.
        """
        if self._state is None:
            raise RuntimeError('call reset() before step()')
        n_steps = int(n_steps)
        if n_steps < 0:
            raise ValueError(f'n_steps must be >= 0, got {n_steps}')
        t0 = time.perf_counter()
        done = 0
        spc = self.steps_per_control
        while done < n_steps:
            if self.controller is not None and self.step_index % spc == 0:
                steer, drive = self.controller(self)
                self._inputs[:, K.IN_DELTA_CMD] = steer
                self._inputs[:, K.IN_FDRIVE] = drive
            to_tick = spc - self.step_index % spc if self.controller is not None else n_steps
            n = min(n_steps - done, to_tick)
            self._run_kernel(n)
            done += n
        self._wall += time.perf_counter() - t0

    def _run_kernel(self, n: int) -> None:
        threads = numba.get_num_threads()
        serial = threads > 1 and self.batch_size * n < SERIAL_BELOW_DESIGN_STEPS
        if serial:
            numba.set_num_threads(1)  # for this thread's calls only
        try:
            self._run_kernel_calls(n)
        finally:
            if serial:
                numba.set_num_threads(threads)

    def _run_kernel_calls(self, n: int) -> None:
        b = self.batch_size
        if self._record:
            full = RECORDING.empty((b, K.N_FULL, n))
            first = (-self.step_index) % self.decimation
            n_hist = 0 if first >= n else (n - 1 - first) // self.decimation + 1
            hist = RECORDING.empty((b, K.N_HIST, n_hist))
        else:
            full = np.empty((b, K.N_FULL, 0))
            hist = np.empty((b, K.N_HIST, 0))
        if self.integrator.method == 'variable_step':
            self._run_variable(n, full, hist)
        else:
            K.integrate(
                *self._kernel_inputs(),
                self.dt_s,
                n,
                self.step_index,
                self.decimation,
                full,
                hist,
                0,
                0,
                self._cstates,
                self._C,
                self._ytab,
            )
        self.step_index += n
        if self._record:
            self._full_chunks.append(full)
            if hist.shape[2]:
                self._hist_chunks.append(hist)

    def _kernel_inputs(self) -> tuple:
        """States, strut states, inputs, parameters and road: what both kernels take first."""
        r = self.road
        return (self._state, self._ss, self._inputs, self._P, self._Minv, self._pc, self._dk,
                self._dv, self._ds, r.x0_m, r.dx_m, r.z_left_m, r.z_right_m)  # fmt: skip

    def _run_variable(self, n: int, full: np.ndarray, hist: np.ndarray) -> None:
        VS.integrate_variable(
            *self._kernel_inputs(),
            self.dt_s,
            n,
            self.step_index,
            self.decimation,
            full,
            hist,
            self._cstates,
            self._C,
            self._ytab,
            self._ctl,
            *VS.PAIRS[self.integrator.pair],
            self.integrator.controllers == 'continuous',
            self._hstate,
            self._vstats,
            self._step_log,
        )
        failed = np.flatnonzero(self._vstats[:, VS.S_FAILED] > 0)
        if failed.size:
            b = int(failed[0])
            raise RuntimeError(
                f'variable-step integration failed for design {b} at t = '
                f'{self._vstats[b, VS.S_FAIL_T]:.4f} s: step below '
                f'{self.integrator.min_step_s:g} s (rtol {self.integrator.rtol:g}, '
                f'atol {self.integrator.atol:g})'
            )

    def integrator_stats(self) -> dict[str, np.ndarray]:
        """Variable-step statistics per design since reset (zeros for fixed steps).

        Keys: accepted_steps, rejected_steps, derivative_calls, min_step_s,
        max_step_s, and step_log_t_s, step_log_h_s (batch, m): end time and size of
        the first ``step_log_capacity`` accepted steps (NaN beyond the logged ones).
        """
        st = self._vstats
        nlog = st[:, VS.S_NLOG].astype(int)
        cols = np.arange(self._step_log.shape[2])[None, :]
        keep = cols < nlog[:, None]
        return {
            'accepted_steps': st[:, VS.S_ACCEPTED].astype(int),
            'rejected_steps': st[:, VS.S_REJECTED].astype(int),
            'derivative_calls': st[:, VS.S_CALLS].astype(int),
            'min_step_s': st[:, VS.S_HMIN_USED].copy(),
            'max_step_s': st[:, VS.S_HMAX_USED].copy(),
            'step_log_t_s': np.where(keep, self._step_log[:, 0], np.nan),
            'step_log_h_s': np.where(keep, self._step_log[:, 1], np.nan),
        }

    def set_valve_state(
        self, spring_soft: np.ndarray | None = None, damping_high: np.ndarray | None = None
    ) -> None:
        """Switch the 4S4 valves (per design and axle, arrays broadcastable to (batch, 2)).

        Gas is conserved per accumulator: disconnecting the large accumulator freezes its
        gas volume and pressure; reconnecting equalises the pressures isentropically (the
        closed form of ``strut.py``).  Takes effect from the next step.  The valves switch
        at once: their 50-100 ms delay belongs to the valve controller (valve_logic.py),
        which calls this when a delayed switch lands.
        """
        b = self.batch_size
        soft_new = (
            self.valves.spring_soft
            if spring_soft is None
            else np.broadcast_to(np.asarray(spring_soft, dtype=bool), (b, 2)).copy()
        )
        high_new = (
            self.valves.damping_high
            if damping_high is None
            else np.broadcast_to(np.asarray(damping_high, dtype=bool), (b, 2)).copy()
        )
        ca = np.array([0, 0, 1, 1])
        sp = self.params.strut
        stroke = self.outputs()['strut_stroke_m']
        n = sp.polytropic_exponent
        for c in range(4):
            was, now = self.valves.spring_soft[:, ca[c]], soft_new[:, ca[c]]
            k1, k2 = self._k_acc[:, c, 0], self._k_acc[:, c, 1]
            v_conn = self._ss[:, c, K.SS_VREF] - sp.piston_area_m2 * stroke[:, c]
            v_conn_safe = np.maximum(v_conn, self._ss[:, c, K.SS_VGUARD])
            # soft -> stiff: large accumulator keeps its share of the gas at the current p
            off = was & ~now
            p = (self._ss[:, c, K.SS_KSUM] / v_conn_safe) ** n
            v2 = k2 / p ** (1.0 / n)
            self._v_large[off, c] = v2[off]
            vref_off = v_conn - v2 + sp.piston_area_m2 * stroke[:, c]
            # stiff -> soft: reconnect, pressures equalise (K_j unchanged)
            on = ~was & now
            vref_on = v_conn + self._v_large[:, c] + sp.piston_area_m2 * stroke[:, c]
            self._ss[off, c, K.SS_KSUM] = k1[off]
            self._ss[off, c, K.SS_VREF] = vref_off[off]
            self._ss[on, c, K.SS_KSUM] = (k1 + k2)[on]
            self._ss[on, c, K.SS_VREF] = vref_on[on]
            v_static = np.where(
                now,
                self.setting.gas_volume_soft_m3[:, ca[c]],
                np.minimum(
                    self.setting.gas_volume_stiff_m3[:, ca[c]],
                    self.setting.gas_volume_soft_m3[:, ca[c]],
                ),
            )
            self._ss[:, c, K.SS_VGUARD] = sp.min_volume_fraction * v_static
            self._ss[:, c, K.SS_DPSF] = np.where(
                high_new[:, ca[c]],
                self.setting.dpsf_high[:, ca[c]],
                self.setting.dpsf_low[:, ca[c]],
            )
            self._ss[:, c, K.SS_DPSF_REB] = np.where(
                high_new[:, ca[c]],
                self.setting.dpsf_high_rebound[:, ca[c]],
                self.setting.dpsf_low_rebound[:, ca[c]],
            )
        self.valves = ValveState(soft_new, high_new)
        self.switch_log.append((self.step_index, soft_new.copy(), high_new.copy()))

    # -- outputs -------------------------------------------------------------------------
    def outputs(self) -> dict[str, np.ndarray]:
        """Return the current outputs of every design (leading batch axis).

        Keys: lateral_accel_mps2, roll_rad, roll_rate_radps, yaw_rate_radps, steer_rad,
        steer_rate_radps, speed_mps, x_m, y_m, yaw_rad, strut_stroke_m, strut_force_n,
        strut_pressure_pa (absolute), tyre_fz_n, tyre_fy_n, slip_angle_rad,
        acc_driver_mps2, acc_passenger_mps2, vertical_accel_mps2 (body centre of mass,
        gravity removed), longitudinal_accel_mps2, pitch_rate_radps.
        """
        b = self.batch_size
        d = np.empty(K.N_STATE)
        full = np.empty(K.N_FULL)
        hist = np.empty(K.N_HIST)
        work = np.empty(K.N_WORK)
        fulls = np.empty((b, K.N_FULL))
        hists = np.empty((b, K.N_HIST))
        r = self.road
        for bi in range(b):
            K.deriv(
                self._state[bi],
                self._ss[bi],
                self._inputs[bi],
                self._P,
                self._Minv,
                self._pc,
                self._dk,
                self._dv,
                self._ds,
                r.x0_m,
                r.dx_m,
                r.z_left_m,
                r.z_right_m,
                d,
                full,
                hist,
                True,
                work,
            )
            fulls[bi], hists[bi] = full, hist
        return outputs_from_channels(fulls, hists)

    def record(self) -> SimulationRecord:
        """All recorded outputs so far."""
        b = self.batch_size
        full = _joined(self._full_chunks, (b, K.N_FULL, 0))
        hist = _joined(self._hist_chunks, (b, K.N_HIST, 0))
        t_full = np.arange(full.shape[2]) * self.dt_s
        t_hist = np.arange(hist.shape[2]) * self.dt_s * self.decimation
        extra = {'integrator': self.integrator.method}
        if self.integrator.method == 'variable_step':
            extra['integrator_stats'] = self.integrator_stats()
        return SimulationRecord(
            self.dt_s, self.decimation, full, hist, t_full, t_hist, self._wall, extra
        )

    def simulate(self, duration_s: float) -> SimulationRecord:
        """Run ``duration_s`` from the current state and return the record."""
        self.step(int(round(duration_s / self.dt_s)))
        return self.record()


def _joined(chunks: list[np.ndarray], empty_shape: tuple[int, int, int]) -> np.ndarray:
    """Recorded chunks joined along time; a single chunk as it is, without a copy.

    An open-loop run records one chunk, tens of megabytes for a batch (a 30-design
    ride batch: 14 MB of full-rate and 32 MB of decimated channels); copying it cost
    a fresh allocation, page faults and zeroing on every run.  Chunks are never
    written after they are recorded, so sharing one is safe.
    """
    if not chunks:
        return np.empty(empty_shape)
    if len(chunks) == 1:
        return chunks[0]
    return np.concatenate(chunks, axis=2)


def outputs_from_channels(full: np.ndarray, hist: np.ndarray) -> dict[str, np.ndarray]:
    """Named outputs from kernel channel arrays (leading axes preserved, channel axis 1)."""

    def h(i, n=1):
        return hist[:, i] if n == 1 else hist[:, i : i + n]

    return {
        'acc_driver_mps2': full[:, K.F_ACC_D],
        'acc_passenger_mps2': full[:, K.F_ACC_P],
        'roll_rad': full[:, K.F_ROLL],
        'roll_rate_radps': full[:, K.F_ROLL_RATE],
        'tyre_fz_n': full[:, K.F_FZ0 : K.F_FZ0 + 4],
        'x_m': h(K.H_X),
        'y_m': h(K.H_Y),
        'yaw_rad': h(K.H_PSI),
        'speed_mps': h(K.H_U),
        'lateral_accel_mps2': h(K.H_AY),
        'yaw_rate_radps': h(K.H_R),
        'steer_rad': h(K.H_DELTA),
        'steer_rate_radps': h(K.H_DELTA_RATE),
        'roll_front_rad': h(K.H_ROLL_F),
        'roll_rear_rad': h(K.H_ROLL_R),
        'slip_angle_rad': h(K.H_SLIP0, 4),
        'tyre_fy_n': h(K.H_FY0, 4),
        'strut_stroke_m': h(K.H_STROKE0, 4),
        'strut_force_n': h(K.H_FSTRUT0, 4),
        'strut_pressure_pa': h(K.H_PRESS0, 4),
        'road_under_wheel_m': h(K.H_ROAD0, 4),
        'heave_m': h(K.H_ZS),
        'pitch_rad': h(K.H_THETA),
        'pitch_rate_radps': h(K.H_THETA_RATE),
        'vertical_accel_mps2': h(K.H_AZ),
        'longitudinal_accel_mps2': h(K.H_AX),
    }


# ---- linearisation ----------------------------------------------------------------------
def natural_frequencies(
    params: VehicleParams | None = None,
    setting: SuspensionSetting | None = None,
    valves: ValveState | None = None,
    eps: float = 1e-6,
) -> dict[str, float]:
    """Undamped natural frequencies [Hz] of the model linearised about static equilibrium.

    The vertical/roll subsystem (8 DOF: heave, pitch, front and rear body roll, axle
    bounce and roll) is linearised by a central-difference Jacobian of the generalised
    forces; lateral and yaw motion are held (vehicle standing on its tyres, whose side
    forces resist lateral motion), so body roll is about the roll axis.  Modes are named
    after the DOF group holding most of their kinetic energy.

    Returns
    -------
    dict
        'body_heave', 'body_pitch', 'body_roll', 'body_torsion', 'front_axle_hop',
        'rear_axle_hop', 'front_axle_roll', 'rear_axle_roll' in Hz.
    """
    params = params if params is not None else load_vehicle_params()
    setting = setting if setting is not None else SuspensionSetting.baseline(params, 1)
    valves = valves if valves is not None else ValveState.ride(1)
    ss, _, _ = strut_states(setting, valves, params)
    ss = ss[:1]
    idx = np.arange(3, 11)
    M = mass_matrix(params)[np.ix_(idx, idx)]
    s0 = np.zeros((1, K.N_STATE))
    Kmat = np.empty((8, 8))
    for j in range(8):
        sp_, sm_ = s0.copy(), s0.copy()
        sp_[0, K.I_ZS + j] += eps
        sm_[0, K.I_ZS + j] -= eps
        qp = generalised_forces_numpy(sp_, ss, np.zeros((1, K.N_IN)), params)['Q'][0, idx]
        qm = generalised_forces_numpy(sm_, ss, np.zeros((1, K.N_IN)), params)['Q'][0, idx]
        Kmat[:, j] = -(qp - qm) / (2 * eps)
    w2, vecs = linalg.eigh(0.5 * (Kmat + Kmat.T), M)
    names = {}
    for k in range(8):
        phi = vecs[:, k]
        e = phi * (M @ phi)
        groups = {
            'heave': e[0],
            'pitch': e[1],
            'roll_or_torsion': e[2] + e[3],
            'front_axle_hop': e[4],
            'front_axle_roll': e[5],
            'rear_axle_hop': e[6],
            'rear_axle_roll': e[7],
        }
        g = max(groups, key=groups.get)
        f = float(np.sqrt(max(w2[k], 0.0)) / (2 * np.pi))
        if g == 'heave':
            names['body_heave'] = f
        elif g == 'pitch':
            names['body_pitch'] = f
        elif g == 'roll_or_torsion':
            same_sign = phi[2] * phi[3] > 0
            names['body_roll' if same_sign else 'body_torsion'] = f
        else:
            names[g] = f
    return names
