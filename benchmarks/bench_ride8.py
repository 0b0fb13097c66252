"""Benchmark of the 8-variable ride (preset ride8): full runs of ours against the peers.

The case: the ride scenario (eq. 9 with the eq. 11 tyre-hop constraints) on the
``ride8`` preset of config/design_space.yaml (the compression and rebound scale factors
of the damper table and the static gas volume per axle, and both anti-roll bars;
docs/design_space.md).  The pitch-plane model that gives our gradients sees the split
damper and the gas volumes, not the bars: their columns are seeded with one full run
each and then learnt by the secant correction (optim/correction.py).

What it runs from the 6 benchmark starts (``method_benchmark.benchmark_starts(8)``:
'baseline', 'centre' and 4 seeded Latin-hypercube points), on the fixed-step model and,
with ``--noisy``, on the noisy variable-step one:

* ours: Dynamic-Q with simplified gradients and the correction, after the calibration a
  tuning goal spends by default, shared by the starts (config/simplified_models.yaml
  ``scaling.run_samples``: none for 2 and 4 variables, unit scaling; 16 full-model
  samples for 8, the maximin Latin hypercube: the 2^8 corners do not fit;
  ``--calibration-samples N`` for N);
* the peers of ``--peers`` (default COBYLA; ``all``: COBYLA, COBYQA, NOMAD, Optuna TPE),
  each with a budget of 300 full runs, stopping at its first solved design.

Definitions are bench_method.py's (``suspension_tuning.studies.method_benchmark``):
solved = gap <= 1 % to the reference on the fixed-step model and max g <= 0.005; full
runs to solve exclude the calibration; ``ride8_paid_full_runs`` adds it (what a user
pays on a first run).  ``full_runs_ratio_vs_best_peer_ride8``: the best peer's median
full runs to solve over ours; ``..._paid``: over ours plus the calibration.

``ratio_by_n``: the same ratio against COBYLA (and the other peers run) for the ride
with n = 2, 4 and 8 variables (``--ratio-n``), each against its reference.

The reference of ride8 is in benchmarks/references.json (case ``ride_8var``), written
by ``.venv/bin/python benchmarks/bench_ride8.py --write-reference`` (the method study's
search: a 3^8 grid, then SLSQP polish from its best points and from the designs
Dynamic-Q with full and with simplified gradients reaches from the 6 starts; best
feasible point seen, max g <= 1e-3).

Run: .venv/bin/python benchmarks/bench_ride8.py [--peers cobyla|all] [--noisy]
[--ratio-n 2 4 8] [--jobs N]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from suspension_tuning.optim.simplified_gradient import (
    SimplifiedGradient,
    calibrate,
    run_calibration_samples,
)
from suspension_tuning.studies import common
from suspension_tuning.studies import method_benchmark as mb
from suspension_tuning.studies.peers import PEERS, install_study_extra
from suspension_tuning.vehicle.design import load_design_space
from suspension_tuning.vehicle.scenarios import run_scenario

SCENARIO = 'ride'
N_VARS = 8
NOISY = 'variable_step'
REFERENCES = Path(__file__).resolve().parent / 'references.json'
COMMAND = '.venv/bin/python benchmarks/bench_ride8.py --write-reference'
#: Grid points per axis of the reference search (3^8 = 6561 full runs).
GRID_POINTS = 3


def runs(value: float) -> str:
    return 'inf' if math.isinf(value) else f'{value:g}'


def write_reference() -> None:
    """Search the ride8 reference and write it into benchmarks/references.json."""
    t0 = time.perf_counter()
    ref = mb.search_reference(SCENARIO, N_VARS, grid_points=GRID_POINTS,
                              log=lambda s: print(s, flush=True))
    ref.search['command'] = COMMAND
    status = mb.write_references(REFERENCES, [ref])
    print(f'ride8_reference_f: {ref.f:.6f}')
    print(f'ride8_reference_x: {np.round(ref.x, 4).tolist()}')
    print(f'ride8_reference_status: {status}')
    print(f'ride8_reference_wall_s: {time.perf_counter() - t0:.1f}')


def run_case(n_vars: int, integrator: str, peers: tuple[str, ...], jobs: int,
             log=None, samples: int = -1) -> dict:
    """Ours and ``peers`` from the 6 starts of the n-variable ride, judged.

    ``samples``: ours' eq. 25 calibration samples; -1: what a tuning goal spends
    (config/simplified_models.yaml ``scaling.run_samples``: none for 2 and 4 variables,
    ``scaling.n_samples`` 16 for 8), 0: none (unit scaling).
    """
    reference = mb.reference_for(SCENARIO, n_vars)
    starts = mb.benchmark_starts(n_vars)
    judge = mb.FixedStepJudge(SCENARIO, n_vars)
    t0 = time.perf_counter()
    n_samples = run_calibration_samples(SCENARIO, n_vars, samples)
    scaling = calibrate(SCENARIO, n_vars, n_samples=n_samples,
                        run_full=lambda sc, x: run_scenario(sc, x, integrator=integrator)
                        ) if n_samples else None
    cal_wall = time.perf_counter() - t0
    gradient = SimplifiedGradient(SCENARIO, n_vars, scaling, common.FD_STEP)
    results = {'dq_simplified': mb.run_starts('dq_simplified', SCENARIO, n_vars, reference,
                                              integrator, judge, starts, gradient=gradient,
                                              log=log)}
    for peer in peers:
        results[peer] = mb.run_starts(peer, SCENARIO, n_vars, reference, integrator, judge,
                                      starts, log=log, stop_when_solved=True)
    summaries = {m: mb.summary(rs) for m, rs in results.items()}
    ours = summaries['dq_simplified']['median_full_runs']
    figures = mb.peer_figures(results, ours, n_samples)
    return {'reference': reference, 'results': results, 'summaries': summaries,
            'peers': figures, 'calibration_wall_s': cal_wall, 'starts': starts,
            'calibration_runs': n_samples,
            'scaling_r2': {k: v['r2'] for k, v in scaling.summary().items()}
            if scaling is not None else {}}


def print_ride8(out: dict, suffix: str) -> None:
    names = load_design_space().names(N_VARS)
    for r in out['results']['dq_simplified']:
        values = load_design_space().physical_values(r.x)
        print(f'ride8_start_{r.start}{suffix}: gap_pct {r.gap_pct:+.3f}, max_violation '
              f'{r.max_violation:.3g}, full_runs_to_solve {runs(r.full_runs_to_solve)}, '
              f'full_runs {r.full_runs}, design '
              + ' '.join(f'{n}={values[n]:.4g}' for n in names))
    s = out['summaries']['dq_simplified']
    p = out['peers']
    ours = s['median_full_runs']
    print(f'ride8_calibration_r2{suffix}: '
          + (', '.join(f'{k} {v:.3f}' for k, v in out['scaling_r2'].items())
             or 'none (unit scaling)'))
    print(f'ride8_starts_solved{suffix}: {s["starts_solved"]} of {len(out["starts"])}')
    print(f'ride8_median_gap_pct{suffix}: {s["median_gap_pct"]:.3f}')
    print(f'ride8_max_gap_pct{suffix}: {s["max_gap_pct"]:.3f}')
    print(f'ride8_median_full_runs{suffix}: {runs(ours)}')
    print(f'ride8_calibration_runs{suffix}: {out["calibration_runs"]}')
    print(f'ride8_paid_full_runs{suffix}: {runs(ours + out["calibration_runs"])}')
    for peer, median in p['peer_medians'].items():
        m = out['summaries'][peer]
        print(f'peer_median_full_runs_{peer}_ride8{suffix}: {runs(median)} '
              f'({m["starts_solved"]} of {len(out["starts"])} solved)')
    print(f'peer_best_ride8{suffix}: {p["best_peer"]}')
    print(f'peer_best_full_runs_ride8{suffix}: {runs(p["peer_best_full_runs"])}')
    print(f'full_runs_ratio_vs_best_peer_ride8{suffix}: '
          f'{p["full_runs_ratio_vs_best_peer"]:.2f}')
    print(f'full_runs_ratio_vs_best_peer_ride8_paid{suffix}: '
          f'{p["full_runs_ratio_vs_best_peer_with_calibration"]:.2f}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--write-reference', action='store_true',
                        help='search the ride8 reference and write it (see above)')
    parser.add_argument('--peers', default='cobyla',
                        help="comma-separated peers, or 'all' (default cobyla)")
    parser.add_argument('--noisy', action='store_true',
                        help='the variable-step model too')
    parser.add_argument('--ratio-n', type=int, nargs='*', default=[2, 4, 8],
                        help='sizes of the ratio_by_n lines (default 2 4 8; the ride8 '
                             'lines need 8)')
    parser.add_argument('--jobs', type=int, default=1, help='(reserved) worker processes')
    parser.add_argument('--calibration-samples', type=int, default=-1, metavar='N',
                        help="ours' eq. 25 samples (0: none; default -1: what a tuning "
                        'goal spends, config/simplified_models.yaml scaling.run_samples)')
    args = parser.parse_args()
    if args.write_reference:
        write_reference()
        return
    peers = PEERS if args.peers == 'all' else tuple(p for p in args.peers.split(',') if p)
    unknown = [p for p in peers if p not in PEERS]
    if unknown:
        raise SystemExit(f'unknown peer(s) {unknown}; valid: {", ".join(PEERS)}, all')
    install_study_extra()
    t0 = time.perf_counter()
    print(f'ride8_peers: {",".join(peers)}')
    cases = {}
    for n in sorted(set(args.ratio_n)):
        cases[n] = run_case(n, mb.REFERENCE_INTEGRATOR, peers, args.jobs,
                            samples=args.calibration_samples)
        print(f'ride{n}_reference_f: {cases[n]["reference"].f:.6f}', flush=True)
    if N_VARS in cases:
        print_ride8(cases[N_VARS], '')
    for n in sorted(args.ratio_n):
        out = cases[n]
        p = out['peers']
        ours = out['summaries']['dq_simplified']['median_full_runs']
        print(f'ratio_by_n: n {n}, ours_median_full_runs {runs(ours)}, ours_solved '
              f'{out["summaries"]["dq_simplified"]["starts_solved"]}, best_peer '
              f'{p["best_peer"]} {runs(p["peer_best_full_runs"])}, calibration_runs '
              f'{out["calibration_runs"]}, ratio '
              f'{p["full_runs_ratio_vs_best_peer"]:.2f}, paid_ratio '
              f'{p["full_runs_ratio_vs_best_peer_with_calibration"]:.2f}')
    print(f'bench_ride8_fixed_step_wall_s: {time.perf_counter() - t0:.1f}', flush=True)
    if args.noisy:
        print_ride8(run_case(N_VARS, NOISY, peers, args.jobs,
                             samples=args.calibration_samples), '_noisy')
    print(f'bench_ride8_wall_s: {time.perf_counter() - t0:.1f}')


if __name__ == '__main__':
    main()
