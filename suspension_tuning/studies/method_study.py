"""The method study: does the simplified-gradient approach pay off? (paper section 2).

The library of the ``study`` command (:mod:`suspension_tuning.study`, whose docstring
says what it runs): every method on every case (:func:`run_case`, :func:`run_study`),
the noise-optimal forward-difference step of SLSQP on the noisy model
(:func:`noise_optimal_fd_step`), the comparison with the peers an engineer would pick
instead (:func:`run_peer_study`), and the study's tables and plots.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from suspension_tuning.optim.simplified_gradient import SimplifiedGradient, calibrate
from suspension_tuning.studies.common import (
    ACTIVE_G_TOL,
    FD_STEP,
    GRID_POINTS,
    METHOD_LABELS,
    N_VARS,
    POLISH_STARTS,
    SCENARIOS,
    SLSQP_EPS,
    STARTS,
    FullModelCache,
    Recorder,
    StudyRun,
    active_constraints,
    cal_label,
    fmt,
    fmt_g,
    integrator_name,
    max_violation,
    recording,
    reference_optimum,
    run_dynamic_q,
    run_slsqp,
    start_point,
    write_bag,
)
from suspension_tuning.tuning import centre, physical_settings
from suspension_tuning.vehicle.design import validate_design
from suspension_tuning.vehicle.scenarios import run_scenario

#: The same for ``--quick`` (a smoke run, not a reference worth reporting).
QUICK_GRID_POINTS = {2: 11, 4: 3}
#: Calibration sample counts of the simplified-gradient runs [P s.6.3.1: 30;
#: fewer are allowed if the optimum holds: 16 = the 2^4 corners for n = 4].
CALIBRATION_SAMPLES = (30, 16)
#: Grid points per axis of the fixed-step reference in the noisy study [E].  On the sett
#: paving the tyre-hop constraints are step functions of the design: a design at the
#: noisy model's constraint boundary is often just infeasible on the fixed-step model,
#: and SLSQP's polish cannot cross such a step.  In the smooth study the reference came
#: from Dynamic-Q with full-model gradients every time (grids and polish ended higher),
#: so the fixed-step reference also starts from that method run on the fixed-step model
#: itself, from both start points; a coarse grid then suffices.
FIXED_REFERENCE_GRID = {2: 5, 4: 3}


# ---------------------------------------------------------------------- study
def compare_to_reference(runs: Sequence[StudyRun], reference: StudyRun) -> None:
    """Fill each run's distance and objective gap to the reference optimum."""
    x_ref = np.asarray(reference.x)
    for run in runs:
        run.distance_to_reference = float(np.linalg.norm(np.asarray(run.x) - x_ref))
        run.gap_to_reference_pct = 100.0 * (run.f - reference.f) / abs(reference.f)


def committed_reference_run(committed: Any, integrator: str | None = 'fixed_step',
                            record: bool = True) -> tuple[StudyRun, Recorder]:
    """A committed reference optimum as the study's reference row (one full run).

    ``committed`` is a :class:`~suspension_tuning.studies.method_benchmark.Reference`
    (fixed-step model).  Its design is run once on ``integrator``: on the fixed-step
    model the row keeps the committed f and g (``details['f_rerun']`` is the run's,
    equal unless the model changed since the file was written); on another model the
    row holds that model's f and g at the committed design.
    """
    model = FullModelCache(committed.scenario, committed.n_vars, integrator)
    recorder = Recorder(record)
    history: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    x = validate_design(committed.x, committed.n_vars)[0]
    f_run, g_run = model(x)
    recording(model, history, recorder)(x)
    on_fixed = integrator_name(integrator) == 'fixed_step'
    f, g = (committed.f, list(committed.g)) if on_fixed else (f_run, g_run.tolist())
    message = ('committed reference (best known on the fixed-step model)' if on_fixed else
               'committed fixed-step reference design, run on this model (not searched)')
    run = StudyRun(
        scenario=committed.scenario, n_vars=committed.n_vars, start='-', method='reference',
        calibration_samples=0, x=x.tolist(), f=float(f), g=[float(v) for v in g],
        max_violation=max_violation(g), iterations=0, n_full_runs=model.n_runs,
        n_simplified_runs=0, n_calibration_runs=0, wall_time_s=time.perf_counter() - t0,
        success=True, message=message, history=history,
        details={'committed': True, 'found_by': committed.found_by,
                 'committed_f': committed.f, 'f_rerun': f_run,
                 'gtol': 1e-3, 'integrator': integrator_name(integrator)},
    )
    return run, recorder


