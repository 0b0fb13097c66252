"""Roll-and-pitch ride model: the pitch-plane model of section 6.2 with roll added.

The paper's ride model (:mod:`.pitch_plane`, eqs. 15-24) runs on the left/right average
of the road, so it cannot see what acts in roll: the anti-roll bars, and the difference
between a left and a right tyre's hop when the two tracks differ (eq. 11 is per tyre).
This model adds the body's roll and each beam axle's roll, seven degrees of freedom:
body heave ``z_s``, pitch ``theta`` (nose down positive) and roll ``phi`` (left side
up positive, about the body's own longitudinal axis), and per axle heave ``z_a`` and roll
``phi_a``.  It is the full model's vertical dynamics (``full_model``: the same 4S4
struts at +-strut_track/2, point-follower tyres at +-track/2 on each track's enveloped
road, a bar per axle as a torsional spring between body and axle) without what a ride on
a straight road barely uses: the body's torsion (one rigid body here), the roll axis and
lateral and yaw motion (no lateral forces, no pendulum moment).

Per corner (FL, FR, RL, RR), with ``y_s = +-strut_track/2`` and ``y_w = +-track/2``:

* strut stroke (compression positive) ``x = z_a + y_s phi_a - (z_s - x_a theta + y_s phi)``;
* tyre deflection ``d = delta_stat + z_road - (z_a + y_w phi_a)``, force eq. 19;
* body: ``m_b z_s'' = sum f - m_b g``, ``I_y theta'' = -sum x_a f``,
  ``I_x phi'' = sum y_s f - k_bf (phi - phi_af) - k_br (phi - phi_ar)``;
* axle: ``m_a z_a'' = sum F_t - sum f - m_a g``,
  ``I_a phi_a'' = sum y_w F_t - sum y_s f + k_b (phi - phi_a)``.

f (eq. 9, both seats at their lateral offsets) and g (eq. 11) are computed exactly as
for the full model, g for each of the four tyres.  RK4 at the pitch-plane model's step
(config/simplified_models.yaml), compiled (``_simplified_kernel.rp_integrate``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _simplified_kernel as SK  # noqa: N812
from . import strut as strut_mod
from .comfort import weighted_rms
from .design import AxleSettings, DesignSpace, to_physical, validate_design
from .metrics import f_ride, soft_tyre_hop_constraints, tyre_hop_constraints
from .params import VehicleParams, load_vehicle_params
from .pitch_plane import (
    RideSetup,
    axle_strut_states,
    load_simplified_config,
    static_tyre_deflections_m,
    strut_block,
)


@dataclass
class RollPitchRecord:
    """Outputs of a roll-and-pitch run at every integration step (leading design axis).

    Attributes
    ----------
    t_s : np.ndarray
        Times (n,) [s].
    acc_driver_mps2, acc_passenger_mps2 : np.ndarray
        Vertical seat accelerations (batch, n) [m/s^2].
    tyre_fz_n : np.ndarray
        Tyre vertical forces FL, FR, RL, RR (batch, 4, n) [N].
    heave_m, pitch_rad, roll_rad : np.ndarray
        Body heave (up), pitch (nose down) and roll (left side up) (batch, n).
    strut_force_n : np.ndarray
        Strut forces FL, FR, RL, RR (batch, 4, n) [N].
    """

    t_s: np.ndarray
    acc_driver_mps2: np.ndarray
    acc_passenger_mps2: np.ndarray
    tyre_fz_n: np.ndarray
    heave_m: np.ndarray
    pitch_rad: np.ndarray
    roll_rad: np.ndarray
    strut_force_n: np.ndarray

    @property
    def dt_s(self) -> float:
        """Time step [s]."""
        return float(self.t_s[1] - self.t_s[0])


class RollPitchModel:
    """Batched roll-and-pitch ride model on the ride scenario's two tracks.

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
        self.soft_load_fraction = float(config['tyre_hop_gradient']['load_fraction'])
        self.dt_s = float(dt_s if dt_s is not None else config['pitch_plane']['time_step_s'])
        if not np.isfinite(self.dt_s) or self.dt_s <= 0:
            raise ValueError(f'dt_s must be positive, got {self.dt_s}')
        p = self.params
        dstf, dstr = static_tyre_deflections_m(p)
        extra = [
            p.g_mps2,
            p.a_m,
            p.b_m,
            p.mass_sprung_kg,
            p.i_pitch_sprung_kgm2,
            p.i_roll_sprung_kgm2,
            p.mass_axle_front_kg,
            p.mass_axle_rear_kg,
            p.i_roll_axle_front_kgm2,
            p.i_roll_axle_rear_kgm2,
            p.tyre.vertical_stiffness_n_per_m,
            p.tyre.vertical_damping_ns_per_m,
            dstf,
            dstr,
            p.track_m / 2.0,
            p.strut_track_m / 2.0,
            p.driver_x_m,
            p.driver_y_m,
            p.passenger_x_m,
            p.passenger_y_m,
        ]
        self._P = np.ascontiguousarray(np.concatenate([strut_block(p), extra]))
        sp = p.strut
        self._dk = np.ascontiguousarray(sp.damper_velocity_mps)
        self._dv = np.ascontiguousarray(sp.damper_force_n)
        self._ds = np.ascontiguousarray(strut_mod.damper_knot_slopes(sp))
        self.n_steps = int(round(self.setup.duration_s / self.dt_s))
        if self.n_steps < 2:
            raise ValueError('ride duration shorter than two time steps')
        self._zc, self._zcd = self._road_arrays()

    def _road_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Road and its rate under each corner (FL, FR, RL, RR) at every half step."""
        st, p = self.setup, self.params
        t_half = np.arange(2 * self.n_steps + 1) * 0.5 * self.dt_s
        z = np.empty((4, t_half.size))
        zd = np.empty((4, t_half.size))
        for i in range(4):
            x = st.x0_cg_m + (p.a_m if i < 2 else -p.b_m) + st.speed_mps * t_half
            z[i], slope = st.road.elevation(x, i % 2)
            zd[i] = slope * st.speed_mps
        return np.ascontiguousarray(z), np.ascontiguousarray(zd)

    def simulate(self, settings: AxleSettings) -> RollPitchRecord:
        """Run every design of ``settings`` from static equilibrium over the ride road.

        Parameters
        ----------
        settings : AxleSettings
            The designs (batch,): the ride-mode gas volume and damping per axle, and the
            bars (the design's where it sets them, else config/vehicle.yaml's).

        Returns
        -------
        RollPitchRecord
            Outputs at every step.
        """
        ss = axle_strut_states(settings.for_mode('ride'), self.params, vehicle_bars=True)
        b = ss.shape[0]
        states = np.zeros((b, SK.N_RP_STATE))
        out = np.empty((b, self.n_steps, SK.N_RP_OUT))
        SK.rp_integrate(states, ss, self._P, self._dk, self._dv, self._ds, self._zc,
                        self._zcd, self.dt_s, self.n_steps, out)
        if not np.all(np.isfinite(out)):
            raise RuntimeError('roll-and-pitch integration diverged (non-finite outputs)')
        out = out.transpose(0, 2, 1)  # (batch, channel, time) views
        return RollPitchRecord(
            t_s=np.arange(self.n_steps) * self.dt_s,
            acc_driver_mps2=out[:, SK.RO_ACC_D],
            acc_passenger_mps2=out[:, SK.RO_ACC_P],
            tyre_fz_n=out[:, SK.RO_FZ0:SK.RO_FZ0 + 4],
            heave_m=out[:, SK.RO_ZS],
            pitch_rad=out[:, SK.RO_TH],
            roll_rad=out[:, SK.RO_PHI],
            strut_force_n=out[:, SK.RO_FS0:SK.RO_FS0 + 4],
        )

    def evaluate(self, x: np.ndarray, n_vars: int,
                 space: DesignSpace | None = None) -> dict[str, np.ndarray]:
        """Objective eq. 9 and constraints eq. 11 (per tyre) for normalised designs.

        Parameters
        ----------
        x : array_like
            Designs, shape (n_vars,) or (batch, n_vars), in [0.001, 1] (eqs. 5-8).
        n_vars : int
            The design space's size.
        space : DesignSpace, optional
            The design space (default config/design_space.yaml).

        Returns
        -------
        dict
            'f' (batch,), 'g' and 'g_soft' (batch, 4) in the order FL, FR, RL, RR, and
            'a_rms_driver_mps2', 'a_rms_passenger_mps2' (batch,).
        """
        xb = validate_design(x, n_vars)
        rec = self.simulate(to_physical(xb, n_vars, space))
        p = self.params
        static = np.array([p.static_tyre_load_front_n] * 2 + [p.static_tyre_load_rear_n] * 2)
        fs = 1.0 / rec.dt_s
        acc = np.stack([rec.acc_driver_mps2, rec.acc_passenger_mps2])
        a_d, a_p = np.atleast_2d(weighted_rms(acc, fs, self.setup.settle_s))
        keep = rec.t_s >= self.setup.settle_s
        fz = rec.tyre_fz_n[..., keep]
        return {
            'f': f_ride(a_d, a_p),
            'g': tyre_hop_constraints(fz, rec.dt_s),
            'g_soft': soft_tyre_hop_constraints(fz, static, self.soft_load_fraction),
            'a_rms_driver_mps2': a_d,
            'a_rms_passenger_mps2': a_p,
        }
