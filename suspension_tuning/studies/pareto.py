"""What the 4S4 buys: the passive ride-handling compromise against the switched suspension.

Thoresson et al. (2009), section 3: a suspension that switches between a ride and a
handling setting "has the ability to eliminate the traditional ride comfort vs.
handling compromise".  This study measures the compromise and how much of it the
switched 4S4 removes, in-process (no rclpy at import; the bags need the message
classes):

1. The two single-objective optima with Dynamic-Q and eq. 25-scaled simplified-model
   gradients (best of the centre and baseline starts): x_r minimises f_ride (eq. 9,
   'ride' scenario) and x_h minimises f_hand (eq. 10, 'handling' scenario), each
   subject to its own eq. 11 tyre-hop constraints.
2. The passive Pareto front (``vehicle.passive``: one design x used in both scenarios,
   f_ride(x) from 'ride', f_hand(x) from 'handling'): an epsilon-constraint sweep,
   minimise f_ride(x) subject to f_hand(x) <= eps, the handling run's eq. 11
   constraints and the ride run's own, for eps evenly inside (f_hand(x_h),
   f_hand(x_r)); each eps from two starts (the previous front point and x_h), the
   better kept.  Every point's values are the full model's; the points that another
   point beats in both objectives are dropped (:func:`non_dominated`).
3. The switched suspension: the two-state point (f_ride(x_r) in the ride state,
   f_hand(x_h) in the handling state) and the 'mixed' closed-loop run (Belgian paving,
   then the double lane change at 65 km/h) with the ride state set by x_r, the
   handling state by x_h and the valve controller switching with its 50-100 ms delay,
   and once more with the delay shortened to one control period (10 ms): what the
   delay costs.  Every passive design of the study runs the mixed scenario too, valves
   fixed, as the reference of the closed-loop gaps.

gap(f) = 100 (f - f_opt) / (f_baseline - f_opt): the share of the improvement from the
baseline vehicle (config/design_space.yaml's baseline, a passive setting) to
the single-objective optimum that a design loses.  The best passive compromise is the
front point with the smallest larger gap of the two.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from suspension_tuning import evaluation
from suspension_tuning.optim.simplified_gradient import (
    SimplifiedGradient,
    calibrate,
    calibration_settings,
)
from suspension_tuning.paths import config_dir
from suspension_tuning.studies.two_state import MIXED_ROUGH_LENGTH_M
from suspension_tuning.tuning import TYRE_HOP_NAMES, ConstraintSpec, physical_settings
from suspension_tuning.vehicle import metrics
from suspension_tuning.vehicle.full_model import SuspensionSetting
from suspension_tuning.vehicle.mixed import in_process_controllers, load_mixed_config, run_mixed
from suspension_tuning.vehicle.passive import passive_setting, switched_setting
from suspension_tuning.vehicle.valve_logic import RIDE_STATE, ValveControllerParams

Array = NDArray[np.float64]

#: Front points (eps values) per number of variables [issue: at least 8 for 4 variables].
FRONT_POINTS = {2: 8, 4: 8}
#: Start points of the single-objective optima (``common.start_point``).
END_POINT_STARTS = ('centre', 'baseline')


@dataclass
class DesignPoint:
    """One design of the study, with its full-model values in both scenarios.

    Attributes
    ----------
    name : str
        e.g. 'ride_optimum', 'front_3', 'baseline'.
    kind : str
        'ride_optimum', 'handling_optimum', 'front' or 'baseline'.
    x : list of float
        Normalised design.
    eps : float
        Upper bound on f_hand of its optimisation (NaN for the others).
    f_ride, f_hand : float
        Full-model objectives, eqs. 9 and 10.
    g_ride, g_hand : list of float
        Eq. 11 constraints of each scenario (FL, FR, RL, RR).
    ride_metrics, handling_metrics : dict
        Full-model metrics (a_rms_*_mps2, roll_first_peak_deg, ...).
    physical : dict
        Physical settings (dpsf, gas volume in litres).
    gap_ride_pct, gap_hand_pct : float
        gap(f) of each objective.
    runs : list of str
        Names of the optimisation runs (bags) behind it.
    """

    name: str
    kind: str
    x: list[float]
    eps: float = math.nan
    f_ride: float = math.nan
    f_hand: float = math.nan
    g_ride: list[float] = field(default_factory=list)
    g_hand: list[float] = field(default_factory=list)
    ride_metrics: dict[str, float] = field(default_factory=dict)
    handling_metrics: dict[str, float] = field(default_factory=dict)
    physical: dict[str, float] = field(default_factory=dict)
    gap_ride_pct: float = math.nan
    gap_hand_pct: float = math.nan
    runs: list[str] = field(default_factory=list)


def gap_pct(f: ArrayLike, f_opt: float, f_baseline: float) -> Array:
    """gap(f) = 100 (f - f_opt) / (f_baseline - f_opt), percent of the achievable gain."""
    span = f_baseline - f_opt
    if not (np.isfinite(span) and span != 0.0):
        raise ValueError(f'gap needs f_baseline != f_opt, got {f_baseline} and {f_opt}')
    return 100.0 * (np.asarray(f, dtype=float) - f_opt) / span


def non_dominated(values: ArrayLike) -> NDArray[np.bool_]:
    """Mask of the points (m, k) that no other point beats in every objective (minimised).

    A point is dominated when another is no worse in every objective and better in at
    least one; of exact duplicates the first is kept.
    """
    v = np.asarray(values, dtype=float)
    if v.ndim != 2:
        raise ValueError(f'values must have shape (m, k), got {v.shape}')
    keep = np.ones(len(v), dtype=bool)
    for i in range(len(v)):
        no_worse = np.all(v <= v[i], axis=1)
        better = np.any(v < v[i], axis=1)
        duplicate_before = np.all(v == v[i], axis=1) & (np.arange(len(v)) < i)
        keep[i] = not np.any((no_worse & better) | duplicate_before)
    return keep


def best_compromise(gaps: ArrayLike) -> int:
    """Index of the point (m, 2) of gaps whose larger gap is the smallest."""
    g = np.asarray(gaps, dtype=float)
    return int(np.argmin(np.max(g, axis=1)))


def epsilon_values(f_hand_min: float, f_hand_max: float, n_points: int) -> Array:
    """n_points bounds evenly inside (f_hand_min, f_hand_max), end points excluded."""
    if n_points < 1:
        raise ValueError(f'the front needs at least one point, got {n_points}')
    if not f_hand_max > f_hand_min:
        raise ValueError(f'f_hand of the ride optimum ({f_hand_max}) must exceed the '
                         f'handling optimum ({f_hand_min}): no compromise to sweep')
    return f_hand_min + (f_hand_max - f_hand_min) * np.arange(1, n_points + 1) / (n_points + 1)


def front_constraints(eps: float) -> list[ConstraintSpec]:
    """Extra constraints of a front point: f_hand <= eps and the handling run's eq. 11."""
    return [ConstraintSpec('handling', 'f', eps),
            *(ConstraintSpec('handling', name, 0.0) for name in TYRE_HOP_NAMES)]