def best_known_reference(reference: StudyRun, committed: Any,
                         log: Callable[[str], None] = print) -> None:
    """Make a searched fixed-step reference the best known one, in place.

    The committed reference replaces the searched point when it is feasible (max g <=
    1e-3) and lower; ``details`` records the committed f and which one is used.  A
    search that ends lower is said so: it may replace the committed entry
    (``--write-references``).
    """
    reference.details['committed_f'] = committed.f
    if max_violation(committed.g) <= 1e-3 and committed.f < reference.f:
        reference.details['searched_f'] = reference.f
        reference.x, reference.f = list(committed.x), float(committed.f)
        reference.g = [float(v) for v in committed.g]
        reference.max_violation = max_violation(reference.g)
        reference.message += ' (the committed reference is lower and is used)'
    elif reference.f < committed.f:
        log(f'  {reference.scenario}_{reference.n_vars}var: the search found f = '
            f'{reference.f:.6f}, lower than the committed {committed.f:.6f} (write it with '
            f'--write-references)')


def run_case(
    scenario: str,
    n_vars: int,
    starts: Sequence[str] = STARTS,
    calibration_samples: Sequence[int] = CALIBRATION_SAMPLES,
    grid_points: int | None = None,
    bags_dir: Path | None = None,
    log: Callable[[str], None] = print,
    slsqp_eps: float = SLSQP_EPS,
    integrator: str | None = None,
    best_fd_step: float | None = None,
    fixed_reference: bool = False,
    committed: Any = None,
    search_references: bool = True,
) -> dict[str, Any]:
    """All methods on one scenario and number of variables, from every start point.

    ``committed`` is the case's committed reference optimum on the fixed-step model
    (:class:`~suspension_tuning.studies.method_benchmark.Reference`).  Without
    ``search_references`` it is the reference (a noisy study also runs its design on
    the variable-step model, as the noisy model's reference row) and nothing is
    searched; with it the searches below run and the fixed-step reference is the better
    of the search's and the committed one (the best known).

    With ``best_fd_step`` SLSQP also runs with that forward-difference step
    ('slsqp_best_fd', see :func:`noise_optimal_fd_step`), and the reference's polish
    uses it.  With ``fixed_reference`` (runs on the variable-step model) the reference
    optimum of the fixed-step model is found too (a :data:`FIXED_REFERENCE_GRID`
    grid, polished from its best points, every method's final design, the noisy
    reference's included, and those of Dynamic-Q with full-model gradients run on the
    fixed-step model from every start), and every final design is run on the
    fixed-step model and compared with it.

    Returns
    -------
    dict
        ``runs`` (list of StudyRun, reference last), ``reference``, ``baseline_f``,
        ``baseline_x``.
    """
    grid_points = GRID_POINTS[n_vars] if grid_points is None else grid_points
    record = bags_dir is not None
    runs: list[tuple[StudyRun, Recorder]] = []
    for samples in calibration_samples:
        t0 = time.perf_counter()
        scaling = calibrate(
            scenario, n_vars, n_samples=samples,
            run_full=lambda sc, x: run_scenario(sc, x, integrator=integrator),
        )  # fmt: skip
        cal_wall = time.perf_counter() - t0
        gradient = SimplifiedGradient(scenario, n_vars, scaling, FD_STEP)
        for start in starts:
            runs.append(
                run_dynamic_q(
                    scenario,
                    n_vars,
                    start,
                    'simplified',
                    gradient,
                    samples,
                    cal_wall,
                    record=record,
                    integrator=integrator,
                )
            )
    for start in starts:
        runs.append(
            run_dynamic_q(scenario, n_vars, start, 'full', record=record, integrator=integrator)
        )
    for start in starts:
        runs.append(
            run_slsqp(scenario, n_vars, start, record=record, eps=slsqp_eps,
                      integrator=integrator)
        )  # fmt: skip
    if best_fd_step is not None:
        for start in starts:
            runs.append(
                run_slsqp(scenario, n_vars, start, record=record, eps=best_fd_step,
                          integrator=integrator, method='slsqp_best_fd')
            )  # fmt: skip
    for run, _ in runs:
        log(
            f'  {run.name}: f = {run.f:.6f}, {run.iterations} iterations, '
            f'{run.n_full_runs} full + {run.n_calibration_runs} calibration runs, '
            f'{run.wall_time_s:.1f} s'
        )
    if not search_references and committed is None:
        raise ValueError(f'{scenario}, {n_vars} variables: no committed reference; search '
                         'one (--search-references)')
    if search_references:
        reference, ref_recorder = reference_optimum(
            scenario, n_vars, grid_points, [r.x for r, _ in runs], record=record,
            integrator=integrator,
            polish_eps=slsqp_eps if best_fd_step is None else best_fd_step,
        )  # fmt: skip
        if committed is not None and not fixed_reference:
            best_known_reference(reference, committed, log)
    else:
        reference, ref_recorder = committed_reference_run(committed, integrator, record)
    log(
        f'  {scenario}_{n_vars}var reference: f = {reference.f:.6f} '
        f'({reference.message}, {reference.n_full_runs} full runs, '
        f'{reference.wall_time_s:.1f} s)'
    )
    runs.append((reference, ref_recorder))
    compare_to_reference([r for r, _ in runs], reference)
    fixed_ref = None
    if fixed_reference and not search_references:
        fixed_ref, _ = committed_reference_run(committed, 'fixed_step', record=False)
    if fixed_reference and search_references:
        finals = np.array([r.x for r, _ in runs])
        # Dynamic-Q with full-model gradients on the fixed-step model (see
        # FIXED_REFERENCE_GRID): its final designs are starts of the fixed reference.
        fixed_dq = [run_dynamic_q(scenario, n_vars, start, 'full', record=False,
                                  integrator='fixed_step')[0] for start in starts]
        fixed_ref, _ = reference_optimum(
            scenario, n_vars, min(grid_points, FIXED_REFERENCE_GRID[n_vars]),
            np.vstack([finals, [r.x for r in fixed_dq]]), record=False,
            integrator='fixed_step',
        )  # fmt: skip
        fixed_ref.n_full_runs += sum(r.n_full_runs for r in fixed_dq)
        fixed_ref.details['dq_full_fixed_step_f'] = [r.f for r in fixed_dq]
        fixed_ref.message += ' and Dynamic-Q (full gradients, fixed-step model)'
        if committed is not None:
            best_known_reference(fixed_ref, committed, log)
    if fixed_ref is not None:
        finals = np.array([r.x for r, _ in runs])
        log(f'  {scenario}_{n_vars}var fixed-step reference: f = {fixed_ref.f:.6f} '
            f'({fixed_ref.n_full_runs} full runs, {fixed_ref.wall_time_s:.1f} s)')
        fixed = run_scenario(scenario, finals, n_vars=n_vars, integrator='fixed_step')
        for (run, _), f, g in zip(runs, fixed.f, fixed.g):
            run.f_fixed_step = float(f)
            run.max_violation_fixed_step = max_violation(g)
            run.gap_to_fixed_reference_pct = (
                100.0 * (float(f) - fixed_ref.f) / abs(fixed_ref.f)
            )
    if bags_dir is not None:
        for run, recorder in runs:
            run.bag = str(write_bag(bags_dir / run.name, run, recorder))
    x_base = start_point('baseline', n_vars)
    base = run_scenario(scenario, x_base[None, :], n_vars=n_vars, integrator=integrator)
    return {
        'runs': [r for r, _ in runs],
        'reference': reference,
        'fixed_reference': fixed_ref,
        'baseline_f': float(base.f[0]),
        'baseline_x': x_base.tolist(),
        'integrator': integrator_name(integrator),
        'best_fd_step': best_fd_step,
    }


