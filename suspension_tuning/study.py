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

Run: ``.venv/bin/python -m suspension_tuning.study [--search-references [--quick]]
[--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize

from suspension_tuning.optim.dynamic_q import load_options
from suspension_tuning.optim.simplified_gradient import SimplifiedGradient, calibrate
from suspension_tuning.paths import config_dir, dump_yaml
from suspension_tuning.reported_design import (
    ReportedDesign,
    design_success,
    reported_design,
    result_message,
)
from suspension_tuning.tuning import (
    FullEvaluation,
    RunCounter,
    TuningRequest,
    centre,
    optimise,
    physical_settings,
)
from suspension_tuning.vehicle.design import X_LOWER, X_UPPER, validate_design
from suspension_tuning.vehicle.params import INTEGRATORS
from suspension_tuning.vehicle.scenarios import run_scenario

Array = NDArray[np.float64]

SCENARIOS = ('ride', 'handling')
N_VARS = (2, 4)
STARTS = ('centre', 'baseline')
METHODS = ('dq_simplified', 'dq_full', 'slsqp', 'slsqp_best_fd', 'reference')
METHOD_LABELS = {
    'dq_simplified': 'Dynamic-Q, simplified-model gradients',
    'dq_full': 'Dynamic-Q, full-model central differences',
    'slsqp': 'SLSQP, full-model 2-point differences',
    'slsqp_best_fd': 'SLSQP, 2-point differences with the noise-optimal step',
    'reference': 'reference optimum',
}
#: Grid points per axis of the reference search (2 and 4 variables) [E: 41 gives a
#: 0.025 spacing, the central-difference half step; 7^4 = 2401 full runs for n = 4].
GRID_POINTS = {2: 41, 4: 7}
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
#: Designs per full-model batch of the reference grid [E: ~2 s per ride batch].
GRID_BATCH = 64
#: SLSQP's finite-difference step, normalised units: SciPy's default sqrt(machine eps).
SLSQP_EPS = float(np.sqrt(np.finfo(float).eps))
#: Distinct best grid points polished by SLSQP for the reference [E].
POLISH_STARTS = 3
#: Central-difference half step of Dynamic-Q's full-model gradients, normalised
#: (config/optimiser.yaml finite_difference.h; the simplified gradients use the same).
FD_STEP = 0.025


# ---------------------------------------------------------------------- results
@dataclass
class StudyRun:
    """One optimisation run of the study (or the reference search) and its costs.

    Attributes
    ----------
    scenario, n_vars, start, method : str, int, str, str
        Case and method (see :data:`METHODS`).
    calibration_samples : int
        Eq. 25 calibration samples (0 for methods without simplified models).
    x, f, g : list, float, list
        Reported design (normalised), objective and constraints (full model):
        Dynamic-Q's best feasible iterate, or its least violating one when none was
        feasible (``details['best_iteration']``, ``details['best_feasible']``; the last
        iterate is ``details['x_last']``, ``f_last``, ``max_violation_last``); SLSQP's
        final point; the reference's best feasible point.
    max_violation : float
        max(0, max g) at x.
    iterations : int
        Optimiser iterations.
    n_full_runs, n_simplified_runs, n_calibration_runs : int
        Full-model runs of the optimisation, simplified-model runs, calibration runs.
    wall_time_s, calibration_wall_time_s : float
        Wall time of the optimisation and of its calibration (shared by the runs that
        use the same calibration).
    success : bool
        The method's own success; for Dynamic-Q also that x is feasible.
    message : str
        The method's stop message.
    history : list of dict
        Per iteration: iteration, f, max_violation, n_full_runs, n_simplified_runs, x.
    distance_to_reference : float
        Euclidean distance of x to the reference optimum, normalised units.
    gap_to_reference_pct : float
        100 (f - f_ref) / |f_ref|.
    f_fixed_step, gap_to_fixed_reference_pct, max_violation_fixed_step : float
        Runs on the variable-step (noisy) model: f of the final design on the
        fixed-step model (the noise-free solution of the same equations), its gap
        to the fixed-step reference optimum, % (negative only for a design that is
        infeasible there), and its largest constraint violation there.
    bag : str
        Bag folder ('' when not recorded).
    details : dict
        Method-specific facts (reference: grid size, grid best, polish results).
    evaluations : list of dict
        SLSQP: every design it evaluated, in order (finite-difference points included),
        as history entries whose ``n_full_runs`` counts the runs up to it; empty for
        the other methods (their history holds every iterate).
    """

    scenario: str
    n_vars: int
    start: str
    method: str
    calibration_samples: int
    x: list[float]
    f: float
    g: list[float]
    max_violation: float
    iterations: int
    n_full_runs: int
    n_simplified_runs: int
    n_calibration_runs: int
    wall_time_s: float
    calibration_wall_time_s: float = 0.0
    success: bool = True
    message: str = ''
    history: list[dict[str, Any]] = field(default_factory=list)
    distance_to_reference: float = math.nan
    gap_to_reference_pct: float = math.nan
    bag: str = ''
    details: dict[str, Any] = field(default_factory=dict)
    f_fixed_step: float = math.nan
    gap_to_fixed_reference_pct: float = math.nan
    max_violation_fixed_step: float = math.nan
    evaluations: list[dict[str, Any]] = field(default_factory=list)

    @property
    def full_runs_with_calibration(self) -> int:
        """Full-model runs including the eq. 25 calibration."""
        return self.n_full_runs + self.n_calibration_runs

    @property
    def name(self) -> str:
        """``<scenario>_<n>var_<start>_<method>[_cal<N>]`` or ``..._reference`` (bag names)."""
        if self.method == 'reference':
            return f'{self.scenario}_{self.n_vars}var_reference'
        tail = f'_cal{self.calibration_samples}' if self.method == 'dq_simplified' else ''
        return f'{self.scenario}_{self.n_vars}var_{self.start}_{self.method}{tail}'


#: Names of the eq. 11 constraints in the order of g (tyres FL, FR, RL, RR).
CONSTRAINT_NAMES = ('FL', 'FR', 'RL', 'RR')
#: A tyre-hop constraint counts as active at a final point when g >= -ACTIVE_G_TOL [E]:
#: eq. 11 is 10 x (fraction of samples off the ground - 0.1), a step function of x, so an
#: optimiser stops near, not on, g = 0; 0.05 is 0.5 % of the run time from the 10 % limit.
ACTIVE_G_TOL = 0.05


def active_constraints(g: ArrayLike, tol: float = ACTIVE_G_TOL) -> list[str]:
    """Names of the eq. 11 constraints with g >= -tol (active or violated)."""
    g = np.asarray(g, dtype=float)
    return [name for name, v in zip(CONSTRAINT_NAMES, g) if v >= -tol]


def max_violation(g: ArrayLike) -> float:
    """Largest constraint violation max(0, max g) (eq. 11 constraints, <= 0 feasible)."""
    g = np.asarray(g, dtype=float)
    return float(max(0.0, np.max(g))) if g.size else 0.0


class FullModelCache:
    """Full-model runs of one scenario, cached per design and counted once each.

    SLSQP asks for the objective and the constraints at one x separately and for their
    finite differences at the same points: one full run gives both (cost counted once).

    Parameters
    ----------
    scenario : str
        'ride' or 'handling'.
    n_vars : int
        2 or 4.
    """

    def __init__(self, scenario: str, n_vars: int, integrator: str | None = None) -> None:
        self.scenario = scenario
        self.n_vars = n_vars
        self.integrator = integrator
        self.values: dict[bytes, tuple[float, Array]] = {}

    @property
    def n_runs(self) -> int:
        """Distinct designs run so far."""
        return len(self.values)

    def __call__(self, x: ArrayLike) -> tuple[float, Array]:
        """Objective and constraints at one design (one full run if not cached)."""
        xv = validate_design(np.asarray(x, dtype=float), self.n_vars)[0]
        key = xv.tobytes()
        if key not in self.values:
            result = run_scenario(
                self.scenario, xv[None, :], n_vars=self.n_vars, integrator=self.integrator
            )
            self.values[key] = (float(result.f[0]), np.asarray(result.g[0], float).copy())
        return self.values[key]


def full_model(
    scenario: str, n_vars: int, integrator: str | None = None
) -> Callable[[Array], FullEvaluation]:
    """The full model as :func:`suspension_tuning.tuning.optimise` wants it (in-process).

    With the named metrics (``evaluation.metric_table``), which extra constraints may
    bound; 'mixed' runs the closed-loop scenario with in-process valve controllers.
    ``integrator``: 'fixed_step' or 'variable_step' (default config/vehicle.yaml).
    """
    from suspension_tuning.evaluation import in_process_model

    run = in_process_model(scenario, integrator)

    def evaluate(designs: Array) -> FullEvaluation:
        return run(validate_design(designs, n_vars))

    return evaluate


def start_point(name: str, n_vars: int) -> Array:
    """Start design: 'centre' of the design space or the 'baseline' vehicle."""
    if name == 'centre':
        return centre(n_vars)
    if name == 'baseline':
        from suspension_tuning.demo import baseline_design

        return baseline_design(n_vars)
    raise ValueError(f'unknown start point {name!r}; valid: {", ".join(STARTS)}')


def vehicle_options() -> dict[str, Any]:
    """Dynamic-Q options of config/optimiser.yaml, section ``vehicle``."""
    return load_options(str(config_dir() / 'optimiser.yaml'), 'vehicle').as_dict()


# ---------------------------------------------------------------------- bag messages
class _Recorder:
    """Collects a run's IterationRecord messages (with receive times) for its bag."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.messages: list[tuple[int, Any]] = []
        self.t0 = time.monotonic()
        if enabled:
            from suspension_tuning.nodes.coordinator import record_to_msg

            self._to_msg = record_to_msg

    def add(self, record: dict[str, Any], counter: RunCounter) -> None:
        if self.enabled:
            self.messages.append((time.time_ns(), self._to_msg(record, counter, self.t0)))


def _history_entry(record: dict[str, Any], counter: RunCounter) -> dict[str, Any]:
    return {
        'iteration': int(record['iteration']),
        'f': float(record['f']),
        'max_violation': float(record['max_violation']),
        'n_full_runs': counter.full_runs,
        'n_simplified_runs': counter.simplified_runs,
        'x': np.asarray(record['x'], float).tolist(),
    }


# ---------------------------------------------------------------------- runs
def run_dynamic_q(
    scenario: str,
    n_vars: int,
    start: str,
    gradient_source: str,
    gradient: SimplifiedGradient | None = None,
    calibration_samples: int = 0,
    calibration_wall_time_s: float = 0.0,
    options: dict[str, Any] | None = None,
    record: bool = True,
    x0: ArrayLike | None = None,
    constraints: Sequence[Any] = (),
    constraint_gradients: dict[str, SimplifiedGradient] | None = None,
    integrator: str | None = None,
) -> tuple[StudyRun, _Recorder]:
    """Dynamic-Q through :func:`suspension_tuning.tuning.optimise` (the coordinator's loop).

    Parameters
    ----------
    scenario, n_vars, start : str, int, str
        Case; ``start`` is 'centre' or 'baseline'.
    gradient_source : str
        'simplified' (needs ``gradient``) or 'full' (central differences, half step
        :data:`FD_STEP`, 2n full runs per gradient).
    gradient : SimplifiedGradient, optional
        Eq. 25-scaled simplified-model gradient.
    calibration_samples : int
        Full runs spent on the calibration of ``gradient`` (counted in the result).
    calibration_wall_time_s : float
        Wall time of that calibration.
    options : dict, optional
        Dynamic-Q options (default config/optimiser.yaml ``vehicle``).
    record : bool
        Collect the IterationRecord messages for a bag.
    x0 : array_like, optional
        Start design in place of the named ``start`` (which then only labels the run).
    constraints : sequence, optional
        Extra constraints (``tuning.ConstraintSpec``); their scenarios' full models run
        in-process.
    constraint_gradients : dict, optional
        Simplified gradients of the constraints' other scenarios (simplified source).
    integrator : str, optional
        Full-model integrator ('fixed_step' or 'variable_step'; default config).
    """
    options = vehicle_options() if options is None else options
    start_x = start_point(start, n_vars) if x0 is None else validate_design(x0, n_vars)[0]
    request = TuningRequest(
        scenario, n_vars, start_x, gradient_source, options, FD_STEP, constraints,
        integrator=integrator or '',
    )
    counter = RunCounter(calibration_runs=calibration_samples)
    recorder = _Recorder(record)
    history: list[dict[str, Any]] = []

    def on_iteration(rec: dict[str, Any], counts: RunCounter) -> bool:
        history.append(_history_entry(rec, counts))
        recorder.add(rec, counts)
        return False

    t0 = time.perf_counter()
    models = {name: full_model(name, n_vars, integrator)
              for name in request.constraint_scenarios}
    result = optimise(
        request, full_model(scenario, n_vars, integrator), gradient, on_iteration,
        counter=counter, constraint_models=models, constraint_gradients=constraint_gradients,
    )
    wall = time.perf_counter() - t0
    method = 'dq_simplified' if gradient_source == 'simplified' else 'dq_full'
    design = reported_design(result)
    if design is None:
        raise ValueError(f'{scenario}, {n_vars} variables from {start}: Dynamic-Q evaluated '
                         f'no design ({result.message})')
    run = StudyRun(
        scenario=scenario,
        n_vars=n_vars,
        start=start,
        method=method,
        calibration_samples=calibration_samples,
        x=design.x,
        f=design.f,
        g=design.g,
        max_violation=max_violation(design.g),
        iterations=int(result.nit),
        n_full_runs=counter.full_runs,
        n_simplified_runs=counter.simplified_runs,
        n_calibration_runs=counter.calibration_runs,
        wall_time_s=wall,
        calibration_wall_time_s=calibration_wall_time_s,
        success=design_success(result, design),
        message=str(result.message),
        history=history,
        details={'optimiser_options': options, 'fd_step': FD_STEP,
                 'integrator': integrator_name(integrator),
                 'best_iteration': design.iteration, 'best_feasible': design.feasible,
                 'x_last': np.asarray(result.x, float).tolist(), 'f_last': float(result.f),
                 'max_violation_last': max_violation(result.g)},  # fmt: skip
    )
    if request.constraints:
        run.details.update(
            x0=request.start.tolist(),
            constraints=result.constraints,
            constraint_labels=[c.label for c in request.constraints],
            constraint_values=design.constraint_values,
            constraint_values_last=result.constraint_values,
            constraint_gradient_sources=result.constraint_gradient_sources,
        )
    return run, recorder


def _slsqp(
    model: FullModelCache,
    x0: Array,
    on_iteration: Callable[[Array, int], None] | None = None,
    maxiter: int = 100,
    eps: float = SLSQP_EPS,
) -> Any:
    """SciPy SLSQP on the cached full model: bounds 0.001..1, constraints -g >= 0."""
    n = model.n_vars

    def callback(intermediate_result: Any) -> None:
        if on_iteration is not None:
            on_iteration(np.asarray(intermediate_result.x, float), 0)

    return minimize(
        lambda x: model(x)[0],
        x0,
        method='SLSQP',
        bounds=[(X_LOWER, X_UPPER)] * n,
        constraints=[{'type': 'ineq', 'fun': lambda x: -model(x)[1]}],
        callback=callback,
        options={'maxiter': maxiter, 'eps': eps},
    )


def _recording(model: FullModelCache, history: list[dict[str, Any]], recorder: _Recorder):
    """Return ``add(x)``: record the point x of a run without a move limit (SLSQP, grid).

    The values come from the model's cache (the point was evaluated already), the run
    count from the model; the record goes into ``history`` and the run's bag.
    """

    def add(x: Array) -> None:
        f, g = model(x)
        rec = {
            'iteration': len(history),
            'x': x,
            'f': f,
            'g': g,
            'rho': 0.0,
            'rho_next': 0.0,
            'max_violation': max_violation(g),
        }
        counter = RunCounter(full_runs=model.n_runs)
        history.append(_history_entry(rec, counter))
        recorder.add(rec, counter)

    return add


def integrator_name(integrator: str | None) -> str:
    """The integrator a run uses: the given one or config/vehicle.yaml's default."""
    if integrator is not None:
        return integrator
    from suspension_tuning.vehicle.params import load_vehicle_params

    return load_vehicle_params().integrator.method


def run_slsqp(
    scenario: str,
    n_vars: int,
    start: str,
    record: bool = True,
    maxiter: int = 100,
    eps: float = SLSQP_EPS,
    integrator: str | None = None,
    method: str = 'slsqp',
    x0: ArrayLike | None = None,
) -> tuple[StudyRun, _Recorder]:
    """SciPy SLSQP with its finite differences on the full model.

    ``jac=None``: SciPy's 2-point forward differences with the absolute step ``eps``
    (default SciPy's sqrt(machine eps) = 1.49e-8, normalised units), n full runs per
    gradient; the objective and the constraints at one x share one full run
    (:class:`FullModelCache`).  ``method`` names the row ('slsqp' or
    'slsqp_best_fd'); ``x0`` replaces the named ``start`` (which then only labels the
    run).  Every evaluated design is kept in order in ``evaluations``.
    """
    model = FullModelCache(scenario, n_vars, integrator)
    recorder = _Recorder(record)
    history: list[dict[str, Any]] = []
    x0 = start_point(start, n_vars) if x0 is None else validate_design(x0, n_vars)[0]

    add = _recording(model, history, recorder)

    t0 = time.perf_counter()
    add(x0)  # iteration 0: the start point (SLSQP's own first evaluation hits the cache)
    result = _slsqp(model, x0, lambda x, _: add(x), maxiter, eps)
    wall = time.perf_counter() - t0
    f, g = model(result.x)
    run = StudyRun(
        scenario=scenario,
        n_vars=n_vars,
        start=start,
        method=method,
        calibration_samples=0,
        x=np.asarray(result.x, float).tolist(),
        f=f,
        g=g.tolist(),
        max_violation=max_violation(g),
        iterations=int(result.nit),
        n_full_runs=model.n_runs,
        n_simplified_runs=0,
        n_calibration_runs=0,
        wall_time_s=wall,
        success=bool(result.success),
        message=str(result.message),
        history=history,
        details={
            'jac': '2-point forward differences (scipy default, jac=None)',
            'eps': float(eps),
            'maxiter': maxiter,
            'ftol': 1e-6,
            'integrator': integrator_name(integrator),
        },
        evaluations=[
            {'n_full_runs': k + 1, 'f': fk, 'max_violation': max_violation(gk),
             'x': np.frombuffer(key).tolist()}
            for k, (key, (fk, gk)) in enumerate(model.values.items())],
    )
    return run, recorder


def grid_designs(n_vars: int, points: int) -> Array:
    """Full-factorial grid over the normalised box, ``points`` per axis (bounds included)."""
    if points < 2:
        raise ValueError(f'grid points per axis must be >= 2, got {points}')
    axis = np.linspace(X_LOWER, X_UPPER, points)
    mesh = np.meshgrid(*[axis] * n_vars, indexing='ij')
    return np.column_stack([m.ravel() for m in mesh])


def reference_optimum(
    scenario: str,
    n_vars: int,
    points: int,
    extra_starts: Sequence[ArrayLike] = (),
    gtol: float = 1e-3,
    record: bool = True,
    integrator: str | None = None,
    polish_eps: float = SLSQP_EPS,
) -> tuple[StudyRun, _Recorder]:
    """Reference optimum: full-factorial grid, then SLSQP polish; the best feasible point seen.

    Parameters
    ----------
    scenario, n_vars : str, int
        Case.
    points : int
        Grid points per axis (``points ** n_vars`` full runs, in batches of
        :data:`GRID_BATCH`).
    extra_starts : sequence of array_like
        Further polish starts (the methods' final designs).
    gtol : float
        Feasible when max g <= gtol (config/optimiser.yaml vehicle gtol).
    record : bool
        Collect IterationRecord messages (grid best, then each improvement) for a bag.
    integrator : str, optional
        Full-model integrator (default config).
    polish_eps : float
        SLSQP's finite-difference step of the polish (a noisy model needs the
        noise-optimal step of :func:`noise_optimal_fd_step`).

    Returns
    -------
    (StudyRun, recorder)
        ``details`` holds the grid size and spacing, the grid's best f and x, the best f
        polished from the grid alone and from each extra start.
    """
    t0 = time.perf_counter()
    grid = grid_designs(n_vars, points)
    f_grid, g_grid = [], []
    for k in range(0, len(grid), GRID_BATCH):
        res = run_scenario(
            scenario, grid[k : k + GRID_BATCH], n_vars=n_vars, integrator=integrator
        )
        f_grid.append(np.asarray(res.f, float))
        g_grid.append(np.asarray(res.g, float))
    f_grid, g_grid = np.concatenate(f_grid), np.vstack(g_grid)
    feasible = np.max(g_grid, axis=1) <= gtol
    if not feasible.any():
        raise ValueError(f'{scenario}, {n_vars} variables: no feasible grid point')
    order = np.argsort(np.where(feasible, f_grid, np.inf))
    model = FullModelCache(scenario, n_vars, integrator)
    for x, f, g in zip(grid, f_grid, g_grid):  # the grid's runs, counted once
        model.values[validate_design(x, n_vars)[0].tobytes()] = (float(f), g.copy())
    best_x, best_f = grid[order[0]].copy(), float(f_grid[order[0]])
    recorder = _Recorder(record)
    history: list[dict[str, Any]] = []

    add = _recording(model, history, recorder)

    add(best_x)
    starts = [('grid', grid[i]) for i in order[:POLISH_STARTS] if feasible[i]]
    starts += [('method', np.asarray(x, float)) for x in extra_starts]
    polished: dict[str, list[float]] = {'grid': [], 'method': []}
    for origin, x0 in starts:
        # the start itself is a candidate: with active tyre-hop constraints SLSQP can
        # leave a feasible start and end infeasible, and then the start is the better one
        f0, g0 = model(x0)
        if max_violation(g0) <= gtol and f0 < best_f:
            best_x, best_f = np.asarray(x0, float).copy(), f0
            add(best_x)
        res = _slsqp(model, np.asarray(x0, float), eps=polish_eps)
        f, g = model(res.x)
        ok = max_violation(g) <= gtol
        polished[origin].append(f if ok else math.inf)
        if ok and f < best_f:
            best_x, best_f = np.asarray(res.x, float).copy(), f
            add(best_x)
    wall = time.perf_counter() - t0
    f, g = model(best_x)
    spacing = (X_UPPER - X_LOWER) / (points - 1)
    run = StudyRun(
        scenario=scenario,
        n_vars=n_vars,
        start='-',
        method='reference',
        calibration_samples=0,
        x=best_x.tolist(),
        f=f,
        g=g.tolist(),
        max_violation=max_violation(g),
        iterations=len(history) - 1,
        n_full_runs=model.n_runs,
        n_simplified_runs=0,
        n_calibration_runs=0,
        wall_time_s=wall,
        success=True,
        message=f'grid {points}^{n_vars} + SLSQP polish from {len(starts)} starts',
        history=history,
        details={
            'grid_points_per_axis': points,
            'grid_runs': len(grid),
            'grid_spacing': spacing,
            'grid_best_f': float(f_grid[order[0]]),
            'grid_best_x': grid[order[0]].tolist(),
            'polished_from_grid_best_f': min(polished['grid'], default=math.inf),
            'polished_from_methods_best_f': min(polished['method'], default=math.inf),
            'gtol': gtol,
            'polish_eps': float(polish_eps),
            'integrator': integrator_name(integrator),
        },
    )
    return run, recorder


# ---------------------------------------------------------------------- bags
def run_config(run: StudyRun) -> dict[str, Any]:
    """The run's configuration as the coordinator publishes it (plus the method)."""
    return {
        'scenario': run.scenario,
        'n_vars': run.n_vars,
        'x0': (start_point(run.start, run.n_vars).tolist() if run.start in STARTS else []),
        'start': run.start,
        'method': run.method,
        'method_label': METHOD_LABELS[run.method],
        'integrator': run.details.get('integrator', integrator_name(None)),
        'gradient_source': {'dq_simplified': 'simplified', 'dq_full': 'full'}.get(
            run.method, 'full'
        ),
        'calibration_samples': run.calibration_samples,
        **run.details,
        'started_unix_s': time.time(),
    }


def write_bag(path: Path, run: StudyRun, recorder: _Recorder) -> Path:
    """Record one run as a rosbag2-style bag, as the graph's recorder would.

    Topics ``/optimisation/run_config`` (std_msgs/String, YAML), ``/optimisation/progress``
    (IterationRecord per iteration) and ``/optimisation/result`` (Optimise_Result); the
    run_config YAML is also the bag's ``run_config`` metadata record.
    """
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.bag.recorder import run_config_metadata
    from suspension_tuning.bag.writer import BagWriter, qos_profile_dict
    from suspension_tuning.nodes.coordinator import configuration_yaml

    text = dump_yaml(run_config(run)) + configuration_yaml()
    latched = qos_profile_dict(durability='transient_local', depth=1)
    reliable = qos_profile_dict(depth=100)
    physical = physical_settings(run.x)
    if 'best_iteration' in run.details:  # Dynamic-Q: its best iterate, and whether feasible
        best_iteration, feasible = run.details['best_iteration'], run.details['best_feasible']
        message = result_message(ReportedDesign(run.x, run.f, run.g, best_iteration, feasible,
                                                run.max_violation), run.message)
    else:  # SLSQP, the reference: the final point, as recorded
        gtol = float(run.details.get('gtol', vehicle_options()['gtol']))
        best_iteration = next((h['iteration'] for h in reversed(run.history)
                               if h['x'] == run.x), max(len(run.history) - 1, 0))
        feasible, message = run.max_violation <= gtol, run.message
    result = Optimise.Result(
        success=run.success,
        message=message,
        x=list(run.x),
        f=run.f,
        g=list(run.g),
        feasible=bool(feasible),
        best_iteration=int(best_iteration),
        max_violation=float(run.max_violation),
        physical_names=list(physical),
        physical_values=list(physical.values()),
        iterations=run.iterations,
        n_full_runs=run.n_full_runs,
        n_simplified_runs=run.n_simplified_runs,
        n_calibration_runs=run.n_calibration_runs,
        history=[m for _, m in recorder.messages],
        wall_time_s=run.wall_time_s,
    )
    if path.exists():
        shutil.rmtree(path)  # this study's own earlier bag of the same run
    first = recorder.messages[0][0] if recorder.messages else time.time_ns()
    last = recorder.messages[-1][0] if recorder.messages else first
    with BagWriter(path) as bag:
        bag.add_topic('/optimisation/run_config', 'std_msgs/msg/String', [latched])
        bag.add_topic(
            '/optimisation/progress',
            'suspension_tuning_interfaces/msg/IterationRecord',
            [reliable],
        )
        bag.add_topic(
            '/optimisation/result',
            'suspension_tuning_interfaces/action/Optimise_Result',
            [latched],
        )
        bag.write('/optimisation/run_config', serialize_message(String(data=text)), first - 1)
        bag.add_metadata('run_config', run_config_metadata(text))
        for stamp, msg in recorder.messages:
            bag.write('/optimisation/progress', serialize_message(msg), stamp)
        bag.write('/optimisation/result', serialize_message(result), last + 1)
    return path


# ---------------------------------------------------------------------- study
def compare_to_reference(runs: Sequence[StudyRun], reference: StudyRun) -> None:
    """Fill each run's distance and objective gap to the reference optimum."""
    x_ref = np.asarray(reference.x)
    for run in runs:
        run.distance_to_reference = float(np.linalg.norm(np.asarray(run.x) - x_ref))
        run.gap_to_reference_pct = 100.0 * (run.f - reference.f) / abs(reference.f)


def committed_reference_run(committed: Any, integrator: str | None = 'fixed_step',
                            record: bool = True) -> tuple[StudyRun, _Recorder]:
    """A committed reference optimum as the study's reference row (one full run).

    ``committed`` is a :class:`~suspension_tuning.studies.method_benchmark.Reference`
    (fixed-step model).  Its design is run once on ``integrator``: on the fixed-step
    model the row keeps the committed f and g (``details['f_rerun']`` is the run's,
    equal unless the model changed since the file was written); on another model the
    row holds that model's f and g at the committed design.
    """
    model = FullModelCache(committed.scenario, committed.n_vars, integrator)
    recorder = _Recorder(record)
    history: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    x = validate_design(committed.x, committed.n_vars)[0]
    f_run, g_run = model(x)
    _recording(model, history, recorder)(x)
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
    runs: list[tuple[StudyRun, _Recorder]] = []
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
def _cal_label(run: StudyRun) -> str:
    """Calibration sample count of a simplified-gradient run, '-' for the others."""
    return str(run.calibration_samples) if run.method == 'dq_simplified' else '-'


def _fmt(value: float, digits: int = 4) -> str:
    return f'{value:.{digits}f}' if math.isfinite(value) else '-'


def _fmt_g(value: float) -> str:
    return f'{value:.3g}' if math.isfinite(value) else '-'


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
            cal = _cal_label(r)
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
            cal = _cal_label(r)
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
            f"best f = {_fmt(d['polished_from_grid_best_f'], 5)}, from the methods' final "
            f'points {_fmt(d["polished_from_methods_best_f"], 5)}; reference f = {ref.f:.5f} '
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
                f'| {r.scenario} | {r.n_vars} | {r.start} | {r.method} | {cal} | {_fmt_g(step)} | '
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