def _fill_gaps(points: list[DesignPoint]) -> None:
    """Gaps of every point; points[0..2]: ride optimum, handling optimum, baseline."""
    base = points[2]
    for p in points:
        p.gap_ride_pct = float(gap_pct(p.f_ride, points[0].f_ride, base.f_ride))
        p.gap_hand_pct = float(gap_pct(p.f_hand, points[1].f_hand, base.f_hand))


def balanced_eps(points: Sequence[DesignPoint]) -> float | None:
    """The eps at which the ride and handling gaps of the front points are equal.

    Linear interpolation of (gap_ride - gap_hand) against eps between the neighbouring
    front points (ordered by eps) where it changes sign; None when it does not.
    """
    front = sorted((p for p in points if p.kind == 'front'), key=lambda p: p.eps)
    for a, b in zip(front, front[1:]):
        da, db = a.gap_ride_pct - a.gap_hand_pct, b.gap_ride_pct - b.gap_hand_pct
        if da == 0.0:
            return None  # a sweep point balances already
        if da * db < 0.0:
            return float(a.eps + (b.eps - a.eps) * da / (da - db))
    return None


# ---------------------------------------------------------------------- full model
def evaluate_points(points: list[DesignPoint], n_vars: int) -> None:
    """Fill each point's full-model values in both scenarios (one batch per scenario)."""
    x = np.array([p.x for p in points], dtype=float)
    ride = evaluation.evaluate('ride', x)
    hand = evaluation.evaluate('handling', x)
    for i, point in enumerate(points):
        point.f_ride, point.f_hand = float(ride.f[i]), float(hand.f[i])
        point.g_ride, point.g_hand = ride.g[i].tolist(), hand.g[i].tolist()
        point.ride_metrics = dict(zip(ride.metric_names, ride.metrics[i].tolist()))
        point.handling_metrics = dict(zip(hand.metric_names, hand.metrics[i].tolist()))
        point.physical = physical_settings(point.x)


def _stack(settings: Sequence[SuspensionSetting]) -> SuspensionSetting:
    return SuspensionSetting(*(np.vstack([getattr(s, name) for s in settings]) for name in (
        'gas_volume_soft_m3', 'gas_volume_stiff_m3', 'dpsf_low', 'dpsf_high')))


def fast_valve_params(params: ValveControllerParams | None = None) -> ValveControllerParams:
    """The valve controller with its switching delay cut to one control period."""
    params = params or ValveControllerParams.from_yaml(config_dir() / 'valve_controller.yaml')
    return replace(params, delay_min_s=params.control_period_s,
                   delay_max_s=params.control_period_s)