def forward_difference_step(noise: float, curvature: float, largest: float = 0.1) -> float:
    """More & Wild's noise-optimal forward-difference step ``8^(1/4) sqrt(noise/|f''|)``.

    Minimises the bound |f''| h / 2 + 2 noise / h of a forward difference's error
    (noise = standard deviation of f's noise, curvature = f'').  Without noise the step
    is 0 (any small step does); without curvature it is ``largest``.
    """
    if noise <= 0.0:
        return 0.0
    if curvature == 0.0:
        return largest
    return float(min(largest, 8.0**0.25 * math.sqrt(noise / abs(curvature))))


def noise_optimal_fd_step(
    scenario: str,
    n_vars: int,
    integrator: str | None = 'variable_step',
    n_points: int = 41,
    half_width: float = 0.1,
) -> dict[str, Any]:
    """Forward-difference step that balances truncation and noise (More & Wild 2012).

    For f with noise of standard deviation eps_f and second derivative mu, the error
    of a forward difference with step h is about |mu| h / 2 + 2 eps_f / h, least at
    ``h* = 8^(1/4) sqrt(eps_f / |mu|)`` (More & Wild, "Estimating derivatives of noisy
    simulations", ACM TOMS 38(3), 2012, eq. 2.3 with their constant).  Each variable
    is swept through the centre of the design space (``n_points`` designs over
    centre +- ``half_width``, one batch per variable); eps_f is the third-difference
    noise estimate (:func:`suspension_tuning.studies.noise.noise_measure`) and mu the
    curvature of a quadratic fitted to the sweep.  SLSQP takes one step for every
    variable: the median of the per-variable steps, clipped to [1e-4, 0.1].

    Returns
    -------
    dict
        'step', 'per_variable' (list), 'noise' (list of eps_f), 'curvature' (list of
        mu), 'full_runs' (n_vars * n_points, spent on finding the step).
    """
    from suspension_tuning.studies.noise import noise_measure

    c = centre(n_vars)
    xs = np.linspace(c[0] - half_width, c[0] + half_width, n_points)
    steps, noises, curvatures = [], [], []
    for k in range(n_vars):
        x = np.tile(c, (n_points, 1))
        x[:, k] = xs
        f = np.asarray(run_scenario(scenario, x, n_vars=n_vars, integrator=integrator).f)
        eps_f = noise_measure(xs, f)['noise_rms']
        mu = 2.0 * np.polyfit(xs, f, 2)[0]
        noises.append(float(eps_f))
        curvatures.append(float(mu))
        steps.append(forward_difference_step(eps_f, mu))
    step = float(np.clip(np.median(steps), 1e-4, 0.1))
    return {'step': step, 'per_variable': steps, 'noise': noises, 'curvature': curvatures,
            'full_runs': n_vars * n_points}  # fmt: skip


