"""``study``: does the simplified-gradient approach pay off? (paper section 2).

Thoresson et al. (2009), section 2: with gradients from the eq. 25-scaled simplified
models an iteration costs one full-model run plus 2n simplified runs ("0.2n + 1"
full-run equivalents) instead of 2n + 1 full-model runs, without losing the optimum.
This module measures that claim on our models, in-process (no rclpy at import; the ROS
message classes are loaded only to write the bags).  For each scenario (ride, handling),
number of variables (2, 4) and start point (centre of the design space, baseline
vehicle) it runs

* ``dq_simplified`` - Dynamic-Q with scaled simplified-model central differences (one
  row per calibration sample count, e.g. the paper's 30 and the 16 of 2^4 corners);
* ``dq_full`` - Dynamic-Q with full-model central differences (2n full runs per
  gradient, the same half step as the simplified gradients);
* ``slsqp`` - SciPy SLSQP with its default gradients: 2-point forward differences
  with the absolute step sqrt(machine eps) = 1.49e-8 in normalised units, on the full
  model (n full runs per gradient);
* ``reference`` - the reference optimum: by default the committed best known feasible
  optimum on the fixed-step model (benchmarks/references.json,
  :mod:`suspension_tuning.studies.method_benchmark`); with ``--search-references`` also a
  search: a dense grid (2 variables: 41 x 41 by default) or a coarse grid (4 variables:
  7^4), then SLSQP polishes from the best grid points and from every method's final
  point, the best feasible result, or the committed one where that is lower.
  ``--write-references OUT`` searches the references anew and writes them.

First, unless ``--no-peers``, it compares the method with the optimisers an engineer
would pick instead (:mod:`suspension_tuning.studies.peer_study`): COBYLA, COBYQA,
NOMAD 4, Optuna TPE and SLSQP, each with 300 full runs, on every case and on both the
fixed-step and the noisy variable-step model, from the same starts (the 6 of the
4-variable ride, the 2 above elsewhere): ``peers.md``, ``peers.json`` and the data
profiles ``plots/data_profile_<case>.png`` (``--docs-dir`` copies them, ``make study``
into docs/img).  It installs the study extra (requirements-study.txt) on first use.
``--peers-only`` stops after it.

All Dynamic-Q runs go through :func:`suspension_tuning.tuning.optimise`, the loop of the
ROS coordinator.  Cost counting: every full-model run counts once; SLSQP's objective and
constraints at one x come from one run (cached per x), its finite-difference points
likewise.  The eq. 25 calibration (N full runs) is reported separately and added per
run ("full runs incl. calibration"), as a run that calibrates afresh pays it (the
coordinator caches a calibration across runs of the same scenario and n).

Outputs (``--out``, default ``out/study``): ``method_study.md`` (the tables),
``results.json``, ``plots/<case>.png`` (f against full-model runs per method) and one
rosbag2-style bag per run under ``bags/`` (``/optimisation/run_config``,
``/optimisation/progress``, ``/optimisation/result``, as the graph records them), which
``inspect_bag`` reads.

This module is the command; the studies live in :mod:`suspension_tuning.studies`
(:mod:`~suspension_tuning.studies.method_study`, :mod:`~suspension_tuning.studies.
peer_study`, :mod:`~suspension_tuning.studies.common`).

Run: ``.venv/bin/python -m suspension_tuning.study [--search-references [--quick]]
[--peers-only | --no-peers] [--jobs N] [--docs-dir DIR] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from suspension_tuning.studies.common import GRID_POINTS, N_VARS, SCENARIOS, SLSQP_EPS, STARTS
from suspension_tuning.studies.method_study import (
    CALIBRATION_SAMPLES,
    QUICK_GRID_POINTS,
    run_study,
    write_reference_file,
)
from suspension_tuning.vehicle.params import INTEGRATORS


def run_peers(args: argparse.Namespace) -> int:
    """The comparison with the peer optimisers (installs the study extra on first use)."""
    from suspension_tuning.studies import peer_study
    from suspension_tuning.studies.peers import install_study_extra

    if args.jobs < 1:
        print(f'study: --jobs must be >= 1, got {args.jobs}', file=sys.stderr)
        return 2
    cases = [c for c in peer_study.CASES if c[0] in args.scenarios and c[1] in args.n_vars]
    models = [args.integrator] if args.integrator else list(peer_study.MODELS)
    try:
        install_study_extra(lambda s: print(s, flush=True))
        result = peer_study.run_peer_study(
            Path(args.out), cases, models, args.jobs, args.references,
            Path(args.docs_dir) if args.docs_dir else None,
            log=lambda s: print(s, flush=True))
    except (ValueError, RuntimeError) as error:
        print(f'study: {error}', file=sys.stderr)
        return 2
    print()
    print(result['markdown'])
    out = Path(args.out)
    print(f'peer table: {out / "peers.md"}')
    print(f'peer results: {out / "peers.json"}')
    print(f'data profiles: {", ".join(str(p) for p in result["plots"])}')
    print(f'peers_wall_time_s: {result["wall_time_s"]:.1f}')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: run the study, print the table and where the outputs are."""
    parser = argparse.ArgumentParser(prog='study', description=__doc__.split('\n')[0])
    parser.add_argument('--out', default='out/study', help='output folder (default out/study)')
    parser.add_argument('--scenarios', nargs='+', default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument('--n-vars', nargs='+', type=int, default=list(N_VARS), choices=N_VARS)
    parser.add_argument('--starts', nargs='+', default=list(STARTS), choices=STARTS)
    parser.add_argument(
        '--calibration-samples',
        nargs='+',
        type=int,
        default=list(CALIBRATION_SAMPLES),
        help='eq. 25 sample counts of the simplified-gradient runs '
        '(the first one is used in the settings table)',
    )
    parser.add_argument(
        '--grid-2',
        type=int,
        default=None,
        help=f'reference grid points per axis, 2 variables (default {GRID_POINTS[2]})',
    )
    parser.add_argument(
        '--grid-4',
        type=int,
        default=None,
        help=f'reference grid points per axis, 4 variables (default {GRID_POINTS[4]})',
    )
    parser.add_argument(
        '--quick',
        action='store_true',
        help=f'coarse reference grids ({QUICK_GRID_POINTS[2]} and '
        f'{QUICK_GRID_POINTS[4]} per axis) for --search-references and '
        '--write-references: a smoke run',
    )
    parser.add_argument(
        '--slsqp-eps',
        type=float,
        default=SLSQP_EPS,
        help="SLSQP forward-difference step, normalised (default SciPy's 1.49e-8)",
    )
    parser.add_argument('--no-bags', action='store_true', help='do not record bags')
    parser.add_argument(
        '--references', default=None, metavar='FILE',
        help='the committed reference optima (default benchmarks/references.json)',
    )
    parser.add_argument(
        '--search-references', action='store_true',
        help='search the reference optima too (grid then SLSQP polish, ~10 min per ride '
        'case); the gaps are to the better of the search and the committed reference',
    )
    parser.add_argument(
        '--write-references', default=None, metavar='OUT',
        help='instead: search the reference optimum of every case on the fixed-step model '
        '(the grid, then SLSQP polish from its best points and from the designs of '
        'Dynamic-Q with full and with simplified gradients from the 6 benchmark starts) '
        'and write OUT, keeping any lower committed entry (~20-40 min)',
    )
    parser.add_argument(
        '--pareto',
        action='store_true',
        help='instead: the passive ride-handling Pareto front against the switched 4S4 '
        '(suspension_tuning.studies.pareto; default output out/pareto)',
    )
    parser.add_argument(
        '--pareto-n-vars', type=int, default=4, choices=N_VARS,
        help='design variables of the Pareto study (default 4)',
    )
    parser.add_argument(
        '--points', type=int, default=None,
        help='epsilon values of the Pareto front (default 8)',
    )
    parser.add_argument(
        '--pareto-samples', type=int, default=None,
        help='eq. 25 calibration samples per scenario of the Pareto study (default '
             'config/simplified_models.yaml scaling.n_samples, 16)',
    )
    parser.add_argument(
        '--peers-only', action='store_true',
        help='only the comparison with the peer optimisers (COBYLA, COBYQA, NOMAD, Optuna '
        'TPE, SLSQP) on every case and both models (suspension_tuning.studies.peer_study)',
    )
    parser.add_argument(
        '--no-peers', action='store_true',
        help='without the comparison with the peer optimisers',
    )
    parser.add_argument(
        '--jobs', type=int, default=1,
        help='worker processes for the peers\' runs (default 1; 2 on an otherwise idle '
        '2-core machine; the figures do not depend on it)',
    )
    parser.add_argument(
        '--docs-dir', default=None, metavar='DIR',
        help='also copy the data profiles of the peer comparison into DIR (docs/img)',
    )
    parser.add_argument(
        '--integrator',
        choices=INTEGRATORS,
        default=None,
        help='full-model integrator (default config/vehicle.yaml: fixed_step); '
        'variable_step runs the study on the noisy model',
    )
    args = parser.parse_args(argv)
    if args.pareto:
        from suspension_tuning.studies import pareto

        if args.out == 'out/study':
            args.out = 'out/pareto'
        try:
            return pareto.main(args)
        except ValueError as error:
            print(f'study: {error}', file=sys.stderr)
            return 2
    grid = dict(QUICK_GRID_POINTS if args.quick else GRID_POINTS)
    if args.grid_2 is not None:
        grid[2] = args.grid_2
    if args.grid_4 is not None:
        grid[4] = args.grid_4
    if args.write_references:
        return write_reference_file(Path(args.write_references), args.scenarios, args.n_vars,
                                    grid)
    if not args.no_peers:
        code = run_peers(args)
        if code or args.peers_only:
            return code
    try:
        study = run_study(
            Path(args.out),
            args.scenarios,
            args.n_vars,
            args.starts,
            args.calibration_samples,
            grid,
            bags=not args.no_bags,
            log=lambda s: print(s, flush=True),
            slsqp_eps=args.slsqp_eps,
            integrator=args.integrator,
            search_references=args.search_references,
            references=args.references,
        )
    except ValueError as error:
        print(f'study: {error}', file=sys.stderr)
        return 2
    print()
    print(study['markdown'])
    out = Path(args.out)
    noisy = '_noisy' if args.integrator == 'variable_step' else ''
    print(f'table: {out / f"method_study{noisy}.md"}')
    print(f'results: {out / f"results{noisy}.json"}')
    print(f'plots: {", ".join(str(p) for p in study["plots"])}')
    if not args.no_bags:
        print(f'bags: {out / "bags"} (inspect: inspect_bag <bag>)')
    print(f'study_wall_time_s: {study["wall_time_s"]:.1f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