def mixed_runs(passive_x: Array, x_ride: Array, x_hand: Array) -> dict[str, Any]:
    """The mixed scenario: passive designs with fixed valves, then the switched 4S4 twice.

    Rows 0..m-1: the passive designs (valves held in the ride state: with equal
    settings in both states no switch could change anything); row m: the switched
    suspension with the configured valve controller (50-100 ms delay); row m + 1: the
    same with a one-period (10 ms) delay.

    Returns
    -------
    dict
        ``f_ride`` and ``f_hand`` (m + 2,) of the paving and lane-change segments,
        ``metrics`` (name -> (m + 2,)), ``valve_switches``, ``stiff_volume_capped``.
    """
    m = len(passive_x)
    switched, capped = switched_setting(x_ride, x_hand)
    setting = _stack([passive_setting(passive_x), switched, switched])
    x = np.vstack([passive_x, x_ride[None, :], x_ride[None, :]])

    def locked(step: int, state: dict[str, Any]) -> tuple[int, int, int, int]:
        return RIDE_STATE

    configured = in_process_controllers(1)[0]
    fast = in_process_controllers(1, fast_valve_params())[0]
    controllers = [locked] * m + [configured.update_from_state, fast.update_from_state]
    config = {**load_mixed_config(), 'rough_length_m': MIXED_ROUGH_LENGTH_M}
    result = run_mixed(x, controllers, config=config, setting=setting)
    met = {k: np.asarray(v, float) for k, v in result.metrics.items()}
    f_ride = np.asarray(metrics.f_ride(met['a_rms_driver_mps2'], met['a_rms_passenger_mps2']))
    f_hand = np.asarray(metrics.f_hand(met['roll_rate_rms_deg_s'], met['roll_first_peak_deg']))
    return {'f_ride': f_ride, 'f_hand': f_hand, 'metrics': met,
            'valve_events': {'configured': [asdict(e) for e in configured.events],
                             'one_period': [asdict(e) for e in fast.events]},
            'stiff_volume_capped': capped[0].tolist(), 'period_s': result.valve_period_s}


# ---------------------------------------------------------------------- the study
def _optimise(objective: str, n_vars: int, start: str, x0: ArrayLike | None,
              gradients: dict[str, SimplifiedGradient], constraints: Sequence[ConstraintSpec],
              calibration_runs: int, record: bool):
    from suspension_tuning.studies.common import run_dynamic_q

    return run_dynamic_q(objective, n_vars, start, 'simplified', gradients[objective],
                         calibration_runs, record=record, x0=x0, constraints=constraints,
                         constraint_gradients=gradients)


def best_iterate(runs: Sequence[Any], gtol: float) -> list[float]:
    """The best feasible full-model iterate of some runs (their histories), as x.

    On the sett paving the eq. 11 tyre-hop constraints are active and piecewise
    constant in x, so a Dynamic-Q run may end on an infeasible iterate after passing
    feasible ones: the design kept is the iterate with the lowest f among those with
    every constraint (eq. 11 and the extra ones) within gtol, over every run given;
    without any, the one with the smallest violation.
    """
    entries = [h for run in runs for h in run.history]
    if not entries:
        raise ValueError('no iterate recorded')
    feasible = [h for h in entries if h['max_violation'] <= gtol]
    if feasible:
        return list(min(feasible, key=lambda h: h['f'])['x'])
    return list(min(entries, key=lambda h: h['max_violation'])['x'])