def noisy_ratios(case: dict[str, Any], calibration_samples: int,
                 max_gap_pct: float = 1.0) -> dict[str, Any]:
    """The noisy-model headline: the best SLSQP variant within ``max_gap_pct`` of the
    reference against simplified-gradient Dynamic-Q (totals over the start points).

    Gaps are to the reference optimum of the same (variable-step) model.  The best
    SLSQP variant is the cheaper of 'slsqp' and 'slsqp_best_fd' among those whose
    every start ends within ``max_gap_pct``; if neither does, the one with the
    smaller worst gap (``slsqp_within_gap`` False).
    """  # noqa: D205
    runs = case['runs']
    simp = [r for r in runs
            if r.method == 'dq_simplified' and r.calibration_samples == calibration_samples]
    n_simp = sum(r.n_full_runs for r in simp)
    variants = {}
    for m in ('slsqp', 'slsqp_best_fd'):
        rs = [r for r in runs if r.method == m]
        if rs:
            variants[m] = (sum(r.n_full_runs for r in rs),
                           max(r.gap_to_reference_pct for r in rs))
    within = {m: v for m, v in variants.items() if v[1] <= max_gap_pct}
    if within:
        best = min(within, key=lambda m: within[m][0])
    else:
        best = min(variants, key=lambda m: variants[m][1])
    n_best = variants[best][0]
    return {
        'best_slsqp_variant': best,
        'slsqp_within_gap': bool(within),
        'best_slsqp_full_runs': n_best,
        'best_slsqp_gap_pct': variants[best][1],
        'dq_simplified_full_runs': n_simp,
        'full_runs_ratio_vs_slsqp_noisy': n_best / n_simp,
        'full_runs_ratio_vs_slsqp_noisy_with_calibration': n_best / (
            n_simp + len(simp) * calibration_samples),
        'optimum_gap_pct_noisy': max(r.gap_to_reference_pct for r in simp),
        'optimum_gap_to_fixed_reference_pct_noisy': max(
            r.gap_to_fixed_reference_pct for r in simp),
        'slsqp_default_gap_pct_noisy': variants.get('slsqp', (0, math.nan))[1],
    }  # fmt: skip


def cost_ratios(case: dict[str, Any], calibration_samples: int) -> dict[str, float]:
    """SLSQP and full-gradient Dynamic-Q full runs over simplified-gradient Dynamic-Q's.

    Totals over the start points of the case; ``..._with_calibration``: the calibration
    counted once per run; ``..._calibration_shared``: once for all the start points (the
    coordinator caches it).
    """
    runs = case['runs']
    simp = [
        r
        for r in runs
        if r.method == 'dq_simplified' and r.calibration_samples == calibration_samples
    ]
    slsqp = [r for r in runs if r.method == 'slsqp']
    dq_full = [r for r in runs if r.method == 'dq_full']
    n_simp = sum(r.n_full_runs for r in simp)
    n_simp_cal = sum(r.full_runs_with_calibration for r in simp)
    n_simp_shared = n_simp + calibration_samples  # one calibration for all start points
    n_slsqp = sum(r.n_full_runs for r in slsqp)
    worst_simp = max(r.f for r in simp)
    best_slsqp = min(r.f for r in slsqp)
    return {
        'full_runs_ratio_vs_slsqp': n_slsqp / n_simp,
        'full_runs_ratio_vs_slsqp_with_calibration': n_slsqp / n_simp_cal,
        'full_runs_ratio_vs_slsqp_calibration_shared': n_slsqp / n_simp_shared,
        'full_runs_ratio_vs_dq_full': sum(r.n_full_runs for r in dq_full) / n_simp,
        'full_runs_ratio_vs_dq_full_with_calibration': sum(r.n_full_runs for r in dq_full)
        / n_simp_cal,
        'objective_gap_vs_slsqp_pct': 100.0 * (worst_simp - best_slsqp) / abs(best_slsqp),
        'optimum_gap_pct': max(r.gap_to_reference_pct for r in simp),
    }


# ---------------------------------------------------------------------- outputs


