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
from .design import AxleSettings
from .pitch_plane import (
    PitchPlaneModel,
    PitchPlaneRecord,
    axle_strut_states,
    static_tyre_deflections_m,
)


@dataclass
class RollPitchRecord(PitchPlaneRecord):
    """Outputs of a roll-and-pitch run at every integration step (leading design axis).

    A pitch-plane record (``t_s``, seat accelerations, heave, pitch) whose tyre and
    strut forces are per corner, FL, FR, RL, RR: ``tyre_fz_n`` and ``strut_force_n``
    (batch, 4, n) [N], ``road_m`` the road under each corner (4, n) [m]; and the body's
    roll ``roll_rad`` (left side up) (batch, n).
    """

    roll_rad: np.ndarray


class RollPitchModel(PitchPlaneModel):
    """Batched roll-and-pitch ride model on the ride scenario's two tracks.

    Same parameters as :class:`~.pitch_plane.PitchPlaneModel` (vehicle, ride setup, RK4
    step of config/simplified_models.yaml ``pitch_plane.time_step_s``); f and g come
    from the same rules (:func:`~.pitch_plane.ride_metrics`), g for each tyre.
    """

    def _model_parameters(self) -> list[float]:
        """The kernel's parameters after the strut block (``_simplified_kernel`` RP_*)."""
        p = self.params
        dstf, dstr = static_tyre_deflections_m(p)
        return [
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

    def static_tyre_loads_n(self) -> np.ndarray:
        """Static load of each tyre, FL, FR, RL, RR [N]."""
        front, rear = super().static_tyre_loads_n()
        return np.array([front, front, rear, rear])

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
        zc, zcd = self._road
        SK.rp_integrate(states, ss, self._P, self._dk, self._dv, self._ds, zc, zcd,
                        self.dt_s, self.n_steps, out)
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
            strut_force_n=out[:, SK.RO_FS0:SK.RO_FS0 + 4],
            road_m=zc[:, 0:-1:2],
            roll_rad=out[:, SK.RO_PHI],
        )
