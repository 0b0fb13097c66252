"""Benchmark of tuning over a set of operating conditions: the 4-variable ride over 6.

The case: the ride (eq. 9 with the eq. 11 tyre-hop constraints in every condition) over
the 6 conditions of config/conditions.yaml (30, 50 and 70 km/h, unladen and with the
full 650 kg payload on the load floor, Belgian paving), worst-case form: minimise the
largest per-condition f_ride, posed for Dynamic-Q in epigraph form
(``suspension_tuning.tuning.optimise_conditions``).

What it runs from the 6 benchmark starts of bench_method.py
(``method_benchmark.benchmark_starts(4)``: 'baseline', 'centre' and 4 seeded
Latin-hypercube points): Dynamic-Q with simplified gradients, each condition's
pitch-plane model with the calibration a tuning goal spends by default (the
coordinator's ``calibration_samples`` -1: config/simplified_models.yaml
``scaling.run_samples``, none on the 4-variable ride, unit scaling; ``--calibration-samples
N`` for N eq. 25 samples per condition, shared by the starts and cached) and corrected by
a secant correction of its own; the Dynamic-Q options of config/optimiser.yaml
``vehicle`` with the built-in ride model's noise levels.

Figures:

* ``conditions_ride4_starts_solved``: starts whose reported design is within 1 % of the
  reference's worst-case f and has max g <= 0.005 in every condition (bench_method.py's
  definition of solved), of 6.
* ``conditions_ride4_starts_feasible_at_check``: starts whose answer is feasible when run
  again in every condition at the tighter solver tolerance (config/vehicle.yaml
  ``integration.check``; max g <= its gtol), of 6.
* ``conditions_ride4_median_paid_full_runs``: every full run a start pays, counted per
  condition (a design in 6 conditions is 6 condition-runs), the check of its answer
  included (6 condition-runs, one round), with the calibration's runs (all N x 6, as a
  user's first run pays them; none by default), median over the starts;
  ``..._rounds``: the same in rounds, the sequential batches with 6 workers (a design's 6
  conditions are one round, N samples per condition N rounds).
* ``conditions_speedup_2_workers``: wall time of evaluating designs in the 6 conditions
  with 1 worker process over that with 2 (``concurrent.futures`` processes, one numba
  thread each, the condition-runs shared as the pool shares a batch: ``--speedup-designs``
  of the 6 starts, default all 6, each in every condition; the least of 3 timings).

The reference is in benchmarks/references.json (``condition_cases``:
``ride_4var_conditions_worst``),
written by ``.venv/bin/python benchmarks/bench_conditions.py --write-reference``: the
best feasible worst-case design (max g <= 1e-3 in every condition) among a 5^4 grid of
the normalised box, Dynamic-Q with full-model gradients from the 'baseline' and
'centre' starts and Dynamic-Q with simplified gradients from the 6 starts, then
polished by SciPy SLSQP on the epigraph form (kept when it finds a lower feasible f).

Run: .venv/bin/python benchmarks/bench_conditions.py [--starts K] [--write-reference]
[--speedup-designs M] [--speedup-only] [--calibration-samples N]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

REFERENCES = Path(__file__).with_name('references.json')
CASE = 'ride_4var_conditions_worst'
COMMAND = '.venv/bin/python benchmarks/bench_conditions.py --write-reference'
N_VARS = 4
SOLVED_GAP_PCT = 1.0  # bench_method.py's definition (method_benchmark.SOLVED_GAP_PCT)
SOLVED_VIOLATION = 0.005
REFERENCE_GTOL = 1e-3
GRID_POINTS = 5  # per variable of the reference search's grid
REPEATS = 3  # timings of the speed-up, the least kept


def _options() -> dict:
    from suspension_tuning.studies.common import vehicle_options
    from suspension_tuning.tuning import with_noise_levels

    return with_noise_levels(vehicle_options(), 'ride', 'fixed_step')


def _run(start: np.ndarray, conditions, gradients, source: str, maxiter: int | None = None,
         check: bool = False):
    """One start; ``check``: the answer checked at the tighter tolerance (C paid runs)."""
    from suspension_tuning.answer_check import check_condition_options
    from suspension_tuning.evaluation import in_process_condition_model
    from suspension_tuning.tuning import TuningRequest, optimise_conditions

    options = _options()
    if maxiter:
        options['maxiter'] = maxiter
    request = TuningRequest('ride', N_VARS, start, source, options,
                            conditions=conditions.as_text(), condition_form='worst')
    return optimise_conditions(request, in_process_condition_model(),
                               gradients if source == 'simplified' else None,
                               **(check_condition_options('ride', N_VARS) if check else {}))


def _worst(x: np.ndarray, conditions) -> tuple[float, float]:
    from suspension_tuning.evaluation import in_process_condition_model
    from suspension_tuning.tuning import RunCounter, _ConditionTerms

    f, g, _ = _ConditionTerms(in_process_condition_model(), conditions.conditions,
                              RunCounter()).at(np.asarray(x, float))
    return float(np.max(f)), float(max(0.0, np.max(g)))


def write_reference(conditions, gradients) -> dict:
    """Search the reference once (see the module docstring) and store it."""
    from scipy.optimize import minimize

    from suspension_tuning.evaluation import in_process_condition_model
    from suspension_tuning.studies.method_benchmark import benchmark_starts
    from suspension_tuning.tuning import RunCounter, _ConditionTerms

    candidates = []
    for name, x0 in benchmark_starts(N_VARS):
        sources = ('simplified', 'full') if name in ('baseline', 'centre') else ('simplified',)
        for source in sources:
            r = _run(x0, conditions, gradients, source)
            if 'x_best' in r and r.best_feasible:
                candidates.append((float(r.f_best), np.asarray(r.x_best), f'{source} {name}'))
                print(f'# {source} from {name}: f {r.f_best:.5f}', flush=True)
    terms = _ConditionTerms(in_process_condition_model(), conditions.conditions, RunCounter())
    axis = np.linspace(0.001, 1.0, GRID_POINTS)
    grid = np.stack(np.meshgrid(*[axis] * N_VARS, indexing='ij'), -1).reshape(-1, N_VARS)
    f_grid, g_grid, _ = terms.batch(grid)
    worst_grid = f_grid.max(axis=1)
    feasible = g_grid.reshape(len(grid), -1).max(axis=1) <= REFERENCE_GTOL
    if feasible.any():
        k = int(np.argmin(np.where(feasible, worst_grid, np.inf)))
        candidates.append((float(worst_grid[k]), grid[k], f'grid {GRID_POINTS}^{N_VARS}'))
        print(f'# grid {GRID_POINTS}^{N_VARS}: best feasible f {worst_grid[k]:.5f}', flush=True)
    f0, x0, how = min(candidates, key=lambda c: c[0])
    n_c = len(conditions)

    def fg(z):
        f, g, _ = terms.at(np.clip(z[:N_VARS], 0.001, 1.0))
        return f, g.reshape(-1)

    cons = [{'type': 'ineq', 'fun': lambda z: z[N_VARS] - fg(z)[0]},
            {'type': 'ineq', 'fun': lambda z: -fg(z)[1]}]
    z0 = np.r_[x0, f0]
    polish = minimize(lambda z: z[N_VARS], z0, method='SLSQP', constraints=cons,
                      bounds=[(0.001, 1.0)] * N_VARS + [(None, None)],
                      options={'maxiter': 15, 'ftol': 1e-6})
    best_x, best_f, best_how = x0, f0, how
    f_p, v_p = _worst(polish.x[:N_VARS], conditions)
    if v_p <= REFERENCE_GTOL and f_p < best_f:
        best_x, best_f, best_how = np.clip(polish.x[:N_VARS], 0.001, 1.0), f_p, how + ' + SLSQP'
    entry = {'scenario': 'ride', 'n_vars': N_VARS, 'form': 'worst',
             'conditions': conditions.as_dict(), 'x': best_x.tolist(), 'f': best_f,
             'found_by': best_how, 'command': COMMAND, 'feasibility_gtol': REFERENCE_GTOL,
             'condition_count': n_c}
    data = json.loads(REFERENCES.read_text())
    data.setdefault('condition_cases', {})[CASE] = entry
    REFERENCES.write_text(json.dumps(data, indent=1) + '\n')
    return entry


def _evaluate_chunk(args):
    designs, condition_texts = args
    from suspension_tuning.evaluation import evaluate

    return [float(evaluate('ride', designs, condition=text).f[0]) for text in condition_texts]


def _init_worker():
    os.environ['NUMBA_NUM_THREADS'] = '1'


def speedup(conditions, m: int) -> tuple[float, float, float]:
    """Wall time of m designs x C conditions on 1 and on 2 worker processes."""
    from suspension_tuning.studies.method_benchmark import benchmark_starts

    designs = [x for _, x in benchmark_starts(N_VARS)][:m]
    jobs = [(np.asarray(x)[None, :], [c.as_text()]) for x in designs
            for c in conditions.conditions]
    times = {}
    for workers in (1, 2):
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context('spawn'),
                                 initializer=_init_worker) as pool:
            list(pool.map(_evaluate_chunk, jobs[:2 * workers]))  # compile, warm each worker
            best = np.inf
            for _ in range(REPEATS):  # the least of REPEATS: the machine is shared
                t = time.perf_counter()
                list(pool.map(_evaluate_chunk, jobs))
                best = min(best, time.perf_counter() - t)
            times[workers] = best
    return times[1], times[2], times[1] / times[2]


def main(argv: list[str] | None = None) -> int:
    """Print the benchmark's ``name: value`` lines."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--starts', type=int, default=6, help='how many of the 6 starts')
    parser.add_argument('--write-reference', action='store_true')
    parser.add_argument('--calibration-samples', type=int, default=-1, metavar='N',
                        help='eq. 25 samples per condition (0: none; default -1: what a '
                        'tuning goal spends, config/simplified_models.yaml '
                        'scaling.run_samples)')
    parser.add_argument('--speedup-only', action='store_true',
                        help='only the 1- vs 2-worker timing')
    parser.add_argument('--speedup-designs', type=int, default=6,
                        help='designs of the 1- vs 2-worker timing, 1-6: the first M '
                             'starts, each in every condition')
    args = parser.parse_args(argv)
    if not 1 <= args.speedup_designs <= 6:
        parser.error(f'--speedup-designs takes 1 to 6 (the starts), got {args.speedup_designs}')
    os.environ.setdefault('NUMBA_NUM_THREADS', '1')
    from suspension_tuning.conditions import load_conditions
    from suspension_tuning.evaluation import in_process_condition_gradients
    from suspension_tuning.optim.simplified_gradient import run_calibration_samples
    from suspension_tuning.studies.method_benchmark import benchmark_starts

    conditions = load_conditions()
    if args.speedup_only:
        t1, t2, s = speedup(conditions, args.speedup_designs)
        print(f'conditions_speedup_2_workers: {s:.2f} ({t1:.1f} s on 1 worker process, '
              f'{t2:.1f} s on 2, {args.speedup_designs} designs x {len(conditions)} '
              'conditions)')
        return 0
    n_samples = run_calibration_samples('ride', N_VARS, args.calibration_samples)
    gradients = in_process_condition_gradients(conditions, N_VARS, n_samples=n_samples)
    calibration_runs = sum(g.calibration_runs for g in gradients.values())
    total_calibration = n_samples * len(conditions)
    print(f'conditions: {", ".join(conditions.names)}')
    print(f'conditions_calibration_runs: {total_calibration} '
          + (f'({calibration_runs} run now, the rest from the cache)' if n_samples
             else '(none: unit scaling, what a tuning goal spends by default)'))
    if args.write_reference:
        entry = write_reference(conditions, gradients)
        print(f'conditions_reference_f: {entry["f"]:.6f} ({entry["found_by"]})')
    reference = json.loads(REFERENCES.read_text()).get('condition_cases', {}).get(CASE)
    if reference is None:
        print(f'no reference for {CASE}: run {COMMAND}', file=sys.stderr)
        return 1
    f_ref = float(reference['f'])
    solved, feasible_at_check, paid, rounds = 0, 0, [], []
    starts = benchmark_starts(N_VARS)[:args.starts]
    for name, x0 in starts:
        t = time.perf_counter()
        r = _run(x0, conditions, gradients, 'simplified', check=True)
        gap = 100.0 * (float(r.f_best) - f_ref) / abs(f_ref)
        ok = bool(gap <= SOLVED_GAP_PCT and r.max_violation_best <= SOLVED_VIOLATION)
        solved += ok
        feasible_at_check += bool(r.check['feasible_check'])
        # paid: the run, each check of its answer (a round of C runs; a second one after a
        # continuation with shifted constraints) and the calibration
        checks = 1 + int(r.check.get('continuations', 0))
        paid.append(r.n_full_runs + total_calibration if ok else np.inf)
        rounds.append(r.rounds + checks + n_samples if ok else np.inf)
        print(f'conditions_ride4_{name}: f {r.f_best:.5f} gap {gap:+.2f} % max g '
              f'{r.max_violation_best:.4f} worst {r.worst_condition} iterations {r.nit} '
              f'condition-runs {r.n_full_runs} (check included) rounds {r.rounds} stop '
              f'{r.stop_test} max g at the check {r.check["max_violation_check"]:.4f} '
              f'wall {time.perf_counter() - t:.1f} s', flush=True)
    print(f'conditions_ride4_reference_f: {f_ref:.6f}')
    print(f'conditions_ride4_starts_solved: {solved} of {len(starts)}')
    print(f'conditions_ride4_starts_feasible_at_check: {feasible_at_check} of {len(starts)}')
    print(f'conditions_ride4_median_paid_full_runs: {float(np.median(paid)):g} condition-runs, '
          f'{float(np.median(rounds)):g} rounds')
    t1, t2, s = speedup(conditions, args.speedup_designs)
    print(f'conditions_speedup_2_workers: {s:.2f} ({t1:.1f} s on 1 worker process, '
          f'{t2:.1f} s on 2, {args.speedup_designs} designs x {len(conditions)} conditions)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