def markdown_tables(cases: Sequence[dict[str, Any]], calibration_samples: Sequence[int]) -> str:
    """The study's Markdown: the run table, settings against baseline, cost ratios."""
    lines = [
        '| scenario | n | start | method | cal. N | f | max viol. | dist. to ref. '
        '| f gap to ref. % | iter. | full runs | simpl. runs | calib. runs '
        '| full runs incl. calib. | wall s (calib. s) |',
        '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for case in cases:
        for r in case['runs']:
            cal = cal_label(r)
            wall = f'{r.wall_time_s:.1f}'
            iters = '-' if r.method == 'reference' else str(r.iterations)
            if r.method == 'dq_simplified':
                wall += f' ({r.calibration_wall_time_s:.1f})'
            lines.append(
                f'| {r.scenario} | {r.n_vars} | {r.start} | {r.method} | {cal} | '
                f'{r.f:.5f} | {r.max_violation:.3g} | {r.distance_to_reference:.3f} | '
                f'{r.gap_to_reference_pct:+.3f} | {iters} | {r.n_full_runs} | '
                f'{r.n_simplified_runs} | {r.n_calibration_runs} | '
                f'{r.full_runs_with_calibration} | {wall} |'
            )
    lines += [
        '',
        f'**Tyre-hop constraints (eq. 11) at the final points** (active: g >= '
        f'-{ACTIVE_G_TOL}, i.e. within {10 * ACTIVE_G_TOL:.1f} % of the run time of the '
        f'10 % limit; violation = max(0, max g))',
        '',
        '| scenario | n | start | method | cal. N | g FL | g FR | g RL | g RR '
        '| active constraints | violation |',
        '|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for case in cases:
        for r in case['runs']:
            cal = cal_label(r)
            active = ', '.join(active_constraints(r.g)) or 'none'
            cells = ' | '.join(f'{v:+.3f}' for v in r.g)
            lines.append(
                f'| {r.scenario} | {r.n_vars} | {r.start} | {r.method} | {cal} | {cells} '
                f'| {active} | {r.max_violation:.3g} |'
            )
    lines += [
        '',
        '**Optimum settings against the baseline vehicle** (physical units; '
        'improvement = (f_baseline - f) / |f_baseline|)',
        '',
        '| scenario | n | design | dpsf front | gas front (L) | dpsf rear | gas rear (L) '
        '| f | improvement % |',
        '|---|---|---|---|---|---|---|---|---|',
    ]
    for case in cases:
        ref = case['reference']
        base_f = case['baseline_f']
        rows = [('baseline', case['baseline_x'], base_f), ('reference', ref.x, ref.f)]
        rows += [
            (f'{r.method} ({r.start}, N={r.calibration_samples})', r.x, r.f)
            for r in case['runs']
            if r.method == 'dq_simplified' and r.calibration_samples == calibration_samples[0]
        ]
        for label, x, f in rows:
            p = physical_settings(x)
            imp = 100.0 * (base_f - f) / abs(base_f)
            lines.append(
                f'| {ref.scenario} | {ref.n_vars} | {label} | {p["dpsf_front"]:.3f} | '
                f'{p["gas_volume_front_l"]:.3f} | {p["dpsf_rear"]:.3f} | '
                f'{p["gas_volume_rear_l"]:.3f} | {f:.5f} | {imp:+.2f} |'
            )
    lines += [
        '',
        '**Full-model runs: SLSQP and full-gradient Dynamic-Q over '
        'simplified-gradient Dynamic-Q** (totals over the start points; calibration '
        'counted once per run)',
        '',
        '| scenario | n | cal. N | vs SLSQP | vs SLSQP incl. calib. '
        '| vs SLSQP, one calib. for both starts | vs DQ full '
        '| vs DQ full incl. calib. | f gap vs best SLSQP % | f gap vs ref. % |',
        '|---|---|---|---|---|---|---|---|---|---|',
    ]
    for case in cases:
        ref = case['reference']
        for samples in calibration_samples:
            c = cost_ratios(case, samples)
            lines.append(
                f'| {ref.scenario} | {ref.n_vars} | {samples} | '
                f'{c["full_runs_ratio_vs_slsqp"]:.2f} | '
                f'{c["full_runs_ratio_vs_slsqp_with_calibration"]:.2f} | '
                f'{c["full_runs_ratio_vs_slsqp_calibration_shared"]:.2f} | '
                f'{c["full_runs_ratio_vs_dq_full"]:.2f} | '
                f'{c["full_runs_ratio_vs_dq_full_with_calibration"]:.2f} | '
                f'{c["objective_gap_vs_slsqp_pct"]:+.3f} | {c["optimum_gap_pct"]:+.3f} |'
            )
    lines += ['', '**Reference optima**', '']
    for case in cases:
        ref = case['reference']
        d = ref.details
        if d.get('committed'):
            lines.append(
                f'- {ref.scenario}, n = {ref.n_vars}: committed reference (best known, '
                f'fixed-step model) f = {ref.f:.5f} at x = {np.round(ref.x, 3).tolist()}, '
                f'found by {d["found_by"]}; the design re-run now: f = {d["f_rerun"]:.5f}.'
            )
            continue
        if 'committed_f' in d:
            used = 'used: lower than the search' if 'searched_f' in d else 'not lower'
            lines.append(
                f'- {ref.scenario}, n = {ref.n_vars}: committed reference f = '
                f'{d["committed_f"]:.5f} ({used}).'
            )
        lines.append(
            f'- {ref.scenario}, n = {ref.n_vars}: grid {d["grid_points_per_axis"]}^{ref.n_vars} '
            f'({d["grid_runs"]} full runs, spacing {d["grid_spacing"]:.4f}) best f = '
            f'{d["grid_best_f"]:.5f}; SLSQP polish from the {POLISH_STARTS} best grid points '
            f"best f = {fmt(d['polished_from_grid_best_f'], 5)}, from the methods' final "
            f'points {fmt(d["polished_from_methods_best_f"], 5)}; reference f = {ref.f:.5f} '
            f'at x = {np.round(ref.x, 3).tolist()} ({ref.wall_time_s:.1f} s).'
        )
    return '\n'.join(lines) + '\n'


def plot_case(case: dict[str, Any], start: str, path: Path) -> Path:
    """f against full-model runs per method (left: optimisation; right: incl. calibration)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    ref = case['reference']
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True)
    styles = {'dq_simplified': '-o', 'dq_full': '-s', 'slsqp': '-^', 'slsqp_best_fd': '-v'}
    for ax, with_cal in zip(axes, (False, True)):
        for r in case['runs']:
            if r.start != start or r.method not in styles:
                continue
            offset = r.n_calibration_runs if with_cal else 0
            runs = [h['n_full_runs'] + offset for h in r.history]
            label = METHOD_LABELS[r.method]
            if r.method == 'dq_simplified':
                label += f' (N = {r.calibration_samples})'
            ax.plot(runs, [h['f'] for h in r.history], styles[r.method], ms=3, label=label)
        ax.axhline(ref.f, color='k', ls='--', lw=0.8, label=f'reference f = {ref.f:.5f}')
        ax.set_xlabel('full-model runs' + (' incl. eq. 25 calibration' if with_cal else ''))
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel('objective f (full model)')
    axes[0].legend(fontsize=7)
    eq = 'eq. 9' if ref.scenario == 'ride' else 'eq. 10'
    fig.suptitle(f'{ref.scenario} ({eq}), {ref.n_vars} variables, start: {start}')
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run_study(
    out: Path,
    scenarios: Sequence[str] = SCENARIOS,
    n_vars_list: Sequence[int] = N_VARS,
    starts: Sequence[str] = STARTS,
    calibration_samples: Sequence[int] = CALIBRATION_SAMPLES,
    grid_points: dict[int, int] | None = None,
    bags: bool = True,
    log: Callable[[str], None] = print,
    slsqp_eps: float = SLSQP_EPS,
    integrator: str | None = None,
    search_references: bool = False,
    references: str | Path | None = None,
) -> dict[str, Any]:
    """Run every case, write the tables, plots, JSON and bags under ``out``.

    The reference of each case is the committed one (``references``, default
    benchmarks/references.json: the best known feasible optimum on the fixed-step
    model); with ``search_references`` the reference searches run as well and the
    better of the two is used (see :func:`run_case`).

    With ``integrator='variable_step'`` the study runs on the noisy variable-step full
    model: SLSQP also with the noise-optimal step (:func:`noise_optimal_fd_step`), the
    reference optimum on both models, and the outputs ``method_study_noisy.md``,
    ``results_noisy.json``, ``plots/noisy_*.png`` and ``bags/noisy_*``.

    Returns
    -------
    dict
        ``cases`` (as :func:`run_case`), ``markdown``, ``plots``, ``wall_time_s``.
    """
    for s in scenarios:
        if s not in SCENARIOS:
            raise ValueError(f'unknown scenario {s!r}; valid: {", ".join(SCENARIOS)}')
    for n in n_vars_list:
        if n not in N_VARS:
            raise ValueError(f'n_vars must be 2 or 4, got {n}')
    for s in starts:
        start_point(s, 2)
    if not (np.isfinite(slsqp_eps) and 0.0 < slsqp_eps <= 0.25):
        raise ValueError(f'the SLSQP step must lie in (0, 0.25], got {slsqp_eps}')
    if not calibration_samples or min(calibration_samples) < 2:
        raise ValueError(f'calibration sample counts must be >= 2, got {calibration_samples}')
    grid_points = {**GRID_POINTS, **(grid_points or {})}
    from suspension_tuning.studies import method_benchmark as mb

    try:
        committed = mb.load_references(references)
    except FileNotFoundError as error:
        if not search_references:
            raise ValueError(f'{error}, or search them with --search-references') from None
        committed = {}
    if not search_references:
        missing = [mb.case_key(s, n) for s in scenarios for n in n_vars_list
                   if mb.case_key(s, n) not in committed]
        if missing:
            raise ValueError(f'no committed reference for {", ".join(missing)}; search them '
                             f'with --search-references or write them with '
                             f'{mb.REFERENCES_COMMAND}')
    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    noisy = integrator == 'variable_step'
    tag = 'noisy_' if noisy else ''
    for s in scenarios:  # numba compile / cache load outside every timed run
        for integ in ('fixed_step', integrator):
            run_scenario(s, centre(2)[None, :], n_vars=2, integrator=integ)
    cases, plots = [], []
    for scenario in scenarios:
        for n in n_vars_list:
            log(f'== {scenario}, {n} variables' + (' (variable-step model)' if noisy else ''))
            step = noise_optimal_fd_step(scenario, n, integrator) if noisy else None
            if step is not None:
                log(f'  noise-optimal forward-difference step {step["step"]:.4f} '
                    f'({step["full_runs"]} full runs)')
            case = run_case(
                scenario,
                n,
                starts,
                calibration_samples,
                grid_points[n],
                (out / 'bags' / 'noisy' if noisy else out / 'bags') if bags else None,
                log,
                slsqp_eps,
                integrator=integrator,
                best_fd_step=None if step is None else step['step'],
                fixed_reference=noisy,
                committed=committed.get(mb.case_key(scenario, n)),
                search_references=search_references,
            )
            case['fd_step_search'] = step
            cases.append(case)
            for start in starts:
                plots.append(
                    plot_case(case, start,
                              out / 'plots' / f'{tag}{scenario}_{n}var_{start}.png')
                )  # fmt: skip
    wall = time.perf_counter() - t0
    grids = ', '.join(f'{grid_points[n]}^{n}' for n in n_vars_list)
    source = references or 'benchmarks/references.json'
    if search_references:
        ref_text = (f'reference grids {grids} then SLSQP polish'
                    + (', on each model' if noisy else '')
                    + f'; the committed fixed-step reference ({source}) where that is lower')
    elif noisy:
        ref_text = (f'references: the committed best known fixed-step optima ({source}); the '
                    "noisy model's reference row is the committed design run on the noisy "
                    'model, not a search (`--search-references` searches both)')
    else:
        ref_text = (f'references: the committed best known optima ({source}, fixed-step '
                    'model; `--search-references` searches them again)')
    if noisy:
        return _write_noisy(out, cases, calibration_samples, ref_text, slsqp_eps, wall,
                            plots)
    text = (
        f'# Method study: simplified-model gradients against full-model gradients\n\n'
        f'Generated by `study` in {wall:.0f} s.  Dynamic-Q: config/optimiser.yaml '
        f'`vehicle` options, central-difference half step {FD_STEP} (simplified and full '
        f'gradients); SLSQP: SciPy defaults (maxiter 100, ftol 1e-6), 2-point forward '
        f'differences with step {slsqp_eps:.3g}; {ref_text}.  '
        f'Distances in normalised units (0.001..1 per variable); f gap = '
        f'100 (f - f_ref) / |f_ref|.\n\n' + markdown_tables(cases, calibration_samples)
    )
    (out / 'method_study.md').write_text(text)
    _write_results(out / 'results.json', cases, wall, lambda c: {
        'baseline_x': c['baseline_x'],
        'ratios': {str(s): cost_ratios(c, s) for s in calibration_samples}})
    return {'cases': cases, 'markdown': text, 'plots': plots, 'wall_time_s': wall}


def _write_results(path: Path, cases: Sequence[dict[str, Any]], wall: float,
                   extra: Callable[[dict[str, Any]], dict[str, Any]]) -> None:
    """Every case's runs (and ``extra(case)``) as JSON."""
    payload = {'wall_time_s': wall, 'cases': [
        {'scenario': c['reference'].scenario, 'n_vars': c['reference'].n_vars,
         'baseline_f': c['baseline_f'], **extra(c),
         'runs': [{**asdict(r), 'name': r.name} for r in c['runs']]}
        for c in cases]}  # fmt: skip
    path.write_text(json.dumps(payload, indent=1, default=float))


def noisy_markdown(cases: Sequence[dict[str, Any]], calibration_samples: Sequence[int]) -> str:
    """Tables of the study on the variable-step (noisy) model."""
    lines = [
        '| scenario | n | start | method | cal. N | FD step | f (noisy) | gap to noisy ref. % '
        '| f on fixed-step | gap to fixed-step ref. % | max viol. | max viol. on fixed-step '
        '| iter. | full runs | calib. runs | message |',
        '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for case in cases:
        for r in case['runs']:
            cal = str(r.calibration_samples) if r.method == 'dq_simplified' else '-'
            step = {'dq_simplified': FD_STEP, 'dq_full': FD_STEP}.get(
                r.method, r.details.get('eps', r.details.get('polish_eps', math.nan))
            )
            iters = '-' if r.method == 'reference' else str(r.iterations)
            lines.append(
                f'| {r.scenario} | {r.n_vars} | {r.start} | {r.method} | {cal} | {fmt_g(step)} | '
                f'{r.f:.5f} | {r.gap_to_reference_pct:+.3f} | {r.f_fixed_step:.5f} | '
                f'{r.gap_to_fixed_reference_pct:+.3f} | {r.max_violation:.3g} | '
                f'{r.max_violation_fixed_step:.3g} | {iters} | '
                f'{r.n_full_runs} | {r.n_calibration_runs} | {r.message[:40]} |'
            )
    lines += [
        '',
        '**Full-model runs of the best SLSQP variant within 1 % of the noisy reference over '
        "those of simplified-gradient Dynamic-Q** (totals over both starts; the step "
        "search's runs are not counted)",
        '',
        '| scenario | n | cal. N | best SLSQP variant | within 1 % | its runs | DQ simpl. runs '
        '| ratio | ratio incl. calib. | DQ simpl. gap % (noisy ref.) '
        '| DQ simpl. gap % (fixed-step ref.) | SLSQP default gap % |',
        '|---|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for case in cases:
        ref = case['reference']
        for samples in calibration_samples:
            c = noisy_ratios(case, samples)
            lines.append(
                f'| {ref.scenario} | {ref.n_vars} | {samples} | {c["best_slsqp_variant"]} | '
                f'{"yes" if c["slsqp_within_gap"] else "no"} | {c["best_slsqp_full_runs"]} | '
                f'{c["dq_simplified_full_runs"]} | {c["full_runs_ratio_vs_slsqp_noisy"]:.2f} | '
                f'{c["full_runs_ratio_vs_slsqp_noisy_with_calibration"]:.2f} | '
                f'{c["optimum_gap_pct_noisy"]:+.3f} | '
                f'{c["optimum_gap_to_fixed_reference_pct_noisy"]:+.3f} | '
                f'{c["slsqp_default_gap_pct_noisy"]:+.3f} |'
            )
    lines += ['', '**Reference optima and the forward-difference step**', '']
    for case in cases:
        ref, fref, st = case['reference'], case['fixed_reference'], case['fd_step_search']
        noisy_ref = ('the committed fixed-step reference design on the noisy model (no '
                     'noisy-model search)' if ref.details.get('committed') else 'noisy model')
        lines.append(
            f'- {ref.scenario}, n = {ref.n_vars}: {noisy_ref} f = {ref.f:.5f} at x = '
            f'{np.round(ref.x, 3).tolist()} ({ref.n_full_runs} full runs); fixed-step '
            f'model f = {fref.f:.5f} at x = {np.round(fref.x, 3).tolist()} '
            f'({fref.n_full_runs} full runs).  Forward-difference step: noise '
            f'{np.round(st["noise"], 6).tolist()}, curvature '
            f'{np.round(st["curvature"], 4).tolist()}, per-variable h* '
            f'{np.round(st["per_variable"], 4).tolist()} -> {st["step"]:.4f} '
            f'({st["full_runs"]} full runs).'
        )
    return '\n'.join(lines) + '\n'


def _write_noisy(out: Path, cases: list, calibration_samples: Sequence[int], ref_text: str,
                 slsqp_eps: float, wall: float, plots: list) -> dict[str, Any]:
    text = (
        '# Method study on the variable-step (noisy) full model\n\n'
        f'Generated by `study --integrator variable_step` in {wall:.0f} s.  Full model: '
        'Dormand-Prince 5(4), config/vehicle.yaml integration.variable_step.  '
        f'Dynamic-Q: config/optimiser.yaml `vehicle`, half step {FD_STEP}; SLSQP: maxiter '
        f'100, ftol 1e-6, forward differences with {slsqp_eps:.3g} (slsqp) and the '
        f'noise-optimal step (slsqp_best_fd); {ref_text}.\n\n'
        + noisy_markdown(cases, calibration_samples)
    )
    (out / 'method_study_noisy.md').write_text(text)
    _write_results(out / 'results_noisy.json', cases, wall, lambda c: {
        'fd_step_search': c['fd_step_search'],
        'fixed_reference': asdict(c['fixed_reference']),
        'ratios': {str(s): noisy_ratios(c, s) for s in calibration_samples}})
    return {'cases': cases, 'markdown': text, 'plots': plots, 'wall_time_s': wall}


def write_reference_file(path: Path, scenarios: Sequence[str], n_vars_list: Sequence[int],
                         grid_points: dict[int, int]) -> int:
    """Search every case's fixed-step reference optimum and write them to ``path``.

    See :func:`suspension_tuning.studies.method_benchmark.search_reference`; an entry
    already in ``path`` stays when it is feasible and lower (the file holds the best
    known).
    """
    from suspension_tuning.studies import method_benchmark as mb

    t0 = time.perf_counter()
    refs = []
    for scenario in scenarios:
        for n in n_vars_list:
            print(f'== {scenario}, {n} variables: reference search', flush=True)
            ref = mb.search_reference(scenario, n, grid_points[n],
                                      log=lambda s: print(s, flush=True))
            print(f'  {ref.key}: f = {ref.f:.6f} at x = {np.round(ref.x, 4).tolist()}, max '
                  f'violation {ref.max_violation:.3g} ({ref.search["full_runs"]} full runs, '
                  f'{ref.search["wall_time_s"]:.0f} s)', flush=True)
            refs.append(ref)
    status = mb.write_references(path, refs)
    for key, what in status.items():
        print(f'{key}: {what}')
    print(f'references: {path}')
    print(f'references_wall_time_s: {time.perf_counter() - t0:.1f}')
    return 0
