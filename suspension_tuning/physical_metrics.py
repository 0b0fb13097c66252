"""The physical metrics every report shows beside f and g (no rclpy).

f and g are normalised (eqs. 9-11); what a user wants to know is how much better the
ride got in m/s^2, how many degrees the body rolls and how long each tyre is off the
ground.  The simulation workers return these as named metrics with every answer
(:data:`suspension_tuning.evaluation.METRIC_NAMES`); this module picks the ones a
report shows per scenario and names them with their units:

- ride: the BS 6841 W_b weighted RMS vertical acceleration at each seat, m/s^2 (the
  quantities of eq. 9);
- handling: the first roll peak in the first lane change, deg, and the RMS roll rate
  over the manoeuvre, deg/s (the quantities of eq. 10);
- both: the time each tyre is off the ground, % of the metric window (eq. 11);
- mixed (a recorded closed-loop run, ``tune --evaluate``): the seats' W_b RMS over the
  rough road and the roll metrics of the lane change.

The Optimise action's result, ``tune``, ``inspect_bag``, the demo and the plots show
them for the baseline design (config/design_space.yaml) and the reported design.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

TYRES = ('fl', 'fr', 'rl', 'rr')

#: Per scenario: (the worker's metric name, the shown name, factor to the shown unit).
SHOWN: dict[str, tuple[tuple[str, str, float], ...]] = {
    'ride': (('a_rms_driver_mps2', 'a_rms_driver_mps2', 1.0),
             ('a_rms_passenger_mps2', 'a_rms_passenger_mps2', 1.0),
             *((f'tyre_lift_off_fraction_{t}', f'tyre_lift_off_pct_{t}', 100.0)
               for t in TYRES)),
    'handling': (('roll_first_peak_deg', 'roll_first_peak_deg', 1.0),
                 ('roll_rate_rms_deg_s', 'roll_rate_rms_deg_s', 1.0),
                 *((f'tyre_lift_off_fraction_{t}', f'tyre_lift_off_pct_{t}', 100.0)
                   for t in TYRES)),
    'mixed': (('a_rms_driver_mps2', 'a_rms_driver_mps2', 1.0),
              ('a_rms_passenger_mps2', 'a_rms_passenger_mps2', 1.0),
              ('roll_first_peak_deg', 'roll_first_peak_deg', 1.0),
              ('roll_rate_rms_deg_s', 'roll_rate_rms_deg_s', 1.0)),
}

#: What each shown metric is, and its unit, for text reports.
LABELS: dict[str, tuple[str, str]] = {
    'a_rms_driver_mps2': ('seat W_b RMS, driver', 'm/s^2'),
    'a_rms_passenger_mps2': ('seat W_b RMS, passenger', 'm/s^2'),
    'roll_first_peak_deg': ('first roll peak', 'deg'),
    'roll_rate_rms_deg_s': ('roll-rate RMS', 'deg/s'),
    **{f'tyre_lift_off_pct_{t}': (f'lift-off time {t.upper()}', '%') for t in TYRES},
}


def physical_metrics(scenario: str, names: Sequence[str],
                     values: Sequence[float] | Mapping[str, float]) -> dict[str, float]:
    """The shown metrics of ``scenario`` out of a worker's named metrics.

    Parameters
    ----------
    scenario : str
        'ride' or 'handling' (another scenario shows none).
    names : sequence of str
        The worker's metric names (``metric_names`` of its answer); ignored when
        ``values`` is a mapping.
    values : sequence of float or mapping
        Their values, in the order of ``names``, or name -> value.

    Returns
    -------
    dict
        Shown name (unit in the name: ``tyre_lift_off_pct_fl``) -> value in that unit;
        metrics the worker did not return are left out.
    """
    by_name = dict(values) if isinstance(values, Mapping) else dict(zip(names, values))
    return {shown: float(by_name[name]) * factor
            for name, shown, factor in SHOWN.get(scenario, ()) if name in by_name}


def metric_lines(baseline: Mapping[str, float], reported: Mapping[str, float],
                 reported_title: str = 'reported') -> list[str]:
    """A text table of the shown metrics: one line each, baseline and reported design.

    Metrics missing on one side show as '-'.
    """
    names = list(dict.fromkeys([*reported, *baseline]))
    if not names:
        return []
    texts = {n: '{} ({})'.format(*LABELS[n]) if n in LABELS else n for n in names}
    width = max(len(t) for t in texts.values()) + 2
    right = max(10, len(reported_title) + 2)

    def cell(values: Mapping[str, float], name: str, w: int) -> str:
        return f'{values[name]:>{w}.3f}' if name in values else f'{"-":>{w}}'

    lines = [f'  {"":<{width}}{"baseline":>10}{reported_title:>{right}}']
    lines += [f'  {texts[n]:<{width}}{cell(baseline, n, 10)}{cell(reported, n, right)}'
              for n in names]
    return lines
