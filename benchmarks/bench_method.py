"""Does the simplified-gradient approach pay off? 4-variable ride from 6 starts (section 2).

Against Dynamic-Q with full-model gradients and against the optimisers an engineer would
pick instead (the peers: COBYLA, COBYQA, NOMAD 4, Optuna TPE, SLSQP), on the fixed-step
and on the noisy variable-step full model.

What it runs, on the fixed-step full model and then on the noisy variable-step one
(Dormand-Prince 5(4) at Adams' default error 1e-3, config/vehicle.yaml), each from the
same 6 starts of the 4-variable ride (eq. 9 with the eq. 11 tyre-hop constraints):
'baseline' (dpsf 1, 0.3 L), 'centre' of the design space and 4 seeded Latin-hypercube
points ``0.001 + 0.999 * scipy.stats.qmc.LatinHypercube(d=4, seed=7).random(4)``:

* ours: Dynamic-Q with simplified-model gradients and the first-order correction
  (``common.run_dynamic_q(..., 'simplified', ..., check=True)``), with the noise test of
  the built-in model's noise levels (config/optimiser.yaml ``noise_levels``) and the
  answer checked at DOPRI5 1e-6 after the stop (continued with shifted constraints when
  the check finds it infeasible; ``suspension_tuning.answer_check``).  Its eq. 25
  calibration: what a tuning run spends by default (config/simplified_models.yaml
  ``scaling.run_samples``, ``method_benchmark.bench_calibration_samples``: none on the
  ride, 4 on handling; docs/corrected_gradients.md);
* Dynamic-Q with full-model central differences (``common.run_dynamic_q(..., 'full')``);
* SciPy SLSQP with its default 2-point forward differences (step 1.49e-8).  On the
  noisy model also with More & Wild's noise-optimal step
  (``method_study.noise_optimal_fd_step``, whose sweep is printed, not counted), and the
  better of the two variants (fewer median full runs to solve, then more starts
  solved) is the one compared (``noisy_best_slsqp_variant``).  Each SLSQP run may
  spend 300 full runs.
* the peers (``suspension_tuning.studies.peers``): COBYLA and COBYQA (SciPy, initial
  trust radius 0.3 = Dynamic-Q's first move limit), NOMAD 4's MADS (PyNomadBBO, the
  constraints as progressive barrier) and Optuna's TPE sampler with the constraints
  (seed 0, the start enqueued as its first trial), each with a budget of 300 full runs
  from each start.  A peer's run stops at its first solved reported design (all its
  figure needs; ``make study`` runs the whole budget).  They need the study extra
  (requirements-study.txt), which this script installs on first use.

Definitions (``suspension_tuning.studies.method_benchmark``):

* **Reference**: the best known feasible optimum of the case on the fixed-step model,
  read from benchmarks/references.json (written by ``python -m suspension_tuning.study
  --write-references benchmarks/references.json``: the method study's grid, then SLSQP
  polish from the best grid points and from the designs Dynamic-Q with full and with
  simplified gradients reach from the 6 starts; best feasible point, max g <= 1e-3).
  The benchmark does not search it; ``ride4_lower_feasible_f_found`` says when a run
  found a lower feasible design, which may then replace the file's entry.
* **Reported design**: after each record of a run, the best feasible design so far
  (max g <= 1e-3, Dynamic-Q's gtol, for every method); Dynamic-Q's records are its
  iterates, SLSQP's every design it evaluated.
* **Gap**: 100 (f - f_ref) / |f_ref| with f of the reported design on the FIXED-STEP
  model; runs on the noisy model have their reported designs re-run on the fixed-step
  model for it (these runs are not counted as the method's).
* **Solved**: gap <= 1 % and the reported design's largest g <= 0.005.  On the noisy
  model g is the noisy model's (the method cannot see the fixed-step model); the
  largest fixed-step violation of the final reported designs is printed as its own
  figure (``ride4_max_final_violation_noisy_fixed_step``).
* **Full runs to solve**: the cumulative full-model run count at the first record whose
  reported design is solved, ``inf`` if no record's is; calibration excluded.
  ``..._median_full_runs`` is the median over the 6 starts (``inf`` when 3 or more of
  them are not reached).
* **Paid full runs** (``method_benchmark.paid_full_runs``): every full run of a method
  until it stops by itself, the calibration and the check of the answer included,
  counted for a start only when its final answer is solved, else ``inf`` (not
  reached); the median over the starts.  The peers run to their own stop within the
  300-run budget; Optuna TPE has no stop of its own and pays its budget (its run stops
  at its first solved design, which the budget's answer equals or betters).
  ``paid_ratio_vs_best_peer``: the smallest peer median over ours.
  ``ride4_runs_stopped_by_test``: ours' runs ended by a test of their own (xtol, ftol,
  noise, bound_kkt, rho_min), not by the iteration limit; ``ride4_stop_tests`` names them.
  ``ride4_starts_solved_noisy_checked``: solved with g of the check at the tighter
  tolerance (which stands in for the fixed-step model).  ``..._noisy_judged_fixed_step``:
  the paid figures on the noisy model with every method's answer judged by the
  fixed-step model's g (its gap already is): a peer's answer is then solved only
  when the converged physics finds it feasible, as ours is after the check.
* **Noise realisations** (``--noise-realisations R``, noisy part only).  The noisy
  model's noise is a function of the design that differs from machine to machine (the
  last bits of its libm and its compiled kernels): a design moved by 1e-9 already draws
  an independent sample of it (at the fixed-step optimum f moves by 1.7 %, the
  front-left tyre-hop g by 0.017), so the same start on another machine follows
  another path.  With R > 1 every start runs R times, moved by k * 1e-9 (k = 0 ..
  R-1): what R machines would give, and the figures (medians, counts) are over the
  6 R runs.
* **Rounds** (``method_benchmark.rounds``): sequential full-run rounds with a pool of
  P = 1, 4, 16 workers: the calibration's samples P at a time, every other paid run one
  round (Dynamic-Q, COBYLA and COBYQA are sequential; NOMAD and Optuna ran here one
  evaluation at a time).  Ours and the best paid peer's, median over the starts.
* **Smaller cases** (``--part small``): ours and every peer from the same 6 starts on the
  2-variable ride and both handling cases, fixed step; ``paid_ratio_min_small_cases`` is
  the smallest of their ``paid_ratio_vs_best_peer``.
* **Ratios**: ``full_runs_ratio_vs_slsqp`` and ``full_runs_ratio_vs_dq_full``: median
  full runs to solve of the other method over ours; ``..._with_calibration``: over
  ours plus its calibration runs (``ride4_calibration_runs``).  A ratio whose
  numerator is not reached (the other method solves half of the starts or fewer)
  prints ``inf``; ours not reached prints 0.  ``optimum_gap_pct`` is our largest gap
  over the 6 starts.
* **Peers**: ``peer_best_full_runs_ride4``: for each peer (the four above and the SLSQP
  variants, full runs to solve beyond 300 counting as not reached) the median over the
  6 starts of its full runs to solve (``inf`` where not reached); the figure is the
  smallest of those medians (``peer_best_ride4`` names the peer).
  ``full_runs_ratio_vs_best_peer``: that figure over our median full runs to solve;
  ``..._with_calibration``: over ours plus its calibration runs.  ``_noisy``: the
  same on the variable-step model.  Goal: >= 5 without calibration, >= 2 with it.

Prints ``name: value`` lines: per start, ours' gap, largest violation, full runs to solve
and total full runs; then ``ride4_starts_within_1pct`` (target 6),
``ride4_median_gap_pct`` (<= 0.5), ``ride4_max_gap_pct`` (<= 1),
``ride4_median_full_runs`` (<= 20), ``ride4_calibration_runs`` (0: none on the ride) and
``ride4_max_final_violation`` (<= 0.005); the same with suffix ``_noisy`` (targets:
median gap <= 1 %, max gap <= 2 %), plus ``ride4_max_final_violation_noisy_fixed_step``;
the ratios and ``optimum_gap_pct`` (``..._noisy``: the noisy model's), and the wall time.
Wall time: 62 min measured (3,738 s) on 2 cores shared with other jobs (load average 5-9),
of which 24 min CPU time of its one process: about 25 min on an otherwise idle machine
with one process.  A full run takes ~0.06 s (fixed step) and ~0.1 s (variable step)
idle; NOMAD's 300-run budgets (with its quadratic models) and Optuna's, which solve
late or never, take most of the peers' share.

The peers' runs go to ``--jobs`` worker processes (default: 2 when the machine is
otherwise idle, 1-minute load average below 0.5, else 1; the figures do not depend on it).

Run: .venv/bin/python benchmarks/bench_method.py [--jobs N] [--part all|small|fixed|noisy]
[--noise-realisations R]
(the three parts are independent; three processes can run them side by side).
"""

