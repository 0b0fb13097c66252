"""Benchmark of the 8-variable cases (ride, handling, the two states): ours against the peers.

The case: the ride scenario (eq. 9 with the eq. 11 tyre-hop constraints; default) or,
with ``--scenario handling``, the handling one (eq. 10 with the eq. 11 constraints) on
the 8-variable preset of config/design_space.yaml (``ride8``: the compression and
rebound scale factors of the damper table and the static gas volume per axle, and both
anti-roll bars; docs/design_space.md).  ``--scenario mixed``: the 4S4's two states
tuned together on the mixed scenario (the paving in the ride state, the lane change in
the handling state, the valve controller switching between them; f the mean of eqs. 9
and 10, eq. 11 over the whole run), the preset ``two_state8`` of the configuration
folder ``suspension_tuning.studies.two_state`` writes (per axle the soft and stiff gas
volume, the low and high dpsf; docs/design_space.md), written to a temporary folder
before the models load.  The ride's 8-variable gradients come from the roll-and-pitch
model (config/simplified_models.yaml ``ride_model: auto``: the design has a bar), which
sees all 8: the split damper, the gas volumes and the bars, each tyre on its own track.
The handling model sees all 8 too (the bars in eq. 14's roll moment).  The mixed
case's simplified model is both (vehicle.simplified.run_mixed_simplified).
Lines are prefixed ``ride8_``, ``handling8_`` or ``mixed8_``.

What it runs from the 6 benchmark starts (``method_benchmark.benchmark_starts(8)``:
'baseline', 'centre' and 4 seeded Latin-hypercube points), on the fixed-step model and,
with ``--noisy``, on the noisy variable-step one:

* ours: Dynamic-Q with simplified gradients and the correction, after the calibration a
  tuning goal spends by default, shared by the starts (config/simplified_models.yaml
  ``scaling.run_samples``: none for the ride at any size, unit scaling; 4 full-model
  samples for handling; a case not listed, such as the two states, ``n_samples``,
  16, the maximin Latin hypercube, as the 2^8 corners do not fit;
  ``--calibration-samples N`` for N);
* the peers of ``--peers`` (default COBYLA; ``all``: COBYLA, COBYQA, NOMAD, Optuna TPE),
  each with a budget of 300 full runs, stopping at its first solved design.

Definitions are bench_method.py's (``suspension_tuning.studies.method_benchmark``):
solved = gap <= 1 % to the reference on the fixed-step model and max g <= 0.005; full
runs to solve exclude the calibration; ``ride8_paid_full_runs`` adds it (what a user
pays on a first run that stops at its solved design); ``ride8_paid_full_runs_to_stop``
counts as bench_method.py does: every full run until ours stops by itself (the check
and any continuation included) plus the calibration, per start solved at the check,
else inf.  ``full_runs_ratio_vs_best_peer_ride8``: the best peer's median
full runs to solve over ours; ``..._paid``: over ours plus the calibration.

``ratio_by_n``: the same ratio against COBYLA (and the other peers run) for the ride
with n = 2, 4 and 8 variables (``--ratio-n``), each against its reference.

The references are in benchmarks/references.json (cases ``ride_8var``,
``handling_8var`` and ``mixed_8var``), written by ``.venv/bin/python
benchmarks/bench_ride8.py --write-reference [--scenario handling|mixed]`` (the method study's
search: a 3^8 grid, then SLSQP polish from its best points and from the designs
Dynamic-Q with full and with simplified gradients reaches from the 6 starts; best
feasible point seen, max g <= 1e-3).

``--polish-answers EPS``: each of ours' final 8-variable designs polished by SLSQP on
the full fixed-step model (forward differences of step EPS, 300 full runs at most),
which shows the local optimum of the basin each run ended in.  ``--rerun-answers``: ours
once more from each of its final 8-variable designs (a second run, its move limit and
correction started afresh), the better answer per start and what both runs paid.

``--more-starts N``: ours alone from N more seeded Latin-hypercube starts
(``method_benchmark.more_starts``), on each model run, and the share of the 6 + N
starts solved, within 5 %, the median gap and the median full runs to the stop: six
starts give a success rate only to the nearest 17 %.

Run: .venv/bin/python benchmarks/bench_ride8.py [--scenario ride|handling|mixed]
[--peers cobyla|all] [--noisy] [--ratio-n 2 4 8] [--polish-answers EPS] [--rerun-answers]
[--more-starts N] [--jobs N]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def two_state_folder(argv: list[str]) -> Path | None:
    """``--scenario mixed``: write the two-state configuration folder and name it.

    The mixed case tunes the 4S4's two states (``suspension_tuning.studies.two_state``:
    preset ``two_state8``, the 271 m paving), which live in a configuration folder of
    their own; the models read the folder when they are imported, so it is written (in
    a temporary folder, removed at exit) and named by ``SUSPENSION_TUNING_CONFIG_DIR``
    before the imports below.
    """
    early = argparse.ArgumentParser(add_help=False)
    early.add_argument('--scenario', default='ride')
    if early.parse_known_args(argv)[0].scenario != 'mixed':
        return None
    from suspension_tuning.paths import CONFIG_DIR_VARIABLE
    from suspension_tuning.studies.two_state import write_config

    holder = tempfile.TemporaryDirectory(prefix='two_state_')
    TEMPORARY.append(holder)
    folder = write_config(Path(holder.name) / 'config')
    os.environ[CONFIG_DIR_VARIABLE] = str(folder)
    return folder


TEMPORARY: list[tempfile.TemporaryDirectory] = []
TWO_STATE_FOLDER = two_state_folder(sys.argv[1:])

# The models read the configuration folder when imported: after two_state_folder.
from suspension_tuning.optim.simplified_gradient import (  # noqa: E402
    SimplifiedGradient,
    calibrate,
    run_calibration_samples,
)
from suspension_tuning.studies import common  # noqa: E402
from suspension_tuning.studies import method_benchmark as mb  # noqa: E402
from suspension_tuning.studies.peer_study import SHORT, data_profile  # noqa: E402
from suspension_tuning.studies.peers import PEER_BUDGET, PEERS, install_study_extra  # noqa: E402
from suspension_tuning.vehicle.design import load_design_space  # noqa: E402
from suspension_tuning.vehicle.runs import run_full as run_model  # noqa: E402

SCENARIOS = ('ride', 'handling', 'mixed')
N_VARS = 8
NOISY = 'variable_step'
REFERENCES = Path(__file__).resolve().parent / 'references.json'
COMMAND = '.venv/bin/python benchmarks/bench_ride8.py --write-reference'
#: Grid points per axis of the reference search (3^8 = 6561 full runs).
GRID_POINTS = 3


def runs(value: float) -> str:
    return 'inf' if math.isinf(value) else f'{value:g}'


def write_reference(scenario: str) -> None:
    """Search the 8-variable reference of ``scenario``; write it to references.json."""
    t0 = time.perf_counter()
    ref = mb.search_reference(scenario, N_VARS, grid_points=GRID_POINTS,
                              log=lambda s: print(s, flush=True))
    ref.search['command'] = COMMAND + ('' if scenario == 'ride' else f' --scenario {scenario}')
    status = mb.write_references(REFERENCES, [ref])
    case = f'{scenario}{N_VARS}'
    print(f'{case}_reference_f: {ref.f:.6f}')
    print(f'{case}_reference_x: {np.round(ref.x, 4).tolist()}')
    print(f'{case}_reference_status: {status}')
    print(f'{case}_reference_wall_s: {time.perf_counter() - t0:.1f}')


def run_case(scenario: str, n_vars: int, integrator: str, peers: tuple[str, ...],
             jobs: int, log=None, samples: int = -1) -> dict:
    """Ours and ``peers`` from the 6 starts of the n-variable case, judged.

    ``samples``: ours' eq. 25 calibration samples; -1: what a tuning goal spends
    (config/simplified_models.yaml ``scaling.run_samples``), 0: none (unit scaling).
    """
    reference = mb.reference_for(scenario, n_vars)
    starts = mb.benchmark_starts(n_vars)
    judge = mb.FixedStepJudge(scenario, n_vars)
    t0 = time.perf_counter()
    n_samples = run_calibration_samples(scenario, n_vars, samples)
    scaling = calibrate(scenario, n_vars, n_samples=n_samples,
                        run_full=lambda sc, x: run_model(sc, x, integrator=integrator)
                        ) if n_samples else None
    cal_wall = time.perf_counter() - t0
    gradient = SimplifiedGradient(scenario, n_vars, scaling, common.FD_STEP)
    results = {'dq_simplified': mb.run_starts('dq_simplified', scenario, n_vars, reference,
                                              integrator, judge, starts, gradient=gradient,
                                              log=log)}
    for peer in peers:
        results[peer] = mb.run_starts(peer, scenario, n_vars, reference, integrator, judge,
                                      starts, log=log, stop_when_solved=True)
    summaries = {m: mb.summary(rs) for m, rs in results.items()}
    ours = summaries['dq_simplified']['median_full_runs']
    figures = mb.peer_figures(results, ours, n_samples) if peers else None
    return {'scenario': scenario, 'n_vars': n_vars, 'integrator': integrator,
            'budget': PEER_BUDGET,
            'reference': reference, 'results': results, 'summaries': summaries,
            'peers': figures, 'calibration_wall_s': cal_wall, 'starts': starts,
            'calibration_runs': n_samples, 'gradient': gradient,
            'scaling_r2': {k: v['r2'] for k, v in scaling.summary().items()}
            if scaling is not None else {}}


def ratio_text(ratio: float, ours: float, peers: dict) -> str:
    """A ratio, or 'none' with the reason when neither ours nor any peer solves."""
    if math.isinf(ours) and math.isinf(peers['peer_best_full_runs']):
        return 'none (neither ours nor a peer solves the median start)'
    return f'{ratio:.2f}'


def best_peer_text(p: dict) -> str:
    """The best peer's name, or 'none' when no peer solves the median start."""
    if math.isfinite(p['peer_best_full_runs']):
        return p['best_peer']
    return 'none (no peer solves the median start)'