def run_pareto(out: Path, n_vars: int = 4, n_points: int | None = None, bags: bool = True,
               calibration_samples: int | None = None,
               log: Callable[[str], None] = print) -> dict[str, Any]:
    """Run the study, write ``pareto.json``, ``pareto.png``, ``pareto.md`` and the bags.

    Parameters
    ----------
    out : Path
        Output folder (bags under ``out/bags``).
    n_vars : int
        2 or 4 design variables.
    n_points : int, optional
        Epsilon values of the front (default :data:`FRONT_POINTS`).
    bags : bool
        Record every optimisation run as a bag.
    calibration_samples : int, optional
        Eq. 25 calibration samples per scenario (default config/simplified_models.yaml
        ``scaling.n_samples``).
    log : callable
        Progress lines.

    Returns
    -------
    dict
        The JSON payload (points, front, switched, mixed, figures) plus ``markdown``.
    """
    from suspension_tuning.studies.common import vehicle_options, write_bag
    from suspension_tuning.vehicle.design import baseline_design

    if n_vars not in (2, 4):
        raise ValueError(f'n_vars must be 2 or 4, got {n_vars}')
    n_points = FRONT_POINTS[n_vars] if n_points is None else int(n_points)
    if n_points < 1:
        raise ValueError(f'the front needs at least one point, got {n_points}')
    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    gtol = float(vehicle_options()['gtol'])
    calibration_samples, _ = calibration_settings(calibration_samples)
    gradients = {s: SimplifiedGradient(s, n_vars, calibrate(s, n_vars, calibration_samples))
                 for s in ('ride', 'handling')}
    log(f'calibrated both simplified models ({calibration_samples} samples each)')
    runs: list[tuple[str, Any, Any]] = []

    def optimise(name: str, objective: str, start: str, x0: ArrayLike | None,
                 constraints: Sequence[ConstraintSpec] = ()):
        run, recorder = _optimise(objective, n_vars, start, x0, gradients, constraints,
                                  calibration_samples, bags)
        runs.append((name, run, recorder))
        log(f'  {name}: f = {run.f:.5f}, max violation {run.max_violation:.2g}, '
            f'{run.iterations} iterations, {run.n_full_runs} full runs')
        return run

    ends: dict[str, list[float]] = {}
    for objective, kind in (('ride', 'ride_optimum'), ('handling', 'handling_optimum')):
        tried = [optimise(f'{kind}_from_{start}', objective, start, None)
                 for start in END_POINT_STARTS]
        ends[kind] = best_iterate(tried, gtol)
    x_r = np.asarray(ends['ride_optimum'])
    x_h = np.asarray(ends['handling_optimum'])
    points = [DesignPoint('ride_optimum', 'ride_optimum', x_r.tolist()),
              DesignPoint('handling_optimum', 'handling_optimum', x_h.tolist()),
              DesignPoint('baseline', 'baseline', baseline_design(n_vars).tolist())]
    evaluate_points(points, n_vars)
    eps_values = epsilon_values(points[1].f_hand, points[0].f_hand, n_points)
    previous = x_r
    for k, eps in enumerate(eps_values):
        specs = front_constraints(float(eps))
        tried = [optimise(f'front_{k}_from_previous', 'ride', 'previous', previous, specs),
                 optimise(f'front_{k}_from_handling_optimum', 'ride', 'handling_optimum',
                          x_h, specs)]
        best = best_iterate(tried, gtol)
        previous = np.asarray(best)
        names = [name for name, run, _ in runs[-2:]]
        points.append(DesignPoint(f'front_{k}', 'front', best, eps=float(eps), runs=names))
    points[0].runs = [n for n, _, _ in runs if n.startswith('ride_optimum')]
    points[1].runs = [n for n, _, _ in runs if n.startswith('handling_optimum')]
    evaluate_points(points[3:], n_vars)
    _fill_gaps(points)
    # One more point where the two gaps balance (the min-max compromise), its eps from
    # the two sweep points whose gap difference changes sign (linear interpolation).
    eps_star = balanced_eps(points)
    if eps_star is not None:
        specs = front_constraints(eps_star)
        start = min((p for p in points if p.kind == 'front'),
                    key=lambda p: abs(p.eps - eps_star))
        tried = [optimise('front_balanced_from_nearest', 'ride', 'nearest_front_point',
                          start.x, specs),
                 optimise('front_balanced_from_handling_optimum', 'ride', 'handling_optimum',
                          x_h, specs)]
        chosen = best_iterate(tried, gtol)
        points.append(DesignPoint('front_balanced', 'front', chosen, eps=eps_star,
                                  runs=[name for name, _, _ in runs[-2:]]))
        evaluate_points(points[-1:], n_vars)
        _fill_gaps(points)
    # A passive design must keep its tyres on the road in both scenarios (eq. 11).
    designs = [p for p in points if p.kind != 'baseline']
    passive = [p for p in designs if max(p.g_ride + p.g_hand) <= gtol]
    infeasible = [p.name for p in designs if max(p.g_ride + p.g_hand) > gtol]
    if not passive:
        raise ValueError('no passive design meets the eq. 11 constraints of both scenarios')
    keep = non_dominated([[p.f_ride, p.f_hand] for p in passive])
    baseline_dominated = not non_dominated(
        [[p.f_ride, p.f_hand] for p in [points[2], *passive]])[0]
    front = sorted((p for p, k in zip(passive, keep) if k), key=lambda p: p.f_hand)
    dominated = [p.name for p, k in zip(passive, keep) if not k]
    interior = [p for p in front if p.kind == 'front'] or front
    best = interior[best_compromise([[p.gap_ride_pct, p.gap_hand_pct] for p in interior])]
    log(f'front: {len(front)} non-dominated points ({len(dominated)} dominated, '
        f'{len(infeasible)} violating eq. 11 dropped); '
        f'best compromise {best.name}: gaps {best.gap_ride_pct:.1f} % ride, '
        f'{best.gap_hand_pct:.1f} % handling')

    # The mixed closed-loop scenario: passive designs locked, then the switched 4S4.
    passive_x = np.array([p.x for p in points])
    mixed = mixed_runs(passive_x, x_r, x_h)
    m = len(points)
    mf_r, mf_h = mixed['f_ride'], mixed['f_hand']
    mixed_gap_r = gap_pct(mf_r, mf_r[0], mf_r[2])
    mixed_gap_h = gap_pct(mf_h, mf_h[1], mf_h[2])
    index = {p.name: i for i, p in enumerate(points)}
    best_i = index[best.name]
    switched = {
        'two_state': {'f_ride': points[0].f_ride, 'f_hand': points[1].f_hand,
                      'gap_ride_pct': 0.0, 'gap_hand_pct': 0.0,
                      'x_ride_state': x_r.tolist(), 'x_handling_state': x_h.tolist()},
    }
    for label, row in (('closed_loop', m), ('closed_loop_one_period_delay', m + 1)):
        switched[label] = {
            'f_ride': float(mf_r[row]), 'f_hand': float(mf_h[row]),
            'gap_ride_pct': float(mixed_gap_r[row]), 'gap_hand_pct': float(mixed_gap_h[row]),
            'metrics': {k: float(v[row]) for k, v in mixed['metrics'].items()
                        if np.ndim(v) == 1}}
    mixed_points = [{'name': p.name, 'f_ride': float(mf_r[i]), 'f_hand': float(mf_h[i]),
                     'gap_ride_pct': float(mixed_gap_r[i]),
                     'gap_hand_pct': float(mixed_gap_h[i]),
                     'metrics': {k: float(v[i]) for k, v in mixed['metrics'].items()
                                 if np.ndim(v) == 1}}
                    for i, p in enumerate(points)]
    bag_paths = []
    if bags:
        for name, run, recorder in runs:
            run.bag = str(write_bag(out / 'bags' / name, run, recorder))
            bag_paths.append(run.bag)
    figures = {
        'passive_front_points': len([p for p in front if p.kind == 'front']),
        'compromise_gap_ride_pct': best.gap_ride_pct,
        'compromise_gap_handling_pct': best.gap_hand_pct,
        'mixed_closed_loop_ride_gap_pct': switched['closed_loop']['gap_ride_pct'],
        'mixed_closed_loop_handling_gap_pct': switched['closed_loop']['gap_hand_pct'],
        'mixed_one_period_delay_ride_gap_pct':
            switched['closed_loop_one_period_delay']['gap_ride_pct'],
        'mixed_one_period_delay_handling_gap_pct':
            switched['closed_loop_one_period_delay']['gap_hand_pct'],
        'mixed_best_passive_ride_gap_pct': float(mixed_gap_r[best_i]),
        'mixed_best_passive_handling_gap_pct': float(mixed_gap_h[best_i]),
    }
    wall = time.perf_counter() - t0
    payload = {
        'n_vars': n_vars, 'n_points': n_points, 'calibration_samples': calibration_samples,
        'ride_road': ride_road(),
        'eps': eps_values.tolist(), 'balanced_eps': eps_star,
        'points': [asdict(p) for p in points], 'baseline_dominated': baseline_dominated,
        'front': [p.name for p in front], 'dominated': dominated, 'infeasible': infeasible,
        'best_compromise': best.name,
        'switched': switched, 'mixed': mixed_points,
        'mixed_valve_events': mixed['valve_events'],
        'mixed_stiff_volume_capped': mixed['stiff_volume_capped'],
        'runs': [{**asdict(run), 'name': name} for name, run, _ in runs],
        'figures': figures, 'bags': bag_paths, 'wall_time_s': wall,
    }
    (out / 'pareto.json').write_text(json.dumps(payload, indent=1, default=float))
    plot_path = plot_front(payload, out / 'pareto.png')
    text = markdown(payload, plot_path.name)
    (out / 'pareto.md').write_text(text)
    return {**payload, 'markdown': text, 'plot': str(plot_path)}