from __future__ import annotations

import argparse
import math
import os
import time
from typing import Any

import numpy as np

from suspension_tuning.studies import method_benchmark as mb
from suspension_tuning.studies.common import SLSQP_EPS
from suspension_tuning.studies.method_study import noise_optimal_fd_step
from suspension_tuning.studies.peers import PEERS, install_study_extra
from suspension_tuning.vehicle.scenarios import run_scenario

SCENARIO = 'ride'
N_VARS = 4
NOISY = 'variable_step'
TARGETS = {  # [-] the benchmark's targets (module docstring)
    'ride4_starts_within_1pct': 6,
    'ride4_median_gap_pct': 0.5,
    'ride4_max_gap_pct': 1.0,
    'ride4_median_full_runs': 20,
    'ride4_max_final_violation': 0.005,
    'ride4_median_gap_pct_noisy': 1.0,
    'ride4_max_gap_pct_noisy': 2.0,
    'paid_ratio_vs_best_peer': 1.5,
    'paid_ratio_vs_best_peer_noisy': 5.0,
    'ride4_runs_stopped_by_test_noisy': 5,
    'ride4_starts_solved_noisy_checked': 6,
    'paid_ratio_min_small_cases': 1.0,
}


def runs_to_solve(value: float) -> str:
    return 'inf' if math.isinf(value) else f'{value:g}'


