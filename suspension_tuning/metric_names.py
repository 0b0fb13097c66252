"""Names of the metrics each scenario reports (units in the names), without the models.

:mod:`suspension_tuning.evaluation` flattens a run's metrics into these columns
(``metric_table``); :class:`suspension_tuning.tuning.ConstraintSpec` checks that an
extra constraint bounds one of them.  Kept apart from both so that neither imports the
other for the names.
"""

from __future__ import annotations

TYRES = ('fl', 'fr', 'rl', 'rr')


def _per_tyre(name: str) -> tuple[str, ...]:
    return tuple(f'{name}_{tyre}' for tyre in TYRES)


#: Metric names of each scenario as :func:`metric_table` flattens them (units in the
#: names; per-tyre metrics split into ``_fl`` .. ``_rr``, pairs into ``_0``, ``_1``).
#: What an extra constraint of the optimisation may bound (``tuning.ConstraintSpec``).
METRIC_NAMES: dict[str, tuple[str, ...]] = {
    'ride': ('a_rms_driver_mps2', 'a_rms_passenger_mps2', 'roll_rms_deg',
             'roll_rate_rms_deg_s', *_per_tyre('tyre_lift_off_fraction'),
             *_per_tyre('strut_stroke_max_m'), 'speed_mean_mps'),
    'handling': ('roll_first_peak_deg', 'roll_rate_rms_deg_s', 'roll_max_deg',
                 'lateral_accel_max_mps2', 'path_error_max_m', 'cone_violation_m',
                 'steer_max_deg', *_per_tyre('tyre_lift_off_fraction'), 'speed_min_mps',
                 't_first_lane_change_s_0', 't_first_lane_change_s_1', 't_manoeuvre_s_0',
                 't_manoeuvre_s_1'),
    'mixed': ('a_rms_driver_mps2', 'a_rms_passenger_mps2', 'roll_first_peak_deg',
              'roll_rate_rms_deg_s', 'valve_switches', 'handling_state_fraction',
              't_first_lane_change_s_0', 't_first_lane_change_s_1', 't_manoeuvre_s_0',
              't_manoeuvre_s_1'),
}
