"""Simplified handling model of Thoresson et al. (2009) Part 1, section 6.1 (eqs. 12-14).

Three degrees of freedom at a constant forward speed ``u`` on a smooth road: lateral
motion, yaw and body roll (ISO axes: y left, yaw left positive, roll ``phi`` positive with
the left side up):

* eq. 13, lateral: ``m_v a_y = F_y1 + F_y2 + F_y3 + F_y4`` (body-frame lateral velocity
  ``v' = a_y - u r``);
* eq. 12, yaw: ``I_z r' = a (F_y1 + F_y2) - b (F_y3 + F_y4)`` (small steer angle);
* eq. 14, roll of the body about its cg:
  ``I_x phi'' = (f_l - f_r) t_s / 2 + h (F_yl + F_yr) m_b / m_v``,
  with ``f_l``, ``f_r`` the summed 4S4 strut forces of each side (``strut.strut_force``
  through the compiled kernel, strokes ``-/+ phi t_s / 2``; axle roll ignored [P]).

Tyre lateral forces: Pacejka '89 (the full model's coefficients, ``tyre.pacejka89_lateral``)
of the vertical load and the slip angle.  Vertical loads [P]: the static front/rear share of
the side's suspension force (``b/L`` front, ``a/L`` rear), plus half the axle weight (the
tyre also carries its axle; documented addition).  Slip angles [P]: the full model's
per-tyre slip angles at the current iterate (``slip_angles: full_model``), or, as an
option, the model's own ``atan((v + a r)/u) - delta`` front and ``atan((v - b r)/u)`` rear
driven by the full model's road-wheel steer angle (``slip_angles: own``).

Options (config/simplified_models.yaml ``handling``; defaults are the paper's eq. 14):
roll moment arm (``cg_height`` [P] or ``roll_axis``), gravity roll moment, anti-roll bars.

The objective eq. 10 and constraints eq. 11 are computed as in the full model's handling
scenario: first roll peak in the first lane change, RMS roll rate and the tyre lift-off
fractions over the manoeuvre window, both windows taken from the full model's run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _simplified_kernel as SK  # noqa: N812
from . import strut as strut_mod
from .design import AxleSettings, DesignSpace, to_physical, validate_design
from .metrics import (
    FZ_CONTACT_THRESHOLD_N,
    f_hand,
    first_peak,
    roll_rate_rms,
    soft_tyre_hop_constraints,
)
from .params import VehicleParams, load_vehicle_params
from .pitch_plane import (
    axle_bars_nm_per_rad,
    axle_strut_states,
    load_simplified_config,
    strut_block,
)
from .tyre import pacejka89_lateral

SLIP_SOURCES = ('full_model', 'own')
ROLL_ARMS = ('cg_height', 'roll_axis')


@dataclass(frozen=True)
class HandlingInputs:
    """Inputs of the handling model, captured from a full-model handling run.

    Attributes
    ----------
    t_s : np.ndarray
        Uniform sample times (n,) [s].
    speed_mps : float
        Constant forward speed [m/s].
    steer_rad : np.ndarray
        Front road-wheel steer angle (n,) [rad].
    slip_angle_rad : np.ndarray
        Per-tyre slip angles FL, FR, RL, RR (4, n) [rad] (ISO sign).
    first_lane_change_s : tuple of float
        Window of the first lane change (first roll peak), [s].
    manoeuvre_s : tuple of float
        Window of the whole manoeuvre (RMS roll rate, tyre lift-off), [s].
    """

    t_s: np.ndarray
    speed_mps: float
    steer_rad: np.ndarray
    slip_angle_rad: np.ndarray
    first_lane_change_s: tuple[float, float]
    manoeuvre_s: tuple[float, float]

    def __post_init__(self) -> None:
        """Check shapes, uniform time and finite values (ValueError naming the field)."""
        t = np.asarray(self.t_s, dtype=float)
        if t.ndim != 1 or t.size < 3:
            raise ValueError('HandlingInputs.t_s must be 1-D with at least 3 samples')
        dt = np.diff(t)
        if np.any(dt <= 0) or not np.allclose(dt, dt[0], rtol=1e-6, atol=1e-12):
            raise ValueError('HandlingInputs.t_s must be uniform and increasing')
        steer = np.asarray(self.steer_rad, dtype=float)
        slip = np.asarray(self.slip_angle_rad, dtype=float)
        if steer.shape != t.shape:
            raise ValueError(f'steer_rad must have shape {t.shape}, got {steer.shape}')
        if slip.shape != (4,) + t.shape:
            raise ValueError(f'slip_angle_rad must have shape (4, {t.size}), got {slip.shape}')
        for name, arr in (('t_s', t), ('steer_rad', steer), ('slip_angle_rad', slip)):
            if not np.all(np.isfinite(arr)):
                raise ValueError(f'HandlingInputs.{name} contains NaN or inf')
        if not (np.isfinite(self.speed_mps) and self.speed_mps > 0):
            raise ValueError(f'speed_mps must be positive, got {self.speed_mps}')
        for name in ('first_lane_change_s', 'manoeuvre_s'):
            w = tuple(float(v) for v in getattr(self, name))
            if len(w) != 2 or not w[0] < w[1]:
                raise ValueError(f'HandlingInputs.{name} must be (start, end), got {w}')
            object.__setattr__(self, name, w)
        object.__setattr__(self, 't_s', t)
        object.__setattr__(self, 'steer_rad', steer)
        object.__setattr__(self, 'slip_angle_rad', slip)

    @property
    def dt_s(self) -> float:
        """Sample interval [s]."""
        return float(self.t_s[1] - self.t_s[0])


@dataclass
class HandlingRecord:
    """Handling-model outputs at the input sample times (leading design axis)."""

    t_s: np.ndarray
    roll_rad: np.ndarray
    roll_rate_radps: np.ndarray
    lateral_accel_mps2: np.ndarray
    tyre_fz_n: np.ndarray  # (batch, 4, n)
    tyre_fy_n: np.ndarray  # (batch, 4, n)


class HandlingModel:
    """Batched roll/yaw/lateral handling model (eqs. 12-14).

    Parameters
    ----------
    params : VehicleParams, optional
        Vehicle parameters (default config/*.yaml).
    options : dict, optional
        Overrides of config/simplified_models.yaml ``handling`` (time_step_s,
        slip_angles, roll_moment_arm, gravity_roll_moment, anti_roll_bar).
    """

    def __init__(
        self, params: VehicleParams | None = None, options: dict[str, Any] | None = None
    ) -> None:
        self.params = params if params is not None else load_vehicle_params()
        opt = dict(load_simplified_config()['handling'])
        opt.update(options or {})
        self.dt_s = float(opt['time_step_s'])
        if opt['slip_angles'] not in SLIP_SOURCES:
            raise ValueError(
                f'slip_angles must be one of {SLIP_SOURCES}, got {opt["slip_angles"]!r}'
            )
        if opt['roll_moment_arm'] not in ROLL_ARMS:
            raise ValueError(
                f'roll_moment_arm must be one of {ROLL_ARMS}, got {opt["roll_moment_arm"]!r}'
            )
        self.options = opt
        self.soft_load_fraction = float(
            load_simplified_config()['tyre_hop_gradient']['load_fraction'])
        p = self.params
        self.roll_arm_m = p.cg_height_m
        if opt['roll_moment_arm'] == 'roll_axis':
            h_rc = (p.roll_centre_front_m * p.b_m + p.roll_centre_rear_m * p.a_m) / p.wheelbase_m
            self.roll_arm_m = p.cg_height_m - h_rc
        f_s, r_s = p.static_strut_load_front_n, p.static_strut_load_rear_n
        extra = [
            p.g_mps2,
            p.a_m,
            p.b_m,
            p.mass_sprung_kg,
            p.mass_total_kg,
            p.i_roll_sprung_kgm2,
            p.i_yaw_total_kgm2,
            self.roll_arm_m,
            0.5 * p.strut_track_m,
            0.0,  # speed, set per run
            f_s / (f_s + r_s),
            r_s / (f_s + r_s),
            0.5 * p.mass_axle_front_kg * p.g_mps2,
            0.5 * p.mass_axle_rear_kg * p.g_mps2,
            1.0 if opt['gravity_roll_moment'] else 0.0,
            1.0 if opt['slip_angles'] == 'own' else 0.0,
        ]
        self._P = np.concatenate([strut_block(p), extra])
        sp = p.strut
        self._dk = np.ascontiguousarray(sp.damper_velocity_mps)
        self._dv = np.ascontiguousarray(sp.damper_force_n)
        self._ds = np.ascontiguousarray(strut_mod.damper_knot_slopes(sp))
        self._pc = np.ascontiguousarray(p.tyre.pacejka)

    def simulate(self, settings: AxleSettings, inputs: HandlingInputs) -> HandlingRecord:
        """Run every design of ``settings`` (handling valve state) with the given inputs.

        RK4 with the largest step not above ``time_step_s`` that is the input interval or
        an even multiple ``m`` of it.  The inputs at the half steps are then the input
        samples themselves (``m`` even) or linear interpolations (midpoint averages,
        ``m = 1``); outputs come at the step times.  The run stops two steps after the
        manoeuvre window, the last time any metric uses.
        """
        if not isinstance(inputs, HandlingInputs):
            raise ValueError(f'inputs must be HandlingInputs, got {type(inputs).__name__}')
        ss = axle_strut_states(settings.for_mode('handling'), self.params,
                               vehicle_bars=self.options['anti_roll_bar'])
        b = ss.shape[0]
        m = int(np.floor(self.dt_s / inputs.dt_s * (1.0 + 1e-9)))
        if m > 1 and m % 2:
            m -= 1
        m = max(m, 1)
        dt = m * inputs.dt_s
        # the metrics end with the manoeuvre window: stop two steps after it
        n_all = int(np.searchsorted(inputs.t_s, inputs.manoeuvre_s[1] + 2.0 * dt)) + 1
        n_all = min(max(n_all, 3), inputs.t_s.size)
        t_in = inputs.t_s[:n_all]
        if m == 1:
            slip = _half_steps(inputs.slip_angle_rad[:, :n_all])
            steer = _half_steps(inputs.steer_rad[None, :n_all])[0]
            t_out = t_in[:-1]
        else:
            n_in = (n_all - 1) // m * m + 1
            slip = np.ascontiguousarray(inputs.slip_angle_rad[:, : n_in : m // 2])
            steer = np.ascontiguousarray(inputs.steer_rad[: n_in : m // 2])
            t_out = t_in[: n_in - 1 : m]
        n = t_out.size
        P = self._P.copy()
        P[SK.HP_U] = inputs.speed_mps
        states = np.zeros((b, SK.N_H_STATE))
        out = np.empty((b, n, SK.N_H_OUT))
        SK.h_integrate(
            states, ss, P, self._dk, self._dv, self._ds, self._pc, slip, steer,
            dt, n, out,
        )  # fmt: skip
        if not np.all(np.isfinite(out)):
            raise RuntimeError('handling-model integration diverged (non-finite outputs)')
        out = out.transpose(0, 2, 1)  # (batch, channel, time) views
        return HandlingRecord(
            t_s=t_out,
            roll_rad=out[:, SK.OH_ROLL],
            roll_rate_radps=out[:, SK.OH_ROLL_RATE],
            lateral_accel_mps2=out[:, SK.OH_AY],
            tyre_fz_n=out[:, SK.OH_FZ0 : SK.OH_FZ0 + 4],
            tyre_fy_n=out[:, SK.OH_FY0 : SK.OH_FY0 + 4],
        )

    def evaluate(
        self, x: np.ndarray, n_vars: int, inputs: HandlingInputs,
        space: DesignSpace | None = None,
    ) -> dict[str, np.ndarray]:
        """Objective eq. 10 and constraints eq. 11 for normalised designs.

        ``space``: the design space (default config/design_space.yaml).

        Returns
        -------
        dict
            'f' (batch,), 'g' (batch, 4) FL, FR, RL, RR, 'roll_first_peak_deg',
            'roll_rate_rms_deg_s' (batch,).
        """
        xb = validate_design(x, n_vars)
        return self.evaluate_settings(to_physical(xb, n_vars, space), inputs)

    def evaluate_settings(self, settings: AxleSettings, inputs: HandlingInputs
                          ) -> dict[str, np.ndarray]:
        """Eqs. 10 and 11 of physical settings (:meth:`evaluate` without the design map)."""
        rec = self.simulate(settings, inputs)
        p = self.params
        static = np.array([p.static_tyre_load_front_n, p.static_tyre_load_front_n,
                           p.static_tyre_load_rear_n, p.static_tyre_load_rear_n])
        return handling_metrics(rec, inputs, static, self.soft_load_fraction)


def _half_steps(a: np.ndarray) -> np.ndarray:
    """Samples (k, n) -> (k, 2n - 1) at half steps (linear interpolation)."""
    a = np.asarray(a, dtype=float)
    out = np.empty((a.shape[0], 2 * a.shape[1] - 1))
    out[:, 0::2] = a
    out[:, 1::2] = 0.5 * (a[:, :-1] + a[:, 1:])
    return np.ascontiguousarray(out)


def handling_metrics(rec: HandlingRecord, inputs: HandlingInputs,
                     static_load_n: np.ndarray | None = None,
                     load_fraction: float | None = None) -> dict[str, np.ndarray]:
    """Eq. 10 and eq. 11 of a handling record, with the full model's metric windows.

    With the static wheel loads (FL, FR, RL, RR, N) and a load fraction, also 'g_soft':
    :func:`~suspension_tuning.vehicle.metrics.soft_tyre_hop_constraints` over the
    manoeuvre, the tyre-hop measure for gradients.
    """
    t = rec.t_s
    roll_deg = np.degrees(rec.roll_rad)
    rate_deg = np.degrees(rec.roll_rate_radps)
    peak = first_peak(roll_deg, t, inputs.first_lane_change_s)
    rate_rms = roll_rate_rms(rate_deg, t, inputs.manoeuvre_s)
    in_man = (t >= inputs.manoeuvre_s[0]) & (t <= inputs.manoeuvre_s[1])
    if not in_man.any():
        raise ValueError('manoeuvre window contains no samples')
    lift = rec.tyre_fz_n[..., in_man] <= FZ_CONTACT_THRESHOLD_N
    g = 10.0 * (lift.mean(axis=-1) - 0.1)
    out = {
        'f': np.atleast_1d(f_hand(rate_rms, peak)),
        'g': g,
        'roll_first_peak_deg': np.atleast_1d(peak),
        'roll_rate_rms_deg_s': np.atleast_1d(rate_rms),
    }
    if static_load_n is not None and load_fraction is not None:
        out['g_soft'] = soft_tyre_hop_constraints(rec.tyre_fz_n[..., in_man], static_load_n,
                                                  load_fraction)
    return out


def derivative_numpy(
    state: np.ndarray,
    settings: AxleSettings,
    slip_rad: np.ndarray,
    steer_rad: float,
    speed_mps: float,
    model: HandlingModel,
) -> np.ndarray:
    """Plain numpy reference of eqs. 12-14 on ``strut.strut_force`` and
    ``tyre.pacejka89_lateral`` (same options as ``model``).

    Parameters
    ----------
    state : np.ndarray
        (batch, 6): y, psi, v, r, phi, phi' [m, rad, m/s, rad/s, rad, rad/s].
    settings : AxleSettings
        Physical design (batch,).
    slip_rad : np.ndarray
        (4,) input slip angles FL, FR, RL, RR [rad].
    steer_rad, speed_mps : float
        Road-wheel steer angle [rad] and forward speed [m/s].
    model : HandlingModel
        Supplies parameters and options.

    Returns
    -------
    np.ndarray
        State derivative (batch, 6).
    """  # noqa: D205
    p = model.params
    s = np.asarray(state, dtype=float)
    y, psi, v, r, phi, phid = s.T
    ts2 = 0.5 * p.strut_track_m
    f_s, r_s = p.static_strut_load_front_n, p.static_strut_load_rear_n

    settings = settings.for_mode('handling')
    coil = settings.spring_quantity == 'stiffness'

    def sf(x, xd, axle, load):
        spring = settings.spring(axle)
        return strut_mod.strut_force(x, xd, None if coil else spring, settings.dpsf(axle),
                                     load, p, spring if coil else None,
                                     settings.dpsf_rebound(axle))

    xl, xld = -ts2 * phi, -ts2 * phid
    f_fl = sf(xl, xld, 'front', f_s)
    f_fr = sf(-xl, -xld, 'front', f_s)
    f_rl = sf(xl, xld, 'rear', r_s)
    f_rr = sf(-xl, -xld, 'rear', r_s)
    fl, fr = f_fl + f_rl, f_fr + f_rr
    shf, shr = f_s / (f_s + r_s), r_s / (f_s + r_s)
    waf, war = 0.5 * p.mass_axle_front_kg * p.g_mps2, 0.5 * p.mass_axle_rear_kg * p.g_mps2
    fz = np.stack([shf * fl + waf, shf * fr + waf, shr * fl + war, shr * fr + war])
    if model.options['slip_angles'] == 'own':
        af = np.arctan2(v + p.a_m * r, speed_mps) - steer_rad
        ar = np.arctan2(v - p.b_m * r, speed_mps)
        alpha = np.stack([af, af, ar, ar])
    else:
        alpha = np.broadcast_to(np.asarray(slip_rad, dtype=float)[:, None], fz.shape)
    fy = pacejka89_lateral(alpha, fz, p.tyre.pacejka)
    ay = fy.sum(0) / p.mass_total_kg
    rd = (p.a_m * (fy[0] + fy[1]) - p.b_m * (fy[2] + fy[3])) / p.i_yaw_total_kgm2
    mx = (fl - fr) * ts2 + model.roll_arm_m * fy.sum(0) * p.mass_sprung_kg / p.mass_total_kg
    if model.options['gravity_roll_moment']:
        mx = mx + p.mass_sprung_kg * p.g_mps2 * model.roll_arm_m * np.sin(phi)
    bars = axle_bars_nm_per_rad(settings, p, model.options['anti_roll_bar'])
    mx = mx - (bars[:, 0] + bars[:, 1]) * phi
    return np.stack(
        [
            speed_mps * np.sin(psi) + v * np.cos(psi),
            r,
            ay - speed_mps * r,
            rd,
            phid,
            mx / p.i_roll_sprung_kgm2,
        ],
        axis=1,
    )