def print_case(out: dict[str, Any], suffix: str, reference: mb.Reference) -> None:
    """The figures of one model (suffix '' or '_noisy')."""
    noisy = bool(suffix)
    ours = out['results']['dq_simplified']
    for r in ours:
        extra = (f', max_violation_fixed_step {r.max_violation_fixed_step:.3g}' if noisy
                 else '')
        print(f'ride4_start_{r.start}{suffix}: gap_pct {r.gap_pct:+.3f}, max_violation '
              f'{r.max_violation:.3g}{extra}, full_runs_to_solve '
              f'{runs_to_solve(r.full_runs_to_solve)}, full_runs {r.full_runs}, '
              f'wall_s {r.wall_time_s:.1f}, x {np.round(r.x, 3).tolist()}')
    s = out['summaries']['dq_simplified']
    print(f'ride4_starts_within_1pct{suffix}: {s["starts_within_1pct"]}')
    print(f'ride4_starts_solved{suffix}: {s["starts_solved"]}')
    print(f'ride4_median_gap_pct{suffix}: {s["median_gap_pct"]:.3f}')
    print(f'ride4_max_gap_pct{suffix}: {s["max_gap_pct"]:.3f}')
    print(f'ride4_median_full_runs{suffix}: {runs_to_solve(s["median_full_runs"])}')
    print(f'ride4_calibration_runs{suffix}: {out["calibration_runs"]}')
    print(f'ride4_calibration_wall_s{suffix}: {out["calibration_wall_s"]:.1f}')
    print(f'ride4_max_final_violation{suffix}: {s["max_final_violation"]:.3g}')
    print(f'ride4_paid_full_runs_per_start{suffix}: '
          f'{[runs_to_solve(r.paid_full_runs) for r in ours]}')
    print(f'ride4_paid_full_runs{suffix}: {runs_to_solve(s["median_paid_full_runs"])}')
    print(f'ride4_stop_tests{suffix}: {[r.stop_test for r in ours]}')
    print(f'ride4_runs_stopped_by_test{suffix}: '
          f'{sum(r.stop_test not in ("maxiter", "cancelled") for r in ours)}')
    print(f'ride4_check_max_violation{suffix}: '
          f'{[round(r.check_max_violation, 4) for r in ours]}')
    print(f'ride4_starts_solved{suffix}_checked: {s["starts_solved_checked"]}')
    if noisy:
        print(f'ride4_max_final_violation_noisy_fixed_step: '
              f'{s["max_final_violation_fixed_step"]:.3g}')
    for method, rs in out['results'].items():
        if method == 'dq_simplified':
            continue
        m = out['summaries'][method]
        print(f'{method}_full_runs_to_solve{suffix}: '
              f'{[runs_to_solve(r.full_runs_to_solve) for r in rs]}')
        print(f'{method}_full_runs{suffix}: {[r.full_runs for r in rs]}')
        print(f'{method}_starts_solved{suffix}: {m["starts_solved"]}')
        print(f'{method}_median_full_runs{suffix}: {runs_to_solve(m["median_full_runs"])}')
        print(f'{method}_median_gap_pct{suffix}: {m["median_gap_pct"]:.3f}')
        print(f'{method}_max_gap_pct{suffix}: {m["max_gap_pct"]:.3f}')
        print(f'{method}_paid_full_runs{suffix}: '
              f'{[runs_to_solve(r.paid_full_runs) for r in rs]}')
        print(f'{method}_wall_s{suffix}: {sum(r.wall_time_s for r in rs):.1f}')
    lower = [(r.f_fixed_step, r) for rs in out['results'].values() for r in rs
             if r.max_violation_fixed_step <= mb.REPORT_GTOL and r.f_fixed_step < reference.f]
    if lower:
        f, r = min(lower, key=lambda item: item[0])
        print(f'ride4_lower_feasible_f_found{suffix}: {f:.6f} ({r.method} from {r.start}, '
              f'x {np.round(r.x, 4).tolist()})')
    else:
        print(f'ride4_lower_feasible_f_found{suffix}: none')


