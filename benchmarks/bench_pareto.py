"""What the 4S4 buys: the quick variant of ``study --pareto`` (2 variables, 4 eps values).

Run: ``.venv/bin/python benchmarks/bench_pareto.py [--n-vars 4] [--points 8]``.  Runs
:func:`suspension_tuning.studies.pareto.run_pareto` without bags into a temporary folder
and prints ``name: value`` lines.  With gap(f) = 100 (f - f_opt) / (f_baseline - f_opt),
the share of the achievable improvement (baseline vehicle to single-objective optimum)
that a design loses:

* passive_front_points: non-dominated interior points of the passive front;
* compromise_gap_ride_pct, compromise_gap_handling_pct: the best passive compromise
  (the front point whose larger gap is the smallest), ride and handling scenarios;
* mixed_closed_loop_ride_gap_pct, mixed_closed_loop_handling_gap_pct: the switched 4S4
  in the mixed closed-loop run (ride over the paving, handling over the lane change),
  against the passive single-objective optima and the baseline in the same run;
* mixed_one_period_delay_*: the same with a 10 ms valve delay (what the delay costs).
"""

import argparse
import tempfile
import time
from pathlib import Path

from suspension_tuning.studies.pareto import run_pareto


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--n-vars', type=int, default=2, choices=(2, 4))
    parser.add_argument('--points', type=int, default=4)
    args = parser.parse_args()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        study = run_pareto(Path(out), args.n_vars, args.points, bags=False,
                           log=lambda _: None)
    for name, value in study['figures'].items():
        print(f'{name}: {value:.2f}' if isinstance(value, float) else f'{name}: {value}')
    print(f'n_vars: {args.n_vars}')
    print(f"optimisation_runs: {len(study['runs'])}")
    print(f"full_model_runs: {sum(r['n_full_runs'] for r in study['runs'])}")
    print(f'wall_time_s: {time.perf_counter() - t0:.1f}')


if __name__ == '__main__':
    main()
