"""Dynamic-Q against SciPy SLSQP on the analytic problems of the optimiser tests.

Run: ``.venv/bin/python benchmarks/bench_optimiser.py``.  Prints two tables (analytic
gradients; no gradients given, i.e. finite differences) and ends with ``name: value``
lines.  Counts:

* it: iterations; nfev: objective evaluations asked by the optimiser (for Dynamic-Q one
  per iteration plus the start); ngev: gradient evaluations (SciPy's njev);
* fd: objective calls spent on finite differences (SLSQP counts them inside its nfev,
  so for SLSQP the column shows the total nfev there and '-' here);
* viol: largest violation of g, h and the bounds at the final point;
* xerr: largest |x - x*| / max(1, |x*|) against the published optimum.

Dynamic-Q runs with the defaults of config/optimiser.yaml (section analytic) plus the
per-problem options of suspension_tuning.optim.problems (only the interior Rosenbrock
has some: tighter xtol/ftol); SLSQP with its own defaults.
"""

import time

import numpy as np
from scipy.optimize import minimize as scipy_minimize

from suspension_tuning.optim import minimize as dq_minimize
from suspension_tuning.optim.problems import PROBLEMS


def max_violation(problem, x):
    worst = 0.0
    for con in problem['constraints']:
        value = np.atleast_1d(con['fun'](x))
        worst = max(worst, float(np.max(-value if con['type'] == 'ineq' else np.abs(value))))
    if problem['bounds'] is not None:
        for xi, (lo, hi) in zip(x, problem['bounds']):
            if lo is not None:
                worst = max(worst, lo - xi)
            if hi is not None:
                worst = max(worst, xi - hi)
    return max(worst, 0.0)


def x_error(problem, x):
    x_star = np.asarray(problem['x_star'])
    return float(np.max(np.abs(x - x_star) / np.maximum(1.0, np.abs(x_star))))


def run(name, with_gradients):
    problem = PROBLEMS[name]()
    jac = problem['jac'] if with_gradients else None
    constraints = problem['constraints']
    if not with_gradients:
        constraints = [{'type': c['type'], 'fun': c['fun']} for c in constraints]
    rows = {}
    start = time.perf_counter()
    res = dq_minimize(
        problem['fun'],
        problem['x0'],
        jac=jac,
        bounds=problem['bounds'],
        constraints=constraints,
        options=problem.get('options'),
    )
    rows['Dynamic-Q'] = dict(
        ok=bool(res.success),
        it=res.nit,
        nfev=res.nfev,
        ngev=res.ngev,
        fd=res.nfev_fd,
        f=res.fun,
        viol=max_violation(problem, res.x),
        xerr=x_error(problem, res.x),
        seconds=time.perf_counter() - start,
    )
    start = time.perf_counter()
    res = scipy_minimize(
        problem['fun'],
        problem['x0'],
        method='SLSQP',
        jac=jac,
        bounds=problem['bounds'],
        constraints=constraints,
    )
    rows['SLSQP'] = dict(
        ok=bool(res.success),
        it=res.nit,
        nfev=res.nfev,
        ngev=res.njev,
        fd=None,
        f=res.fun,
        viol=max_violation(problem, res.x),
        xerr=x_error(problem, res.x),
        seconds=time.perf_counter() - start,
    )
    return problem, rows


def print_table(title, with_gradients, summary):
    print(title)
    header = (
        f'{"problem":24s} {"method":10s} {"ok":>3s} {"it":>4s} {"nfev":>5s} {"ngev":>5s} '
        f'{"fd":>5s} {"final f":>16s} {"f*":>12s} {"viol":>8s} {"xerr":>8s} {"time s":>7s}'
    )
    print(header)
    print('-' * len(header))
    tag = 'grad' if with_gradients else 'fd'
    for name in PROBLEMS:
        problem, rows = run(name, with_gradients)
        for method, r in rows.items():
            fd = '-' if r['fd'] is None else str(r['fd'])
            print(
                f'{name:24s} {method:10s} {"yes" if r["ok"] else "no":>3s} {r["it"]:4d} '
                f'{r["nfev"]:5d} {r["ngev"]:5d} {fd:>5s} {r["f"]:16.10g} '
                f'{problem["f_star"]:12.8g} {r["viol"]:8.1e} {r["xerr"]:8.1e} '
                f'{r["seconds"]:7.3f}'
            )
            key = 'dq' if method == 'Dynamic-Q' else 'slsqp'
            summary[f'{key}_{tag}_nfev_{name}'] = r['nfev'] + (r['fd'] or 0)
            summary[f'{key}_{tag}_it_{name}'] = r['it']
            summary[f'{key}_{tag}_xerr_{name}'] = r['xerr']
            summary.setdefault(f'{key}_{tag}_solved', 0)
            summary[f'{key}_{tag}_solved'] += int(r['xerr'] <= 1e-4 and r['viol'] <= 1e-6)
            summary.setdefault(f'{key}_{tag}_total_nfev', 0)
            summary[f'{key}_{tag}_total_nfev'] += r['nfev'] + (r['fd'] or 0)
            summary.setdefault(f'{key}_{tag}_total_seconds', 0.0)
            summary[f'{key}_{tag}_total_seconds'] += r['seconds']
    print()


def main():
    summary = {}
    print_table('Analytic gradients (jac given)', True, summary)
    print_table(
        'No gradients given (Dynamic-Q: central differences; SLSQP: its default)', False, summary
    )
    summary['problems'] = len(PROBLEMS)
    for key, value in sorted(summary.items()):
        print(f'{key}: {value:.6g}' if isinstance(value, float) else f'{key}: {value}')


if __name__ == '__main__':
    main()