def print_ratios(out: dict[str, Any], noisy: bool) -> None:
    """The ratios and ``optimum_gap_pct`` (names as before, ``_noisy`` for the noisy model)."""
    tag = '_noisy' if noisy else ''
    ratios = out['ratios']
    for other in ('slsqp', 'dq_full'):
        plain = ratios[f'full_runs_ratio_vs_{other}']
        cal = ratios[f'full_runs_ratio_vs_{other}_with_calibration']
        print(f'full_runs_ratio_vs_{other}{tag}: {plain:.2f}')
        print(f'full_runs_ratio_vs_{other}{tag}_with_calibration: {cal:.2f}')
    name = out['slsqp']
    if math.isinf(ratios['full_runs_ratio_vs_slsqp']):
        print(f'full_runs_ratio_vs_slsqp{tag}_note: inf, {name} solves '
              f'{out["summaries"][name]["starts_solved"]} of {len(out["results"][name])} '
              'starts, its median full runs to solve is not reached')
    if math.isinf(ratios['full_runs_ratio_vs_dq_full']):
        print(f'full_runs_ratio_vs_dq_full{tag}_note: inf, dq_full solves '
              f'{out["summaries"]["dq_full"]["starts_solved"]} of '
              f'{len(out["results"]["dq_full"])} starts, its median full runs to solve is '
              'not reached')
    print(f'optimum_gap_pct{tag}: {out["summaries"]["dq_simplified"]["max_gap_pct"]:.3f}')


def print_peers(out: dict[str, Any], noisy: bool) -> None:
    """Each peer's median full runs to solve (within 300) and the best peer's figures."""
    tag = '_noisy' if noisy else ''
    p = out['peers']
    for peer, median in p['peer_medians'].items():
        print(f'peer_median_full_runs_{peer}{tag}: {runs_to_solve(median)}')
    print(f'peer_best_ride4{tag}: {p["best_peer"]}')
    print(f'peer_best_full_runs_ride4{tag}: {runs_to_solve(p["peer_best_full_runs"])}')
    print(f'full_runs_ratio_vs_best_peer{tag}: {p["full_runs_ratio_vs_best_peer"]:.2f}')
    for peer, median in p['peer_paid_medians'].items():
        print(f'peer_median_paid_full_runs_{peer}{tag}: {runs_to_solve(median)}')
    print(f'peer_best_paid_ride4{tag}: {p["best_paid_peer"]}')
    print(f'peer_best_paid_full_runs_ride4{tag}: {runs_to_solve(p["peer_best_paid_full_runs"])}')
    print(f'paid_ratio_vs_best_peer{tag}: {p["paid_ratio_vs_best_peer"]:.2f}')
    if noisy:  # every method's answer judged on the fixed-step model's g too
        for method, rs in out['results'].items():
            name = 'ride4' if method == 'dq_simplified' else method
            print(f'{name}_starts_solved_noisy_judged_fixed_step: '
                  f'{sum(r.solved_fixed_step for r in rs)}')
            print(f'{name}_final_violation_fixed_step_noisy: '
                  f'{[round(r.max_violation_fixed_step, 4) for r in rs]}')
        for peer, median in p['peer_paid_medians_fixed_step'].items():
            print(f'peer_median_paid_full_runs_{peer}_noisy_judged_fixed_step: '
                  f'{runs_to_solve(median)}')
        print(f'ride4_paid_full_runs_noisy_judged_fixed_step: '
              f'{runs_to_solve(p["ours_paid_full_runs_fixed_step"])}')
        best = p['best_paid_peer_fixed_step']
        if math.isinf(p['peer_paid_medians_fixed_step'][best]):
            best = 'none (no peer solves the median start)'
        print(f'peer_best_paid_ride4_noisy_judged_fixed_step: {best}')
        print(f'paid_ratio_vs_best_peer_noisy_judged_fixed_step: '
              f'{p["paid_ratio_vs_best_peer_fixed_step"]:.2f}')
    results = out['results']
    for who, method in (('ours', 'dq_simplified'), ('best_peer', p['best_paid_peer'])):
        cal = out['calibration_runs'] if method == 'dq_simplified' else 0
        for workers in mb.ROUND_WORKERS:
            median = float(np.median([mb.rounds(r, workers, cal) for r in results[method]]))
            print(f'ride4_rounds_p{workers}_{who}{tag}: {runs_to_solve(median)}')
    print(f'full_runs_ratio_vs_best_peer_with_calibration{tag}: '
          f'{p["full_runs_ratio_vs_best_peer_with_calibration"]:.2f}')