def print_case(scenario: str, out: dict, suffix: str) -> None:
    """The 8-variable lines of one case (``suffix``: '' or '_noisy')."""
    case = f'{scenario}{N_VARS}'
    names = load_design_space().names(N_VARS)
    for r in out['results']['dq_simplified']:
        values = load_design_space().physical_values(r.x)
        print(f'{case}_start_{r.start}{suffix}: gap_pct {r.gap_pct:+.3f}, max_violation '
              f'{r.max_violation:.3g}, full_runs_to_solve {runs(r.full_runs_to_solve)}, '
              f'full_runs {r.full_runs}, design '
              + ' '.join(f'{n}={values[n]:.4g}' for n in names))
    s = out['summaries']['dq_simplified']
    p = out['peers']
    ours = s['median_full_runs']
    print(f'{case}_calibration_r2{suffix}: '
          + (', '.join(f'{k} {v:.3f}' for k, v in out['scaling_r2'].items())
             or 'none (unit scaling)'))
    print(f'{case}_starts_solved{suffix}: {s["starts_solved"]} of {len(out["starts"])}')
    print(f'{case}_median_gap_pct{suffix}: {s["median_gap_pct"]:.3f}')
    print(f'{case}_max_gap_pct{suffix}: {s["max_gap_pct"]:.3f}')
    print(f'{case}_median_full_runs{suffix}: {runs(ours)}')
    print(f'{case}_calibration_runs{suffix}: {out["calibration_runs"]}')
    print(f'{case}_paid_full_runs{suffix}: {runs(ours + out["calibration_runs"])}')
    to_stop = [r.full_runs + out['calibration_runs'] if r.solved_checked else math.inf
               for r in out['results']['dq_simplified']]
    print(f'{case}_paid_full_runs_to_stop{suffix}: {runs(float(np.median(to_stop)))} '
          f'(per start {", ".join(runs(v) for v in to_stop)})')
    if p is None:  # --peers none: ours alone
        return
    for peer, median in p['peer_medians'].items():
        m = out['summaries'][peer]
        print(f'peer_median_full_runs_{peer}_{case}{suffix}: {runs(median)} '
              f'({m["starts_solved"]} of {len(out["starts"])} solved)')
    print(f'peer_best_{case}{suffix}: {best_peer_text(p)}')
    print(f'peer_best_full_runs_{case}{suffix}: {runs(p["peer_best_full_runs"])}')
    print(f'full_runs_ratio_vs_best_peer_{case}{suffix}: '
          f'{ratio_text(p["full_runs_ratio_vs_best_peer"], ours, p)}')
    print(f'full_runs_ratio_vs_best_peer_{case}_paid{suffix}: '
          f'{ratio_text(p["full_runs_ratio_vs_best_peer_with_calibration"], ours, p)}')
    for tau in mb.LOOSE_GAPS_PCT:
        medians = {m: float(np.median([r.full_runs_to_gap[tau] for r in rs]))
                   for m, rs in out['results'].items()}
        reached = {m: sum(math.isfinite(r.full_runs_to_gap[tau]) for r in rs)
                   for m, rs in out['results'].items()}
        ours = medians.pop('dq_simplified')
        best = min(medians, key=medians.get) if medians else ''
        if not best or not math.isfinite(ours):
            ratio = 'none (ours does not reach the median start)'
        else:
            ratio = f'{medians[best] / ours:.2f}'
        print(f'{case}_median_full_runs_within_{tau:g}pct{suffix}: ours {runs(ours)} '
              f'({reached["dq_simplified"]} of {len(out["starts"])}), '
              + ', '.join(f'{m} {runs(v)} ({reached[m]} of {len(out["starts"])})'
                          for m, v in medians.items())
              + f'; ratio vs best peer {ratio}')


