"""One passive setting for a set of operating conditions, against tuning per condition.

The engineer's question: what does a passive 4S4 setting tuned for every condition a
vehicle meets lose, per condition, against a setting tuned for that condition alone,
and what does switching between the 4S4's two valve states win back?  On the built-in
model, 4-variable ride (eq. 9 with the eq. 11 tyre-hop constraints), over the
conditions of config/conditions.yaml (or ``--conditions FILE``), in-process:

1. **Per condition**: Dynamic-Q with eq. 25-scaled simplified gradients on that
   condition alone (its own calibration and secant correction), from the 'centre' and
   'baseline' starts, the better reported design kept.
2. **Set-tuned passive**: the same over the whole set, worst case (min-max in epigraph
   form, :func:`suspension_tuning.tuning.optimise_conditions`).
3. **Switched 4S4**: the two valve states each tuned over the conditions it serves, and
   the valves choosing the state by the condition: by default the load (state 1 over
   the unladen conditions, state 2 over the laden ones; ``--switch-by speed`` splits at
   50 km/h instead).  A condition's values are those of its state's setting.
4. **Tuned at one point**: the per-condition optimum of the single condition of
   config/scenarios.yaml (50 km/h unladen, the paper's point), driven in every
   condition.

Every design then runs in every condition (full model): f, seat W_b RMS (driver,
passenger, m/s^2) and the largest lift-off time of a tyre (%, eq. 11 allows 10 %).
Loss = value minus the per-condition optimum's, in the value's unit.

Run: ``.venv/bin/python -m suspension_tuning.studies.conditions_study [--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

N_VARS = 4
SINGLE_POINT = 'unladen_50'


def _optimise(conditions: Any, gradients: dict[str, Any], form: str,
              starts: list[tuple[str, np.ndarray]]) -> dict[str, Any]:
    from suspension_tuning.evaluation import in_process_condition_model
    from suspension_tuning.studies.common import vehicle_options
    from suspension_tuning.tuning import TuningRequest, optimise_conditions, with_noise_levels

    options = with_noise_levels(vehicle_options(), 'ride', 'fixed_step')
    best = None
    for name, x0 in starts:
        request = TuningRequest('ride', N_VARS, x0, 'simplified', options,
                                conditions=conditions.as_text(), condition_form=form)
        r = optimise_conditions(request, in_process_condition_model(),
                                {c: gradients[c] for c in conditions.names})
        if 'x_best' not in r:
            continue
        key = (not r.best_feasible, float(r.f_best))
        if best is None or key < best[0]:
            best = (key, {'x': np.asarray(r.x_best).tolist(), 'f': float(r.f_best),
                          'feasible': bool(r.best_feasible), 'start': name,
                          'full_runs': int(r.n_full_runs), 'iterations': int(r.nit)})
    assert best is not None
    return best[1]


def _table_row(values: dict[str, float]) -> dict[str, float]:
    lift = [values[f'tyre_lift_off_fraction_{t}'] for t in ('fl', 'fr', 'rl', 'rr')]
    return {'a_driver': values['a_rms_driver_mps2'], 'a_passenger': values['a_rms_passenger_mps2'],
            'lift_off_max_pct': 100.0 * max(lift)}


def run_study(conditions: Any, switch_by: str = 'load', log=print) -> dict[str, Any]:
    """Run the study (see the module docstring); the designs and the per-condition table."""
    from suspension_tuning.conditions import ConditionSet
    from suspension_tuning.evaluation import (
        in_process_condition_gradients,
        in_process_condition_model,
    )
    from suspension_tuning.studies.common import start_point
    from suspension_tuning.tuning import RunCounter, _ConditionTerms
    from suspension_tuning.vehicle.design import load_design_space

    t0 = time.perf_counter()
    starts = [(name, start_point(name, N_VARS)) for name in ('centre', 'baseline')]
    gradients = in_process_condition_gradients(conditions, N_VARS)
    designs: dict[str, Any] = {}
    for condition in conditions.conditions:
        one = ConditionSet((condition,), condition.name)
        designs[f'own:{condition.name}'] = _optimise(one, gradients, 'mean', starts)
        log(f'# tuned for {condition.name} alone: f {designs[f"own:{condition.name}"]["f"]:.5f}')
    designs['set'] = _optimise(conditions, gradients, 'worst', starts)
    log(f'# tuned for the set (worst case): f {designs["set"]["f"]:.5f}')
    if switch_by == 'load':
        groups = {'state1': [c for c in conditions.conditions if c.payload_kg == 0.0],
                  'state2': [c for c in conditions.conditions if c.payload_kg > 0.0]}
    else:
        groups = {'state1': [c for c in conditions.conditions if c.speed_kmh <= 50.0],
                  'state2': [c for c in conditions.conditions if c.speed_kmh > 50.0]}
    state_of: dict[str, str] = {}
    for state, members in groups.items():
        if not members:
            continue
        subset = ConditionSet(tuple(members), state)
        designs[state] = _optimise(subset, gradients, 'worst', starts)
        state_of.update({c.name: state for c in members})
        log(f'# switched {state} ({", ".join(subset.names)}): f {designs[state]["f"]:.5f}')
    terms = _ConditionTerms(in_process_condition_model(), conditions.conditions, RunCounter())
    baseline_x = load_design_space().baseline_x(N_VARS)
    rows = []
    single = f'own:{SINGLE_POINT}'
    for c, condition in enumerate(conditions.conditions):
        def values(x: Any, c: int = c) -> dict[str, float]:
            f, g, metrics = terms.at(np.asarray(x, float))
            return {'f': float(f[c]), 'max_g': float(np.max(g[c])), **_table_row(metrics[c])}

        row = {'condition': condition.name,
               'baseline': values(baseline_x),
               'own': values(designs[f'own:{condition.name}']['x']),
               'set': values(designs['set']['x']),
               'switched': values(designs[state_of[condition.name]]['x'])
               if condition.name in state_of else None,
               'switched_state': state_of.get(condition.name, '')}
        if single in designs:
            row['single_point'] = values(designs[single]['x'])
        rows.append(row)
    return {'designs': designs, 'rows': rows, 'switch_by': switch_by,
            'conditions': conditions.as_dict(), 'wall_time_s': time.perf_counter() - t0}


def markdown(study: dict[str, Any]) -> str:
    """The study's table: per condition, each design's f and seat W_b RMS, and losses."""
    cols = [('baseline', 'baseline'), ('own', 'tuned for it'),
            ('single_point', f'tuned at {SINGLE_POINT}'), ('set', 'set-tuned passive'),
            ('switched', 'switched 4S4')]
    cols = [(k, t) for k, t in cols if any(r.get(k) for r in study['rows'])]
    head = '| condition | ' + ' | '.join(t for _, t in cols) + ' |'
    lines = ['f_ride (eq. 9) and seat W_b RMS driver / passenger [m/s^2]; largest lift-off '
             'time of a tyre [%]:', '', head, '|---|' + '---|' * len(cols)]
    for r in study['rows']:
        cells = []
        for key, _ in cols:
            v = r.get(key)
            cells.append('-' if not v else
                         f"{v['f']:.4f}; {v['a_driver']:.3f} / {v['a_passenger']:.3f}; "
                         f"{v['lift_off_max_pct']:.1f} %")
        lines.append(f"| {r['condition']} | " + ' | '.join(cells) + ' |')
    lines += ['', 'Loss against the setting tuned for the condition (f; driver, passenger '
              'W_b RMS in m/s^2):', '',
              '| condition | ' + ' | '.join(t for k, t in cols if k not in ('own',)) + ' |',
              '|---|' + '---|' * (len(cols) - 1)]
    for r in study['rows']:
        own = r['own']
        cells = []
        for key, _ in cols:
            if key == 'own':
                continue
            v = r.get(key)
            cells.append('-' if not v else
                         f"{v['f'] - own['f']:+.4f}; {v['a_driver'] - own['a_driver']:+.3f}, "
                         f"{v['a_passenger'] - own['a_passenger']:+.3f}")
        lines.append(f"| {r['condition']} | " + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the study; print the table and figure lines; write JSON and markdown."""
    from suspension_tuning.conditions import load_conditions

    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--conditions', default=None, help='condition file '
                        '(default config/conditions.yaml)')
    parser.add_argument('--switch-by', choices=('load', 'speed'), default='load')
    parser.add_argument('--out', default='study_conditions')
    args = parser.parse_args(argv)
    conditions = load_conditions(args.conditions)
    study = run_study(conditions, args.switch_by, log=lambda s: print(s, flush=True))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / 'conditions_study.json').write_text(json.dumps(study, indent=1) + '\n')
    table = markdown(study)
    (out / 'conditions_study.md').write_text(table + '\n')
    print(table)
    rows = study['rows']
    set_loss = max(r['set']['f'] - r['own']['f'] for r in rows)
    print(f'conditions_study_set_worst_f: {study["designs"]["set"]["f"]:.5f}')
    print(f'conditions_study_set_largest_f_loss: {set_loss:.5f}')
    if all(r['switched'] for r in rows):
        print('conditions_study_switched_largest_f_loss: '
              f"{max(r['switched']['f'] - r['own']['f'] for r in rows):.5f}")
    print(f"conditions_study_wall_time_s: {study['wall_time_s']:.1f}")
    return 0


if __name__ == '__main__':
    sys.exit(main())