def ride_road() -> dict[str, Any]:
    """The road of the 'ride' scenario and the mixed run's paving: config key and spec."""
    from suspension_tuning.vehicle.params import load_scenarios_config
    from suspension_tuning.vehicle.scenarios import ride_road_spec

    cfg = load_scenarios_config()['ride']
    spec = ride_road_spec(cfg)
    return {'name': str(cfg['road']), 'model': type(spec).__name__, 'spec': asdict(spec)}


# ---------------------------------------------------------------------- outputs
def plot_front(payload: dict[str, Any], path: Path) -> Path:
    """f_ride against f_hand: the scenarios (left) and the mixed closed-loop run (right)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    points = {p['name']: p for p in payload['points']}
    front = [points[name] for name in payload['front']]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    ax = axes[0]
    ax.plot([p['f_hand'] for p in front], [p['f_ride'] for p in front], '-o', ms=4,
            label='passive Pareto front (non-dominated)')
    for name in payload['dominated']:
        ax.plot(points[name]['f_hand'], points[name]['f_ride'], 'x', color='grey')
    for name in payload['infeasible']:  # tyre lift-off beyond eq. 11 in a scenario
        ax.plot(points[name]['f_hand'], points[name]['f_ride'], 'x', color='C3')
    best = points[payload['best_compromise']]
    ax.plot(best['f_hand'], best['f_ride'], 'o', mfc='none', ms=12, color='C1',
            label='best passive compromise')
    base = points['baseline']
    ax.plot(base['f_hand'], base['f_ride'], 's', color='k', label='baseline vehicle (passive)')
    two = payload['switched']['two_state']
    ax.plot(two['f_hand'], two['f_ride'], '*', ms=14, color='C3',
            label='switched 4S4, two-state point')
    ax.set_xlabel('f_hand (eq. 10), handling scenario')
    ax.set_ylabel('f_ride (eq. 9), ride scenario')
    ax.set_title(f"scenarios, {payload['n_vars']} variables")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax = axes[1]
    mixed = {p['name']: p for p in payload['mixed']}
    ax.plot([mixed[n]['f_hand'] for n in payload['front']],
            [mixed[n]['f_ride'] for n in payload['front']], '-o', ms=4,
            label='passive front designs, valves fixed')
    ax.plot(mixed['baseline']['f_hand'], mixed['baseline']['f_ride'], 's', color='k',
            label='baseline vehicle (passive)')
    for label, style, text in (('closed_loop', '*', 'switched 4S4, valve controller '
                                '(50-100 ms delay)'),
                               ('closed_loop_one_period_delay', 'P', 'switched 4S4, 10 ms '
                                'delay')):
        s = payload['switched'][label]
        ax.plot(s['f_hand'], s['f_ride'], style, ms=12, label=text)
    ax.set_xlabel('f_hand (eq. 10) over the double lane change')
    ax.set_ylabel('f_ride (eq. 9) over the paving')
    ax.set_title('mixed closed-loop run (paving, then lane change; 65 km/h)')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _removed(gap: float, passive_gap: float) -> str:
    """Share of the passive compromise's larger gap that a design removes, percent."""
    return f'{100.0 * (1.0 - gap / passive_gap):.0f}' if passive_gap > 0 else 'n/a'


