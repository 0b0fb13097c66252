"""Dynamic-Q against SciPy SLSQP on the analytic problems of the optimiser tests.

Run: ``.venv/bin/python benchmarks/bench_optimiser.py``.  Prints two tables (analytic
gradients; no gradients given, i.e. finite differences) and ends with ``name: value``
lines.  Counts:

* it: iterations; nfev: every call of the objective function, finite differences
  included, as both report it (checked against a counting wrapper: the line
  ``nfev_equals_calls`` is 1 when every reported nfev equals the calls counted);
  njev: gradient evaluations (analytic or by finite differences, SciPy's meaning);
* fd: the part of nfev spent on finite differences (Dynamic-Q's ``nfev_fd``; SLSQP
  does not split its nfev: '-');
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


class Counted:
    """The objective with a count of its calls."""

    def __init__(self, fun):
        self.fun = fun
        self.calls = 0

    def __call__(self, x):
        self.calls += 1
        return self.fun(x)


def run(name, with_gradients):
    problem = PROBLEMS[name]()
    jac = problem['jac'] if with_gradients else None
    constraints = problem['constraints']
    if not with_gradients:
        constraints = [{'type': c['type'], 'fun': c['fun']} for c in constraints]
    rows = {}
    fun = Counted(problem['fun'])
    start = time.perf_counter()
    res = dq_minimize(
        fun,
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
        calls=fun.calls,
        njev=res.njev,
        fd=res.nfev_fd,
        f=res.fun,
        viol=max_violation(problem, res.x),
        xerr=x_error(problem, res.x),
        seconds=time.perf_counter() - start,
    )
    fun = Counted(problem['fun'])
    start = time.perf_counter()
    res = scipy_minimize(
        fun,
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
        calls=fun.calls,
        njev=res.njev,
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
        f'{"problem":24s} {"method":10s} {"ok":>3s} {"it":>4s} {"nfev":>5s} {"njev":>5s} '
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
                f'{r["nfev"]:5d} {r["njev"]:5d} {fd:>5s} {r["f"]:16.10g} '
                f'{problem["f_star"]:12.8g} {r["viol"]:8.1e} {r["xerr"]:8.1e} '
                f'{r["seconds"]:7.3f}'
            )
            key = 'dq' if method == 'Dynamic-Q' else 'slsqp'
            summary[f'{key}_{tag}_nfev_{name}'] = r['nfev']
            summary['nfev_equals_calls'] = int(
                summary.get('nfev_equals_calls', 1) and r['nfev'] == r['calls']
            )
            summary[f'{key}_{tag}_it_{name}'] = r['it']
            summary[f'{key}_{tag}_xerr_{name}'] = r['xerr']
            summary.setdefault(f'{key}_{tag}_solved', 0)
            summary[f'{key}_{tag}_solved'] += int(r['xerr'] <= 1e-4 and r['viol'] <= 1e-6)
            summary.setdefault(f'{key}_{tag}_total_nfev', 0)
            summary[f'{key}_{tag}_total_nfev'] += r['nfev']
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