SMALL_CASES = (('ride', 2), ('handling', 2), ('handling', 4))


def small_cases(peers: dict) -> None:
    """Paid full runs of ours and of every peer on the smaller cases (fixed step)."""
    ratios = []
    for scenario, n_vars in SMALL_CASES:
        key = f'{scenario}{n_vars}'
        reference = mb.reference_for(scenario, n_vars)
        out = mb.run_benchmark(scenario, n_vars, mb.REFERENCE_INTEGRATOR, reference,
                               {'slsqp': SLSQP_EPS}, **peers)
        ours = out['results']['dq_simplified']
        s = out['summaries']['dq_simplified']
        p = out['peers']
        print(f'{key}_calibration_runs: {out["calibration_runs"]}')
        print(f'{key}_starts_solved: {s["starts_solved"]}')
        print(f'{key}_full_runs_to_solve: {[runs_to_solve(r.full_runs_to_solve) for r in ours]}')
        print(f'{key}_paid_full_runs_per_start: '
              f'{[runs_to_solve(r.paid_full_runs) for r in ours]}')
        print(f'{key}_paid_full_runs: {runs_to_solve(s["median_paid_full_runs"])}')
        print(f'{key}_stop_tests: {[r.stop_test for r in ours]}')
        for peer, median in p['peer_paid_medians'].items():
            print(f'{key}_peer_median_paid_full_runs_{peer}: {runs_to_solve(median)}')
        print(f'{key}_peer_best_paid: {p["best_paid_peer"]}')
        print(f'{key}_peer_best_paid_full_runs: {runs_to_solve(p["peer_best_paid_full_runs"])}')
        print(f'{key}_paid_ratio_vs_best_peer: {p["paid_ratio_vs_best_peer"]:.2f}')
        ratios.append(p['paid_ratio_vs_best_peer'])
    print(f'paid_ratio_min_small_cases: {min(ratios):.2f}')