def _pct(value: float) -> str:
    """A gap in percent with one decimal; round-off around zero shown as 0.0."""
    return f'{0.0 if abs(value) < 5e-10 else value:.1f}'


def _physical_columns(n_vars: int) -> list[tuple[str, str]]:
    if n_vars == 2:
        return [('dpsf_front', 'dpsf'), ('gas_volume_front_l', 'gas volume (L)')]
    return [('dpsf_front', 'dpsf front'), ('gas_volume_front_l', 'gas front (L)'),
            ('dpsf_rear', 'dpsf rear'), ('gas_volume_rear_l', 'gas rear (L)')]


DOC_HEADER = """# What the 4S4 buys: the passive ride-handling compromise

The paper's reason for the 4S4 unit is one sentence of section 3: a suspension that
switches between a ride setting and a handling setting "has the ability to eliminate
the traditional ride comfort vs. handling compromise".  This page measures that
compromise on our models and how much of it the switched suspension removes.

```sh
.venv/bin/python -m suspension_tuning.study --pareto          # 4 variables, 8 eps values
.venv/bin/python benchmarks/bench_pareto.py                   # quick: 2 variables, 4 eps
```

`study --pareto` writes `out/pareto/pareto.json`, `pareto.png`, `pareto.md` (this page)
and one bag per optimisation run under `out/pareto/bags/` (`inspect_bag <bag>`).

## Definitions

**Passive suspension.**  One setting of the design variables (2 or 4: dpsf and static
gas volume per axle, eqs. 4-8) used in every situation, with no switching.  In the 4S4
model it is the setting whose two spring states hold the same gas volume, `V_soft =
V_stiff = V` (the large accumulator is empty), and whose two damper states have the
same scale factor, `dpsf_low = dpsf_high = d`, on the standard damper table
(`vehicle.passive.passive_setting`).  The gas constant of the empty accumulator is
zero, so connecting or disconnecting it changes neither the gas volume nor the
pressure: every valve state gives the same strut force, and the valves may stay in the
ride state throughout (a test runs the whole mixed scenario in both states and with
the controller switching, and gets the same bits).  The passive design has exactly the
freedom of one 4S4 state: the same ranges (0.1-0.6 L, dpsf 0.1-3) and damper table.
The 'ride' scenario uses only the soft volume and the low-damping dpsf of a setting
and the 'handling' scenario only the stiff volume and the high-damping dpsf, so a
passive design x has f_ride(x) from the 'ride' scenario and f_hand(x) from the
'handling' scenario at the same x (tested: same bits); that is why the scenario
objectives over one shared x give the passive front.

**Baseline vehicle.**  The passive setting of the baseline in
config/design_space.yaml (dpsf 1, 0.3 L: close to a standard Defender 110 coil rate).

**Switched suspension.**  The 4S4 with its ride state (soft spring, low damping) set
by the ride optimum x_r and its handling state (stiff spring, high damping) by the
handling optimum x_h (`vehicle.passive.switched_setting`; a handling gas volume above
the ride one would be capped at it, as the small accumulator alone cannot hold more
gas than both together).  Measured two ways:

- the **two-state point** (f_ride(x_r) in the ride scenario, f_hand(x_h) in the
  handling scenario): the right state always engaged, at no cost;
- the **mixed closed-loop run** (`vehicle.mixed.run_mixed`): Belgian paving, a 10 m
  fade to a smooth road, 30 m of smooth straight, then the ISO 3888-1 double lane
  change, all at 65 km/h, while the valve controller (config/valve_controller.yaml)
  decides the state every 10 ms from lateral acceleration, roll rate and steering rate,
  and each commanded change lands 50-100 ms later (longer at lower strut pressure,
  paper section 3).  The study's paving is 271 m long (3 s of W_b settling plus 12 s of
  averaging, as the ride scenario averages 12 s), not the 80 m of config/mixed.yaml.
  It runs once more with the delay cut to one control period (10 ms): the difference
  is what the delay costs.

**Segments of the mixed run.**  Ride metric (eq. 9 on the BS 6841 W_b-weighted RMS
vertical accelerations at the driver and rear passenger seats): from 3 s after the
start (the W_b filter runs from t = 0 and its transient is discarded) until the
sprung-mass centre of gravity leaves the paving.  Handling metric (eq. 10): the first
roll peak between the entry of section 2 and the exit of section 3 of the track (the
first lane change), and the RMS roll rate from lane 1 entry (x = 0) to the exit of
section 6, each window from the times the centre of gravity crosses those x, as in the
'handling' scenario.  The references of the gaps in this run are the same run with
passive designs and fixed valves: the ride optimum (ride), the handling optimum
(handling) and the baseline vehicle.  Note the paving is driven at 65 km/h here, at
50 km/h in the 'ride' scenario: the two sets of f_ride are not comparable in
absolute terms, only their gaps are.

**Front.**  End points: the single-objective optima with Dynamic-Q (config/
optimiser.yaml `vehicle` options) and eq. 25-scaled simplified-model gradients (30
samples each), best of the centre and baseline starts, each subject to its own
scenario's eq. 11 tyre-hop constraints.  Interior points: minimise f_ride subject to
f_hand <= eps (extra constraint from the handling scenario, gradient from its scaled
simplified model), the handling run's eq. 11 constraints and the ride run's own, for
eps evenly spaced inside (f_hand(x_h), f_hand(x_r)), each from two starts (the
previous front point and x_h); of each point's two runs (and of the end points' two)
the best feasible iterate is kept, as on the sett paving a run may end on an
infeasible iterate after feasible ones (the tyre-hop constraints are active there);
then one more point at the eps where the ride and handling gaps balance
(interpolated between the sweep points).
Every value in the tables is the full model's.  Designs whose tyres leave the road
for longer than eq. 11 allows in either scenario (g > gtol = 1e-3) are not passive
candidates, and points another point beats in both objectives are dropped.

**Gaps.**  gap(f) = 100 (f - f_opt) / (f_baseline - f_opt): the share of the
improvement from the baseline vehicle to the single-objective optimum that a design
loses (0 %: as good as the optimum; 100 %: no better than the baseline).  The best
passive compromise is the front point whose larger gap is the smallest.

"""


