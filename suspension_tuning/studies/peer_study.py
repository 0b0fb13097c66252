"""The method against the optimisers an engineer would pick instead, on every case.

For each case (ride and handling, 2 and 4 variables) and each model (the fixed-step
full model and the noisy variable-step one), every method runs from the same starts
(the 6 of the 4-variable ride, :func:`~suspension_tuning.studies.method_benchmark.
benchmark_starts`; the centre and the baseline vehicle elsewhere) and is judged against
the committed reference optimum as the method benchmark judges
(:mod:`~suspension_tuning.studies.method_benchmark`: reference, reported design, gap,
solved, full runs to solve):

* ours: Dynamic-Q with eq. 25-scaled simplified-model gradients (one calibration of 16
  full runs per case and model, shared by the starts, counted separately);
* Dynamic-Q with full-model central differences;
* the peers of :mod:`~suspension_tuning.studies.peers` (COBYLA, COBYQA, NOMAD, Optuna
  TPE) and SLSQP (default step; on the noisy model also the noise-optimal step), each
  with a budget of 300 full runs.

Outputs: ``peers.md`` (the table: method by case, full runs to solve and gap within
the budget; the violations), ``peers.json`` (every run judged) and one data profile
per case (Moré and Wild 2009: the fraction of starts solved against full runs),
``plots/data_profile_<scenario>_<n>var.png``.  The outputs are rewritten after each
case and model, so a run cut short keeps what it finished.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from suspension_tuning.studies import method_benchmark as mb
from suspension_tuning.studies.common import (
    METHOD_LABELS,
    N_VARS,
    SCENARIOS,
    SLSQP_EPS,
    STARTS,
    start_point,
)
from suspension_tuning.studies.method_study import noise_optimal_fd_step
from suspension_tuning.studies.peers import PEER_BUDGET, PEERS

#: The models of the comparison: the noise-free fixed-step one and the noisy one.
MODELS = ('fixed_step', 'variable_step')
#: Case order: the 4-variable ride (the benchmark's case) first.
CASES = (('ride', 4), ('ride', 2), ('handling', 2), ('handling', 4))
#: Row order of the tables and the plots.
ROWS = ('dq_simplified', 'dq_full', *PEERS, 'slsqp', 'slsqp_best_fd')
SHORT = {'dq_simplified': 'ours: Dynamic-Q, simplified gradients',
         'dq_full': 'Dynamic-Q, full-model gradients', 'slsqp': 'SLSQP, default step',
         'slsqp_best_fd': 'SLSQP, noise-optimal step', 'cobyla': 'COBYLA',
         'cobyqa': 'COBYQA', 'nomad': 'NOMAD 4 (MADS)', 'optuna_tpe': 'Optuna TPE'}
#: The command that writes this study's outputs (with the method study's).
COMMAND = '.venv/bin/python -m suspension_tuning.study --out out/study --docs-dir docs/img'


def case_starts(scenario: str, n_vars: int) -> list[tuple[str, np.ndarray]]:
    """The starts of a case: the 6 benchmark starts for the 4-variable ride, else 2."""
    if (scenario, n_vars) == ('ride', 4):
        return mb.benchmark_starts(n_vars)
    return [(name, start_point(name, n_vars)) for name in STARTS]


def run_peer_case(scenario: str, n_vars: int, integrator: str, reference: mb.Reference,
                  jobs: int = 1, log: Callable[[str], None] | None = None,
                  budget: int = PEER_BUDGET) -> dict[str, Any]:
    """Every method from the case's starts on one model (see the module docstring).

    Returns
    -------
    dict
        :func:`~suspension_tuning.studies.method_benchmark.run_benchmark`'s result plus
        ``scenario``, ``n_vars``, ``fd_step_search`` (the noisy model's step search,
        not counted as any method's runs) and ``wall_time_s``.
    """
    t0 = time.perf_counter()
    steps = {'slsqp': SLSQP_EPS}
    search = None
    if integrator != mb.REFERENCE_INTEGRATOR:
        search = noise_optimal_fd_step(scenario, n_vars, integrator)
        steps['slsqp_best_fd'] = search['step']
    out = mb.run_benchmark(scenario, n_vars, integrator, reference, steps,
                           starts=case_starts(scenario, n_vars), log=log, peers=PEERS,
                           budget=budget, jobs=jobs)
    out.update(scenario=scenario, n_vars=n_vars, fd_step_search=search,
               wall_time_s=time.perf_counter() - t0)
    return out


# ---------------------------------------------------------------------- figures
def method_figures(results: Sequence[mb.StartResult], budget: int, capped: bool
                   ) -> dict[str, Any]:
    """One method's figures over the starts of a case.

    ``median_full_runs`` to solve (``capped``: ``inf`` beyond ``budget``, as for the
    peers), ``starts_solved`` (within it, when capped), ``median_gap_pct`` and
    ``worst_gap_pct`` of the reported design within the budget (``nan`` for a start
    with no feasible design), ``final_violation`` (the largest over the starts of the
    reported design's largest g within the budget, the run's own model) and
    ``starts_feasible``.
    """
    to_solve = [r.full_runs_to_solve if (not capped or r.full_runs_to_solve <= budget)
                else math.inf for r in results]
    gaps = [r.budget_gap_pct if r.budget_feasible else math.nan for r in results]
    finite = [g for g in gaps if math.isfinite(g)]
    return {
        'median_full_runs': float(np.median(to_solve)),
        'full_runs_to_solve': to_solve,
        'starts': len(results),
        'starts_solved': int(sum(math.isfinite(v) for v in to_solve)),
        'median_gap_pct': float(np.median(gaps)) if len(finite) == len(gaps) else math.nan,
        'best_gap_pct': min(finite, default=math.nan),
        'worst_gap_pct': max(finite, default=math.nan),
        'final_violation': max(r.budget_max_violation for r in results),
        'starts_feasible': len(finite),
    }


def case_figures(case: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """:func:`method_figures` of every method of a case (peers and SLSQP capped)."""
    budget = case['budget']
    return {m: method_figures(rs, budget, capped=m not in ('dq_simplified', 'dq_full'))
            for m, rs in case['results'].items()}


def _runs(value: float) -> str:
    return 'not reached' if math.isinf(value) else f'{value:g}'


def _gap(value: float) -> str:
    return '-' if not math.isfinite(value) else f'{value:+.2f} %'


def case_label(scenario: str, n_vars: int, integrator: str) -> str:
    """'ride 4, fixed' etc."""
    return f'{scenario} {n_vars}, {"noisy" if integrator != "fixed_step" else "fixed"}'


def markdown(cases: Sequence[dict[str, Any]], wall_s: float | None = None) -> str:
    """The study's tables: method by case (full runs and gap), then the details."""
    cols = [(c['scenario'], c['n_vars'], c['integrator']) for c in cases]
    figs = [case_figures(c) for c in cases]
    lines = [
        '**Full runs to solve (median over the starts) / gap of the reported design after '
        f'{cases[0]["budget"] if cases else PEER_BUDGET} full runs (median over the '
        'starts)**.  Solved: within 1 % of the reference with max g <= 0.005; "not '
        'reached": the median start is not solved within the budget; "-": a start has '
        'no feasible design.  Ours without its eq. 25 calibration (16 full runs per '
        'case and model, shared by the starts; the last row adds them).',
        '',
        '| method | ' + ' | '.join(case_label(*c) for c in cols) + ' |',
        '|---|' + '---|' * len(cols),
    ]
    for m in ROWS:
        if not any(m in f for f in figs):
            continue
        cells = []
        for f in figs:
            if m not in f:
                cells.append('')
                continue
            cells.append(f'{_runs(f[m]["median_full_runs"])} / {_gap(f[m]["median_gap_pct"])}')
        lines.append(f'| {SHORT[m]} | ' + ' | '.join(cells) + ' |')
    cells = [_runs(f['dq_simplified']['median_full_runs'] + c['calibration_runs'])
             for f, c in zip(figs, cases)]
    lines.append('| ours incl. calibration | ' + ' | '.join(cells) + ' |')
    lines += ['', '**Best peer and our ratio against it** (its median full runs to solve '
              'over ours; `inf`: no peer solves the median start; 0: we do not)', '',
              '| case | best peer | its full runs | ratio | ratio incl. our calibration |',
              '|---|---|---|---|---|']
    for c in cases:
        p = c['peers']
        lines.append(f'| {case_label(c["scenario"], c["n_vars"], c["integrator"])} | '
                     f'{SHORT[p["best_peer"]]} | {_runs(p["peer_best_full_runs"])} | '
                     f'{p["full_runs_ratio_vs_best_peer"]:.2f} | '
                     f'{p["full_runs_ratio_vs_best_peer_with_calibration"]:.2f} |')
    lines += ['', '**Per method and case**: starts solved, full runs to solve per start, '
              'gap within the budget (best, worst), final violation (largest over the '
              "starts, the run's model), full runs spent", '',
              '| case | method | solved | full runs to solve | best gap | worst gap '
              '| final violation | full runs spent |',
              '|---|---|---|---|---|---|---|---|']
    for c, f in zip(cases, figs):
        for m in ROWS:
            if m not in f:
                continue
            g = f[m]
            spent = [r.full_runs for r in c['results'][m]]
            lines.append(
                f'| {case_label(c["scenario"], c["n_vars"], c["integrator"])} | {SHORT[m]} '
                f'| {g["starts_solved"]}/{g["starts"]} | '
                f'{", ".join(_runs(v) for v in g["full_runs_to_solve"])} | '
                f'{_gap(g["best_gap_pct"])} | {_gap(g["worst_gap_pct"])} | '
                f'{g["final_violation"]:.3g} | {", ".join(map(str, spent))} |')
    if wall_s is not None:
        lines += ['', f'Wall time {wall_s:.0f} s.']
    return '\n'.join(lines) + '\n'


def data_profile(cases: Sequence[dict[str, Any]], path: Path,
                 gap_pct: float | None = None) -> Path:
    """Fraction of starts solved against full runs, per method (Moré and Wild 2009).

    One panel per model of the case; ours also shifted by its calibration runs (dashed).
    ``gap_pct``: a looser tolerance of :data:`~suspension_tuning.studies.method_benchmark.
    LOOSE_GAPS_PCT` in place of the solved one (1 %): the full runs until the reported
    design is within it (``StartResult.full_runs_to_gap``).
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    if gap_pct is not None:
        cases = [{**c, 'results': {m: [replace(r, full_runs_to_solve=r.full_runs_to_gap[
            gap_pct]) for r in rs] for m, rs in c['results'].items()}} for c in cases]
    tolerance = mb.SOLVED_GAP_PCT if gap_pct is None else gap_pct
    fig, axes = plt.subplots(1, len(cases), figsize=(6.2 * len(cases), 4.4), sharey=True,
                             squeeze=False)
    budget = max(c['budget'] for c in cases)
    k = np.arange(budget + 1)
    for ax, case in zip(axes[0], cases):
        figs = case_figures(case)
        for m in ROWS:
            if m not in figs:
                continue
            runs = np.array(figs[m]['full_runs_to_solve'])
            frac = [(runs <= v).mean() for v in k]
            ax.step(k, frac, '-', where='post', lw=2.2 if m == 'dq_simplified' else 1.3,
                    label=SHORT[m])
            if m == 'dq_simplified':
                shifted = runs + case['calibration_runs']
                ax.step(k, [(shifted <= v).mean() for v in k], '--', where='post', lw=1.2,
                        color=ax.lines[-1].get_color(), label='ours incl. calibration')
        ax.set_title(f'{case_label(case["scenario"], case["n_vars"], case["integrator"])} '
                     f'({len(case["starts"])} starts)')
        ax.set_xlabel('full-model runs')
        ax.set_xlim(0, budget)
        ax.set_ylim(-0.02, 1.02)
        ax.grid(True, alpha=0.3)
    axes[0][0].set_ylabel(f'fraction of starts solved ({tolerance:g} %, max g <= 0.005)'
                          if gap_pct is None else
                          f'fraction of starts within {tolerance:g} % (max g <= 0.005)')
    axes[0][-1].legend(fontsize=7, loc='lower right')
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _payload(cases: Sequence[dict[str, Any]], wall: float) -> dict[str, Any]:
    def plain(case: dict[str, Any]) -> dict[str, Any]:
        return {**{k: v for k, v in case.items() if k != 'results'},
                'figures': case_figures(case),
                'results': {m: [asdict(r) for r in rs] for m, rs in case['results'].items()}}

    return {'wall_time_s': wall, 'budget': PEER_BUDGET, 'labels': METHOD_LABELS,
            'cases': [plain(c) for c in cases]}


def run_peer_study(out: Path, cases: Sequence[tuple[str, int]] = CASES,
                   models: Sequence[str] = MODELS, jobs: int = 1,
                   references: str | Path | None = None, docs_dir: Path | None = None,
                   log: Callable[[str], None] = print) -> dict[str, Any]:
    """Run every case on every model; write ``peers.md``, ``peers.json`` and the plots.

    ``docs_dir``: the data profiles are copied there too
    (``method_peers_<scenario>_<n>var.png``).

    Returns
    -------
    dict
        ``cases`` (as :func:`run_peer_case`), ``markdown``, ``plots``, ``wall_time_s``.
    """
    for scenario, n in cases:
        if scenario not in SCENARIOS or n not in N_VARS:
            raise ValueError(f'unknown case {scenario}, {n} variables')
    refs = mb.load_references(references)
    missing = [mb.case_key(s, n) for s, n in cases if mb.case_key(s, n) not in refs]
    if missing:
        raise ValueError(f'no committed reference for {", ".join(missing)}; write them '
                         f'with {mb.REFERENCES_COMMAND}')
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    done: list[dict[str, Any]] = []
    plots: list[Path] = []
    text = ''
    for scenario, n in cases:
        of_case = []
        for integrator in models:
            log(f'== peers: {case_label(scenario, n, integrator)}')
            case = run_peer_case(scenario, n, integrator, refs[mb.case_key(scenario, n)],
                                 jobs, log)
            done.append(case)
            of_case.append(case)
            wall = time.perf_counter() - t0
            text = markdown(done, wall)
            (out / 'peers.md').write_text(text)
            (out / 'peers.json').write_text(json.dumps(_payload(done, wall), indent=1,
                                                       default=float))
        path = data_profile(of_case, out / 'plots' / f'data_profile_{scenario}_{n}var.png')
        plots.append(path)
        if docs_dir is not None:
            Path(docs_dir).mkdir(parents=True, exist_ok=True)
            shutil.copy(path, Path(docs_dir) / f'method_peers_{scenario}_{n}var.png')
    return {'cases': done, 'markdown': text, 'plots': plots,
            'wall_time_s': time.perf_counter() - t0}