def plot_by_n(scenario: str, cases: dict[int, dict], path: Path) -> Path:
    """Full runs against n (fixed-step model): the medians, and the ratio to the best peer.

    Left: median full runs to solve, ours without and with its calibration (dashed) and
    every peer; a method whose median start is not solved within the peers' budget is
    an open marker at the budget ("not reached").  Right: the best peer's median over
    ours (solid) and over ours with the calibration (dashed); no point where neither
    solves the median start.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    sizes = sorted(cases)
    fig, (ax, ax_r) = plt.subplots(1, 2, figsize=(11.5, 4.4))
    for m in cases[sizes[0]]['summaries']:
        medians = [cases[n]['summaries'][m]['median_full_runs'] for n in sizes]
        series = [(medians, '-', SHORT[m])]
        if m == 'dq_simplified':
            series.append(([v + cases[n]['calibration_runs'] for v, n in zip(medians, sizes)],
                           '--', 'ours incl. calibration'))
        for values, style, label in series:
            y = [v if math.isfinite(v) else np.nan for v in values]
            line, = ax.plot(sizes, y, style, marker='o', lw=2.2 if m == 'dq_simplified'
                            else 1.3, label=label,
                            color=None if style == '-' else ax.lines[-1].get_color())
            missed = [n for n, v in zip(sizes, values) if not math.isfinite(v)]
            ax.plot(missed, [PEER_BUDGET] * len(missed), 'o', mfc='none',
                    color=line.get_color())
    ax.axhline(PEER_BUDGET, color='0.6', lw=0.8, ls=':')
    ax.set_yscale('log')
    ax.set_xticks(sizes)
    ax.set_xlabel('design variables n')
    ax.set_ylabel('median full runs to solve (6 starts)')
    ax.set_title(f'{scenario}, fixed step (open marker: not solved in {PEER_BUDGET})',
                 fontsize=10)
    ax.grid(True, alpha=0.3, which='both')
    ax.legend(fontsize=7, loc='lower right')
    for key, style, label in (('full_runs_ratio_vs_best_peer', '-o', 'runs to solve'),
                              ('full_runs_ratio_vs_best_peer_with_calibration', '--o',
                               'ours incl. calibration')):
        points = [(n, cases[n]['peers'][key]) for n in sizes
                  if math.isfinite(cases[n]['peers'][key])]
        ax_r.plot([n for n, _ in points], [v for _, v in points], style, label=label)
    ax_r.axhline(1.0, color='0.5', lw=0.8, ls=':')
    ax_r.set_xticks(sizes)
    ax_r.set_xlim(sizes[0] - 0.5, sizes[-1] + 0.5)
    ax_r.set_ylim(bottom=0)
    ax_r.set_xlabel('design variables n')
    ax_r.set_ylabel("best peer's median full runs / ours")
    ax_r.set_title(f'{scenario}: full-run ratio to the best peer', fontsize=10)
    ax_r.grid(True, alpha=0.3)
    ax_r.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def polish_answers(scenario: str, out: dict, eps: float) -> None:
    """SLSQP on the full fixed-step model from each of ours' final designs (budget 300).

    Where the polish ends near ours, our run ended at the local optimum of its basin;
    the polished gaps say how far each basin's optimum lies from the reference.
    """
    ours = out['results']['dq_simplified']
    reference = out['reference']
    judge = mb.FixedStepJudge(scenario, N_VARS)
    polished = mb.run_starts('slsqp', scenario, N_VARS, reference, mb.REFERENCE_INTEGRATOR,
                             judge, starts=[(r.start, np.asarray(r.x, float)) for r in ours],
                             eps=eps)
    for r, p in zip(ours, polished):
        print(f'{scenario}{N_VARS}_polished_{r.start}: ours gap {r.gap_pct:+.2f} %, polished '
              f'gap {p.gap_pct:+.2f} %, max g {p.max_violation:.4f}, full runs '
              f'{p.full_runs}, x {np.round(p.x, 3).tolist()}')
    best = min((p for p in polished if p.feasible), key=lambda p: p.f_fixed_step,
               default=None)
    if best is not None and best.f_fixed_step < reference.f:
        print(f'{scenario}{N_VARS}_lower_feasible_f_found: {best.f_fixed_step:.6f} (polish '
              f'from {best.start}, x {np.round(best.x, 4).tolist()})')
    else:
        print(f'{scenario}{N_VARS}_lower_feasible_f_found: none')


def rerun_answers(scenario: str, out: dict) -> None:
    """Ours once more from each of ours' final designs: a second run with its move limit
    and correction started afresh (the bars' columns seeded again there), the same
    calibration.  Per start the better of the two answers, and what both runs paid.
    """  # noqa: D205
    ours = out['results']['dq_simplified']
    again = mb.run_starts('dq_simplified', scenario, N_VARS, out['reference'],
                          out['integrator'], mb.FixedStepJudge(scenario, N_VARS),
                          starts=[(r.start, np.asarray(r.x, float)) for r in ours],
                          gradient=out['gradient'], calibration_samples=0)
    best, paid = [], []
    for r, a in zip(ours, again):
        chosen = a if a.feasible and a.f_fixed_step < r.f_fixed_step else r
        solved = chosen.solved
        total = out['calibration_runs'] + r.full_runs + a.full_runs
        best.append(chosen.gap_pct)
        paid.append(total if solved else math.inf)
        print(f'{scenario}{N_VARS}_rerun_{r.start}: first gap {r.gap_pct:+.2f} % ({r.full_runs} '
              f'full runs), rerun gap {a.gap_pct:+.2f} % ({a.full_runs}), solved {solved}')
    print(f'{scenario}{N_VARS}_rerun_starts_solved: {sum(math.isfinite(p) for p in paid)}')
    print(f'{scenario}{N_VARS}_rerun_median_gap_pct: {float(np.median(best)):.3f}')
    print(f'{scenario}{N_VARS}_rerun_paid_full_runs: {runs(float(np.median(paid)))}')


def more_starts_rate(scenario: str, out: dict, count: int, suffix: str) -> None:
    """Ours alone from ``count`` more seeded starts (:func:`method_benchmark.more_starts`)
    on the model of ``out``, with its gradient: the share of the 6 + ``count`` starts
    solved, which the 6 alone estimate coarsely (one start is 17 %).
    """  # noqa: D205
    case = f'{scenario}{N_VARS}'
    more = mb.run_starts('dq_simplified', scenario, N_VARS, out['reference'],
                         out['integrator'], mb.FixedStepJudge(scenario, N_VARS),
                         starts=mb.more_starts(N_VARS, count), gradient=out['gradient'],
                         calibration_samples=out['calibration_runs'])
    for r in more:
        print(f'{case}_start_{r.start}{suffix}: gap_pct {r.gap_pct:+.3f}, max_violation '
              f'{r.max_violation:.3g}, full_runs {r.full_runs}, stop {r.stop_test}',
              flush=True)
    every = list(out['results']['dq_simplified']) + more
    gaps = [r.gap_pct for r in every]
    total = len(every)
    print(f'{case}_starts_solved_of_{total}{suffix}: {sum(r.solved for r in every)}')
    print(f'{case}_starts_within_5pct_of_{total}{suffix}: '
          f'{sum(g <= max(mb.LOOSE_GAPS_PCT) for g in gaps)}')
    print(f'{case}_median_gap_pct_of_{total}{suffix}: {float(np.median(gaps)):.3f}')
    # every full run to the stop (the check's included), solved or not, and the calibration
    print(f'{case}_median_full_runs_to_stop_of_{total}{suffix}: '
          f'{float(np.median([r.calibration_runs + r.full_runs for r in every])):g}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--scenario', choices=SCENARIOS, default='ride',
                        help='the case (default ride)')
    parser.add_argument('--write-reference', action='store_true',
                        help="search the case's 8-variable reference and write it "
                             '(see above)')
    parser.add_argument('--peers', default='cobyla',
                        help="comma-separated peers, 'all', or 'none' (ours alone; no "
                             'ratio lines) (default cobyla)')
    parser.add_argument('--noisy', action='store_true',
                        help='the variable-step model too')
    parser.add_argument('--ratio-n', type=int, nargs='*', default=None,
                        help='sizes of the ratio_by_n lines (default 2 4 8; mixed: 8, the '
                             'two-state preset; the 8-variable lines need 8)')
    parser.add_argument('--jobs', type=int, default=1, help='(reserved) worker processes')
    parser.add_argument('--plot-dir', type=Path, metavar='DIR',
                        help='write the 8-variable data profiles (method_peers_<scenario>'
                             '_8var.png, at 1 %%, and _8var_5pct.png) and the runs against '
                             'n (method_runs_by_n_<scenario>.png) there')
    parser.add_argument('--polish-answers', type=float, default=0.0, metavar='EPS',
                        help="polish ours' final 8-variable designs (fixed step) with SLSQP "
                             'on the full model, forward-difference step EPS (normalised; '
                             'e.g. 0.025): the local optimum of the basin each run ended in')
    parser.add_argument('--rerun-answers', action='store_true',
                        help="run ours once more from each of ours' final 8-variable designs "
                             '(a fresh move limit and correction)')
    parser.add_argument('--calibration-samples', type=int, default=-1, metavar='N',
                        help="ours' eq. 25 samples (0: none; default -1: what a tuning "
                        'goal spends, config/simplified_models.yaml scaling.run_samples)')
    parser.add_argument('--more-starts', type=int, default=0, metavar='N',
                        help='ours alone from N more seeded starts too (8 variables, and '
                             'the noisy model with --noisy): the share of the 6 + N solved')
    args = parser.parse_args()
    if args.more_starts < 0:
        parser.error(f'--more-starts must be >= 0, got {args.more_starts}')
    if args.write_reference:
        write_reference(args.scenario)
        return
    peers = (PEERS if args.peers == 'all' else () if args.peers == 'none'
             else tuple(p for p in args.peers.split(',') if p))
    unknown = [p for p in peers if p not in PEERS]
    if unknown:
        raise SystemExit(f'unknown peer(s) {unknown}; valid: {", ".join(PEERS)}, all')
    install_study_extra()
    t0 = time.perf_counter()
    scenario = args.scenario
    if not peers and args.plot_dir is not None:
        parser.error('--plot-dir plots ours against the peers: name at least one peer')
    print(f'{scenario}{N_VARS}_peers: {",".join(peers) or "none"}')
    if TWO_STATE_FOLDER is not None:
        print(f'{scenario}{N_VARS}_design: preset two_state8 of {TWO_STATE_FOLDER} '
              '(suspension_tuning.studies.two_state)')
    sizes = args.ratio_n if args.ratio_n is not None else (
        [N_VARS] if scenario == 'mixed' else [2, 4, N_VARS])
    cases = {}
    for n in sorted(set(sizes)):
        cases[n] = run_case(scenario, n, mb.REFERENCE_INTEGRATOR, peers, args.jobs,
                            samples=args.calibration_samples)
        print(f'{scenario}{n}_reference_f: {cases[n]["reference"].f:.6f}', flush=True)
    if N_VARS in cases:
        print_case(scenario, cases[N_VARS], '')
        if args.polish_answers > 0.0:
            polish_answers(scenario, cases[N_VARS], args.polish_answers)
        if args.rerun_answers:
            rerun_answers(scenario, cases[N_VARS])
        if args.more_starts:
            more_starts_rate(scenario, cases[N_VARS], args.more_starts, '')
    for n in sorted(set(sizes)):
        out = cases[n]
        p = out['peers']
        if p is None:
            continue
        ours = out['summaries']['dq_simplified']['median_full_runs']
        print(f'ratio_by_n: {scenario} n {n}, ours_median_full_runs {runs(ours)}, ours_solved '
              f'{out["summaries"]["dq_simplified"]["starts_solved"]}, best_peer '
              f'{best_peer_text(p)} {runs(p["peer_best_full_runs"])}, calibration_runs '
              f'{out["calibration_runs"]}, ratio '
              f'{ratio_text(p["full_runs_ratio_vs_best_peer"], ours, p)}, paid_ratio '
              f'{ratio_text(p["full_runs_ratio_vs_best_peer_with_calibration"], ours, p)}')
    print(f'bench_{scenario}{N_VARS}_fixed_step_wall_s: {time.perf_counter() - t0:.1f}',
          flush=True)
    profiled = [cases[N_VARS]] if N_VARS in cases else []
    if args.noisy:
        noisy = run_case(scenario, N_VARS, NOISY, peers, args.jobs,
                         samples=args.calibration_samples)
        print_case(scenario, noisy, '_noisy')
        if args.more_starts:
            more_starts_rate(scenario, noisy, args.more_starts, '_noisy')
        profiled.append(noisy)
    if args.plot_dir is not None:
        if profiled:
            path = data_profile(profiled, args.plot_dir / f'method_peers_{scenario}_8var.png')
            print(f'{scenario}{N_VARS}_data_profile: {path}')
            loose = max(mb.LOOSE_GAPS_PCT)
            path = data_profile(profiled, args.plot_dir / f'method_peers_{scenario}_8var_'
                                f'{loose:g}pct.png', gap_pct=loose)
            print(f'{scenario}{N_VARS}_data_profile_{loose:g}pct: {path}')
        if len(cases) > 1:
            path = plot_by_n(scenario, cases,
                             args.plot_dir / f'method_runs_by_n_{scenario}.png')
            print(f'{scenario}_runs_by_n_plot: {path}')
    print(f'bench_{scenario}{N_VARS}_wall_s: {time.perf_counter() - t0:.1f}')


if __name__ == '__main__':
    main()