def markdown(payload: dict[str, Any], plot_name: str) -> str:
    """The study's page: definitions, tables in physical units, the figures in words."""
    n = payload['n_vars']
    points = {p['name']: p for p in payload['points']}
    cols = _physical_columns(n)
    head = ['design', *[c[1] for c in cols], 'a_w driver (m/s^2)', 'a_w passenger (m/s^2)',
            'roll rate RMS (deg/s)', 'first roll peak (deg)', 'f_ride', 'f_hand',
            'ride gap (%)', 'handling gap (%)', 'max g ride', 'max g handling']
    rows = []
    order = ['baseline', 'ride_optimum', *[p for p in payload['front']
                                          if points[p]['kind'] == 'front'],
             'handling_optimum']
    for name in order:
        p = points[name]
        label = name + (f" (f_hand <= {p['eps']:.4f})" if p['kind'] == 'front' else '')
        if name == payload['best_compromise']:
            label += ' **best compromise**'
        rm, hm = p['ride_metrics'], p['handling_metrics']
        rows.append([label, *[f"{p['physical'][c[0]]:.3f}" for c in cols],
                     f"{rm['a_rms_driver_mps2']:.3f}", f"{rm['a_rms_passenger_mps2']:.3f}",
                     f"{hm['roll_rate_rms_deg_s']:.2f}", f"{hm['roll_first_peak_deg']:.2f}",
                     f"{p['f_ride']:.4f}", f"{p['f_hand']:.4f}", _pct(p['gap_ride_pct']),
                     _pct(p['gap_hand_pct']), f"{max(p['g_ride']):.3f}",
                     f"{max(p['g_hand']):.3f}"])
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    lines += ['| ' + ' | '.join(r) + ' |' for r in rows]
    fig = payload['figures']
    sw = payload['switched']
    cl, fast = sw['closed_loop'], sw['closed_loop_one_period_delay']
    mixed = {p['name']: p for p in payload['mixed']}
    mrows = ['| design | a_w driver (m/s^2) | a_w passenger (m/s^2) | roll rate RMS (deg/s) | '
             'first roll peak (deg) | f_ride (paving) | f_hand (lane change) | ride gap (%) | '
             'handling gap (%) | valve-state changes |', '|' + '---|' * 10]
    for label, m in [*((name, mixed[name]) for name in ('baseline', 'ride_optimum',
                                                       payload['best_compromise'],
                                                       'handling_optimum')),
                     ('switched, valve controller (50-100 ms)', cl),
                     ('switched, 10 ms delay', fast)]:
        mm = m['metrics']
        mrows.append(f"| {label} | {mm['a_rms_driver_mps2']:.3f} | "
                     f"{mm['a_rms_passenger_mps2']:.3f} | {mm['roll_rate_rms_deg_s']:.2f} | "
                     f"{mm['roll_first_peak_deg']:.2f} | {m['f_ride']:.4f} | "
                     f"{m['f_hand']:.4f} | {_pct(m['gap_ride_pct'])} | "
                     f"{_pct(m['gap_hand_pct'])} | "
                     f"{mm['valve_switches']:.0f} |")
    worst_passive = max(fig['compromise_gap_ride_pct'], fig['compromise_gap_handling_pct'])
    worst_passive_mixed = max(fig['mixed_best_passive_ride_gap_pct'],
                              fig['mixed_best_passive_handling_gap_pct'])
    worst_cl = max(fig['mixed_closed_loop_ride_gap_pct'],
                   fig['mixed_closed_loop_handling_gap_pct'])
    delay_cost = (fig['mixed_closed_loop_handling_gap_pct']
                  - fig['mixed_one_period_delay_handling_gap_pct'])
    summary = [
        f"- Passive front: {fig['passive_front_points']} non-dominated interior points "
        f"(of {payload['n_points']} eps values) plus the two end points"
        + (f"; dominated and dropped: {', '.join(payload['dominated'])}"
           if payload['dominated'] else '')
        + (f"; dropped for tyre lift-off beyond eq. 11 in either scenario: "
           f"{', '.join(payload['infeasible'])}" if payload['infeasible'] else '') + '.',
        '- The baseline vehicle is ' + ('dominated by the front (a passive design beats '
                                        'it in both objectives).' if payload[
                                            'baseline_dominated'] else
                                        'not dominated: it lies on the passive front '
                                        'itself, within the resolution of the sweep.'),
        f"- The best passive compromise ({payload['best_compromise']}) loses "
        f"{fig['compromise_gap_ride_pct']:.1f} % of the achievable ride improvement and "
        f"{fig['compromise_gap_handling_pct']:.1f} % of the achievable handling "
        f"improvement (baseline vehicle to single-objective optimum).",
        '- The switched 4S4 at its two-state point loses nothing by construction (0 % and '
        '0 %): it removes the whole compromise if the right state is always engaged.',
        f"- In the mixed closed-loop run it loses {_pct(fig['mixed_closed_loop_ride_gap_pct'])}"
        f" % (ride, paving) and {_pct(fig['mixed_closed_loop_handling_gap_pct'])} % "
        f"(handling, lane change); the best passive compromise, valves fixed, loses "
        f"{fig['mixed_best_passive_ride_gap_pct']:.1f} % and "
        f"{fig['mixed_best_passive_handling_gap_pct']:.1f} % in the same run.  The larger "
        f"of the two gaps falls from {worst_passive_mixed:.1f} % (best passive compromise) "
        f"to {worst_cl:.1f} % (switched, closed loop) in that run, and from "
        f"{worst_passive:.1f} % in the scenarios: the switched suspension with its "
        f"controller removes {_removed(worst_cl, worst_passive_mixed)} % of the "
        'compromise (100 % = no gap left in either objective).',
        f"- The switching delay: with the valves landing one control period (10 ms) after "
        f"the command instead of 50-100 ms, the closed-loop gaps are "
        f"{_pct(fig['mixed_one_period_delay_ride_gap_pct'])} % (ride) and "
        f"{fig['mixed_one_period_delay_handling_gap_pct']:.1f} % (handling): the delay "
        f"costs {delay_cost:.1f} percentage points of the handling gap.",
    ]
    return DOC_HEADER + '\n'.join([
        f"## Results ({n} variables, generated by `study --pareto` in "
        f"{payload['wall_time_s']:.0f} s)", '',
        f"Ride road: `{payload['ride_road']['name']}` of config/road.yaml "
        f"({payload['ride_road']['model']}, seed {payload['ride_road']['spec'].get('seed')})."
        '', '', f'![Pareto front]({plot_name})', '',
        *summary, '', '### Passive designs (ride and handling scenarios, full model)', '',
        *lines, '', '### Mixed closed-loop run (paving then double lane change, 65 km/h)', '',
        *mrows, '']) + '\n'


def main(args: Any) -> int:
    """``study --pareto``: run, print the figures and where the outputs are."""
    result = run_pareto(Path(args.out), args.pareto_n_vars, args.points,
                        bags=not args.no_bags, calibration_samples=args.pareto_samples,
                        log=lambda s: print(s, flush=True))
    print()
    print(result['markdown'])
    for name, value in result['figures'].items():
        print(f'{name}: {value:.2f}' if isinstance(value, float) else f'{name}: {value}')
    out = Path(args.out)
    print(f"results: {out / 'pareto.json'}\nplot: {result['plot']}\ntable: {out / 'pareto.md'}")
    if not args.no_bags:
        print(f"bags: {out / 'bags'} ({len(result['bags'])} runs; inspect: inspect_bag <bag>)")
    print(f"study_wall_time_s: {result['wall_time_s']:.1f}")
    return 0