def default_jobs() -> int:
    """2 worker processes when the machine is otherwise idle, else 1."""
    return 2 if (os.cpu_count() or 1) >= 2 and os.getloadavg()[0] < 0.5 else 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--jobs', type=int, default=None,
                        help="worker processes for the peers' runs (default: see above)")
    parser.add_argument('--part', choices=('all', 'fixed', 'noisy', 'small'), default='all',
                        help='run one part only (the parts are independent: three '
                             'processes can run them side by side)')
    parser.add_argument('--peers', default=','.join(PEERS),
                        help='comma-separated peers to run (default: all)')
    parser.add_argument('--noise-realisations', type=int, default=1, metavar='R',
                        help='noisy part: run every start R times, moved by k * 1e-9 '
                             '(k = 0 .. R-1), each an independent draw of the noise (see '
                             'above); the figures are then over 6 R runs')
    parser.add_argument('--no-baselines', action='store_true',
                        help='leave out Dynamic-Q with full-model gradients and SLSQP '
                             '(their ratios are then not printed)')
    args = parser.parse_args()
    jobs = default_jobs() if args.jobs is None else max(1, args.jobs)
    install_study_extra()
    t0 = time.perf_counter()
    print(f'bench_method_jobs: {jobs}')
    reference = mb.reference_for(SCENARIO, N_VARS)
    check = run_scenario(SCENARIO, np.array([reference.x]), n_vars=N_VARS,
                         integrator=mb.REFERENCE_INTEGRATOR)
    print(f'ride4_reference_f: {reference.f:.6f}')
    print(f'ride4_reference_x: {np.round(reference.x, 4).tolist()}')
    print(f'ride4_reference_rerun_f: {float(check.f[0]):.6f}')
    print(f'ride4_reference_rerun_max_g: {float(np.max(check.g[0])):.3g}')
    starts = mb.benchmark_starts(N_VARS)
    for label, x0 in starts:
        print(f'ride4_start_point_{label}: {np.round(x0, 4).tolist()}')

    chosen = tuple(p for p in args.peers.split(',') if p)
    for peer in chosen:
        if peer not in PEERS:
            parser.error(f'unknown peer {peer!r}; valid: {", ".join(PEERS)}')
    baselines = not args.no_baselines
    print(f'bench_method_peers: {",".join(chosen)}')
    print(f'bench_method_baselines: {baselines}')
    peers = dict(peers=chosen, stop_when_solved=True, jobs=jobs, baselines=baselines)
    if args.part in ('all', 'small'):
        small_cases(peers)
        print(f'bench_method_small_cases_wall_s: {time.perf_counter() - t0:.1f}')
    if args.part in ('all', 'fixed'):
        run_fixed(reference, starts, peers, t0)
    if args.part in ('all', 'noisy'):
        realisations = max(1, args.noise_realisations)
        print(f'ride4_noise_realisations: {realisations}')
        run_noisy(reference, noise_realisations(starts, realisations), peers)
    for name, target in TARGETS.items():
        print(f'target_{name}: {target}')
    print(f'bench_method_wall_s: {time.perf_counter() - t0:.1f}')


#: Normalised move of a start that draws another realisation of the noisy model's noise.
REALISATION_STEP = 1e-9


def noise_realisations(starts: list, realisations: int) -> list:
    """Every start ``realisations`` times, the k-th moved by k * 1e-9 along every variable.

    Labels 'centre', 'centre~1', ...; the moved starts stay within the bounds (eqs. 4-8).
    """
    out = []
    for k in range(realisations):
        for label, x0 in starts:
            x = np.asarray(x0, float) + k * REALISATION_STEP
            x = np.where(x > 1.0, np.asarray(x0, float) - k * REALISATION_STEP, x)
            out.append((label if k == 0 else f'{label}~{k}', x))
    return out


def run_fixed(reference: mb.Reference, starts: list, peers: dict, t0: float) -> None:
    """The 4-variable ride on the fixed-step model."""
    fixed = mb.run_benchmark(SCENARIO, N_VARS, mb.REFERENCE_INTEGRATOR, reference,
                             {'slsqp': SLSQP_EPS}, starts=starts, **peers)
    print_case(fixed, '', reference)
    if peers['baselines']:
        print_ratios(fixed, noisy=False)
    print_peers(fixed, noisy=False)
    print(f'bench_method_fixed_step_wall_s: {time.perf_counter() - t0:.1f}')


def run_noisy(reference: mb.Reference, starts: list, peers: dict) -> None:
    """The 4-variable ride on the noisy (variable-step) model."""
    steps = {'slsqp': SLSQP_EPS}
    if peers['baselines']:
        est = noise_optimal_fd_step(SCENARIO, N_VARS, NOISY)
        print(f'noisy_fd_step_more_wild: {est["step"]:.4f}')
        print(f'noisy_fd_step_search_full_runs: {est["full_runs"]}')
        steps['slsqp_best_fd'] = est['step']
    noisy = mb.run_benchmark(SCENARIO, N_VARS, NOISY, reference, steps, starts=starts,
                             **peers)
    print_case(noisy, '_noisy', reference)
    if peers['baselines']:
        print(f'noisy_best_slsqp_variant: {noisy["slsqp"]}')
        print_ratios(noisy, noisy=True)
    print_peers(noisy, noisy=True)
    if peers['baselines']:
        print(f'slsqp_default_gap_pct_noisy: '
              f'{noisy["summaries"]["slsqp"]["max_gap_pct"]:.3f}')


if __name__ == '__main__':
    main()
