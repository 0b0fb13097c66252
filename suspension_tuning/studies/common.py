"""What the studies share: running a method, counting full runs, study bags, tables.

The method study (:mod:`~suspension_tuning.studies.method_study`), the multi-start
method benchmark (:mod:`~suspension_tuning.studies.method_benchmark`) and the Pareto
study (:mod:`~suspension_tuning.studies.pareto`) run their optimisations through this
module (in-process, no rclpy at import; the ROS message classes are loaded only to
write the bags):

* :func:`run_dynamic_q` - Dynamic-Q through :func:`suspension_tuning.tuning.optimise`,
  the loop of the ROS coordinator, with simplified-model or full-model gradients;
* :func:`run_slsqp` - SciPy SLSQP with its finite differences on the full model;
* :func:`run_peer` - a derivative-free or Bayesian peer of
  :mod:`~suspension_tuning.studies.peers` on the full model, within a budget of full runs;
* :func:`reference_optimum` - a full-factorial grid polished by SLSQP.

Cost counting: every full-model run counts once (:class:`FullModelCache`: the objective
and the constraints at one x come from one run, cached per x).  :func:`write_bag`
records a run as the graph's recorder would; :func:`markdown_table` and :func:`fmt`
format the tables.
"""

from __future__ import annotations

import math
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import OptimizeResult, minimize

from suspension_tuning.metric_names import TYRES
from suspension_tuning.model_identity import builtin_fingerprint
from suspension_tuning.optim.dynamic_q import load_options
from suspension_tuning.optim.simplified_gradient import SimplifiedGradient
from suspension_tuning.paths import config_dir, dump_yaml
from suspension_tuning.reported_design import (
    ReportedDesign,
    design_success,
    reported_design,
    result_message,
)
from suspension_tuning.studies.peers import (
    PEER_BUDGET,
    PEER_LABELS,
    BudgetExhaustedError,
    CountedProblem,
    run_adapter,
)
from suspension_tuning.tuning import (
    FullEvaluation,
    RunCounter,
    TuningRequest,
    centre,
    optimise,
    physical_settings,
    with_noise_levels,
)
from suspension_tuning.vehicle.design import (
    X_LOWER,
    X_UPPER,
    baseline_design,
    load_design_space,
    validate_design,
)
from suspension_tuning.vehicle.params import integrator_name
from suspension_tuning.vehicle.runs import run_full

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
    **PEER_LABELS,
}
#: Grid points per axis of the reference search (2 and 4 variables) [E: 41 gives a
#: 0.025 spacing, the central-difference half step; 7^4 = 2401 full runs for n = 4].
GRID_POINTS = {2: 41, 4: 7}
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
    integrator : str, optional
        Full-model integrator (default config/vehicle.yaml's).
    budget : int, optional
        Distinct designs allowed; one more raises
        :class:`~suspension_tuning.studies.peers.BudgetExhaustedError`.

    A design whose run fails (:func:`run_designs`) counts as a run and gives f = inf
    and g = inf, never feasible; it is listed in ``failed``.
    """

    def __init__(self, scenario: str, n_vars: int, integrator: str | None = None,
                 budget: int | None = None) -> None:
        self.scenario = scenario
        self.n_vars = n_vars
        self.integrator = integrator
        self.budget = budget
        self.values: dict[bytes, tuple[float, Array]] = {}
        self.failed: list[dict[str, Any]] = []

    @property
    def n_runs(self) -> int:
        """Distinct designs run so far."""
        return len(self.values)

    def __call__(self, x: ArrayLike) -> tuple[float, Array]:
        """Objective and constraints at one design (one full run if not cached)."""
        xv = validate_design(np.asarray(x, dtype=float), self.n_vars)[0]
        key = xv.tobytes()
        if key not in self.values:
            if self.budget is not None and self.n_runs >= self.budget:
                raise BudgetExhaustedError(f'budget of {self.budget} full runs spent')
            f, g, failed = run_designs(self.scenario, xv[None, :], self.n_vars,
                                       self.integrator)
            self.values[key] = (float(f[0]), g[0].copy())
            self.failed += failed
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
        return baseline_design(n_vars)
    raise ValueError(f'unknown start point {name!r}; valid: {", ".join(STARTS)}')


def vehicle_options() -> dict[str, Any]:
    """Dynamic-Q options of config/optimiser.yaml, section ``vehicle``."""
    return load_options(str(config_dir() / 'optimiser.yaml'), 'vehicle').as_dict()


# ---------------------------------------------------------------------- bag messages
class Recorder:
    """Collects a run's IterationRecord messages (with receive times) for its bag."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.messages: list[tuple[int, Any]] = []
        self.t0 = time.monotonic()
        if enabled:
            from suspension_tuning.nodes.coordinator import record_to_msg

            self._to_msg = record_to_msg

    def add(self, record: dict[str, Any], counter: RunCounter) -> None:
        """Keep one iteration record (when recording), stamped now."""
        if self.enabled:
            self.messages.append((time.time_ns(), self._to_msg(record, counter, self.t0)))


def history_entry(record: dict[str, Any], counter: RunCounter) -> dict[str, Any]:
    """One record of a run's history: iteration, f, max violation, run counts, x."""
    return {
        'iteration': int(record['iteration']),
        'f': float(record['f']),
        'max_violation': float(record['max_violation']),
        'g': np.asarray(record.get('g', ()), float).tolist(),
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
    check: bool = False,
) -> tuple[StudyRun, Recorder]:
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
    check : bool
        Check the answer at the tighter tolerance (:mod:`suspension_tuning.answer_check`,
        ``optimise``'s ``check_model``; paid full runs, in ``n_full_runs``); the
        verdicts go to ``details['check']``.  When the check continued the run with
        shifted constraints, the history's earlier records carry the shift in their
        ``max_violation`` too, so the run reports the continuation's answer; when it
        continued on the check model, their ``max_violation`` is inf (the check
        overruled their model's feasibility).
    """
    # the built-in model's noise levels (config/optimiser.yaml noise_levels) unless set
    options = with_noise_levels(vehicle_options() if options is None else options,
                                scenario, integrator or '')
    start_x = start_point(start, n_vars) if x0 is None else validate_design(x0, n_vars)[0]
    request = TuningRequest(
        scenario, n_vars, start_x, gradient_source, options, FD_STEP, constraints,
        integrator=integrator or '',
    )
    counter = RunCounter(calibration_runs=calibration_samples)
    recorder = Recorder(record)
    history: list[dict[str, Any]] = []

    def on_iteration(rec: dict[str, Any], counts: RunCounter) -> bool:
        history.append(history_entry(rec, counts))
        recorder.add(rec, counts)
        return False

    t0 = time.perf_counter()
    models = {name: full_model(name, n_vars, integrator)
              for name in request.constraint_scenarios}
    from suspension_tuning.answer_check import check_options

    checking = check_options(scenario, n_vars) if check else {}

    result = optimise(
        request, full_model(scenario, n_vars, integrator), gradient, on_iteration,
        counter=counter, constraint_models=models, constraint_gradients=constraint_gradients,
        **checking,
    )
    verdict = result.get('check')
    if verdict and verdict.get('continued') and verdict.get('continue_by') == 'tighter_model':
        # the run's model's feasibility before the continuation was overruled by the
        # check: those records are no longer candidates for the reported design
        for entry in history:
            if entry['iteration'] < verdict['first_iteration']:
                entry['max_violation'] = math.inf
    elif verdict and verdict.get('continued'):
        shift = np.asarray(verdict['shift'], float)
        for entry in history:
            if entry['iteration'] < verdict['first_iteration'] and entry['g']:
                g = np.asarray(entry['g'], float)
                g[:len(shift)] += shift[:len(g)]
                entry['max_violation'] = max_violation(g)
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
                 **model_details(integrator),
                 'best_iteration': design.iteration, 'best_feasible': design.feasible,
                 'stop_test': str(result.get('stop_test', '')),
                 'check': verdict,
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


def minimize_slsqp(
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


def recording(model: FullModelCache, history: list[dict[str, Any]], recorder: Recorder):
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
        history.append(history_entry(rec, counter))
        recorder.add(rec, counter)

    return add


def model_details(integrator: str | None) -> dict[str, str]:
    """A study run's full model: its integrator and fingerprint (model_identity).

    Every study record and study bag carries them, as the graph's run configurations
    do, so a result names the model that produced it.
    """
    name = integrator_name(integrator)
    return {'integrator': name, 'model_fingerprint': builtin_fingerprint(name)}


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
    budget: int | None = None,
) -> tuple[StudyRun, Recorder]:
    """SciPy SLSQP with its finite differences on the full model.

    ``jac=None``: SciPy's 2-point forward differences with the absolute step ``eps``
    (default SciPy's sqrt(machine eps) = 1.49e-8, normalised units), n full runs per
    gradient; the objective and the constraints at one x share one full run
    (:class:`FullModelCache`).  ``method`` names the row ('slsqp' or
    'slsqp_best_fd'); ``x0`` replaces the named ``start`` (which then only labels the
    run).  Every evaluated design is kept in order in ``evaluations``.  With ``budget``
    the run stops when SLSQP asks for one more full run (its last iterate is then the
    final point).
    """
    model = FullModelCache(scenario, n_vars, integrator, budget)
    recorder = Recorder(record)
    history: list[dict[str, Any]] = []
    x0 = start_point(start, n_vars) if x0 is None else validate_design(x0, n_vars)[0]

    add = recording(model, history, recorder)

    t0 = time.perf_counter()
    add(x0)  # iteration 0: the start point (SLSQP's own first evaluation hits the cache)
    try:
        result = minimize_slsqp(model, x0, lambda x, _: add(x), maxiter, eps)
    except BudgetExhaustedError as stop:
        result = OptimizeResult(x=np.asarray(history[-1]['x'], float), nit=len(history) - 1,
                                success=False, message=str(stop))
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
            **model_details(integrator),
            'budget': budget,
        },
        evaluations=[
            {'n_full_runs': k + 1, 'f': fk, 'max_violation': max_violation(gk),
             'x': np.frombuffer(key).tolist()}
            for k, (key, (fk, gk)) in enumerate(model.values.items())],
    )
    return run, recorder


def run_peer(
    method: str,
    scenario: str,
    n_vars: int,
    start: str,
    x0: ArrayLike | None = None,
    integrator: str | None = None,
    budget: int = PEER_BUDGET,
    stop_when: Callable[[dict[str, Any]], bool] | None = None,
) -> StudyRun:
    """A peer of :mod:`~suspension_tuning.studies.peers` on the full model, within a budget.

    ``method`` is one of :data:`~suspension_tuning.studies.peers.PEERS`; it starts
    from ``x0`` (default the named ``start``) in the normalised box and may spend
    ``budget`` full runs (every distinct design is one run, counted once).  The reported
    design is the best feasible one it evaluated (max g <= config/optimiser.yaml
    ``vehicle`` gtol), or the least violating one; every evaluated design is kept in
    order in ``evaluations`` (and ``history``).  ``stop_when`` may end the run early
    (:class:`~suspension_tuning.studies.peers.CountedProblem`).
    """
    model = FullModelCache(scenario, n_vars, integrator)
    x0 = start_point(start, n_vars) if x0 is None else validate_design(x0, n_vars)[0]
    problem = CountedProblem(model, [X_LOWER] * n_vars, [X_UPPER] * n_vars, budget,
                             stop_when)
    peer = run_adapter(method, problem, x0)
    gtol = float(vehicle_options()['gtol'])
    records = [{k: e[k] for k in ('n_full_runs', 'f', 'max_violation', 'x')}
               for e in peer.evaluations]
    best = peer.best_feasible(gtol) or min(peer.evaluations,
                                           key=lambda e: e['max_violation'])
    history = [{'iteration': k, 'n_simplified_runs': 0, **r} for k, r in enumerate(records)]
    return StudyRun(
        scenario=scenario, n_vars=n_vars, start=start, method=method,
        calibration_samples=0, x=list(best['x']), f=float(best['f']),
        g=list(best['g']), max_violation=float(best['max_violation']),
        iterations=len(records), n_full_runs=problem.n_runs, n_simplified_runs=0,
        n_calibration_runs=0, wall_time_s=peer.wall_time_s,
        success=best['max_violation'] <= gtol, message=peer.message, history=history,
        details={'budget': budget, **model_details(integrator),
                 'gtol': gtol},
        evaluations=records,
    )


def grid_designs(n_vars: int, points: int) -> Array:
    """Full-factorial grid over the normalised box, ``points`` per axis (bounds included)."""
    if points < 2:
        raise ValueError(f'grid points per axis must be >= 2, got {points}')
    axis = np.linspace(X_LOWER, X_UPPER, points)
    mesh = np.meshgrid(*[axis] * n_vars, indexing='ij')
    return np.column_stack([m.ravel() for m in mesh])


def run_designs(scenario: str, designs: Array, n_vars: int, integrator: str | None = None
                ) -> tuple[Array, Array, list[dict[str, Any]]]:
    """f (m,) and g (m, k) of checked designs (m, n); a design whose run fails is infeasible.

    A grid, or a peer's poll, reaches the corners of the box, where a run can fail (in
    the two-state design, the smallest gas volumes of both states with the least damping
    on the Belgian paving: the gas pressure grows without bound and the fixed-step
    integration diverges, so a state turns NaN).  A failed batch then runs design by
    design; a design that fails alone gets f = inf and g = inf (never feasible, never a
    polish start: the extreme barrier SciPy's COBYLA and COBYQA apply to such values)
    and is listed with its error.
    """
    if len(designs) > 1:
        try:
            res = run_full(scenario, designs, n_vars=n_vars, integrator=integrator)
            return np.asarray(res.f, float), np.asarray(res.g, float), []
        except ValueError:
            pass
    f, g, failed = [], [], []
    for x in designs:
        try:
            res = run_full(scenario, x[None, :], n_vars=n_vars, integrator=integrator)
            f.append(float(res.f[0]))
            g.append(np.asarray(res.g[0], float))
        except ValueError as exc:
            f.append(math.inf)
            g.append(np.full(len(TYRES), math.inf))
            failed.append({'x': np.round(x, 6).tolist(), 'error': str(exc)[:200]})
    return np.array(f), np.vstack(g), failed


def reference_optimum(
    scenario: str,
    n_vars: int,
    points: int,
    extra_starts: Sequence[ArrayLike] = (),
    gtol: float = 1e-3,
    record: bool = True,
    integrator: str | None = None,
    polish_eps: float = SLSQP_EPS,
) -> tuple[StudyRun, Recorder]:
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
    f_grid, g_grid, failed = [], [], []
    for k in range(0, len(grid), GRID_BATCH):
        f, g, bad = run_designs(scenario, grid[k : k + GRID_BATCH], n_vars, integrator)
        f_grid.append(f)
        g_grid.append(g)
        failed += bad
    f_grid, g_grid = np.concatenate(f_grid), np.vstack(g_grid)
    feasible = np.max(g_grid, axis=1) <= gtol
    if not feasible.any():
        raise ValueError(f'{scenario}, {n_vars} variables: no feasible grid point')
    order = np.argsort(np.where(feasible, f_grid, np.inf))
    model = FullModelCache(scenario, n_vars, integrator)
    for x, f, g in zip(grid, f_grid, g_grid):  # the grid's runs, counted once
        model.values[validate_design(x, n_vars)[0].tobytes()] = (float(f), g.copy())
    best_x, best_f = grid[order[0]].copy(), float(f_grid[order[0]])
    recorder = Recorder(record)
    history: list[dict[str, Any]] = []

    add = recording(model, history, recorder)

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
        res = minimize_slsqp(model, np.asarray(x0, float), eps=polish_eps)
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
            'grid_failed': failed,
            'polished_from_grid_best_f': min(polished['grid'], default=math.inf),
            'polished_from_methods_best_f': min(polished['method'], default=math.inf),
            'gtol': gtol,
            'polish_eps': float(polish_eps),
            **model_details(integrator),
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


def write_bag(path: Path, run: StudyRun, recorder: Recorder) -> Path:
    """Record one run as a rosbag2-style bag, as the graph's recorder would.

    Topics ``/optimisation/run_config`` (std_msgs/String, YAML), ``/optimisation/progress``
    (IterationRecord per iteration) and ``/optimisation/result`` (OptimisationResult); the
    run_config YAML is also the bag's ``run_config`` metadata record.
    """
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String
    from suspension_tuning_interfaces.msg import OptimisationResult

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
    result = OptimisationResult(
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
        physical_units=list(load_design_space().physical_units(len(run.x))),
        iterations=run.iterations,
        n_full_runs=run.n_full_runs,
        n_simplified_runs=run.n_simplified_runs,
        n_calibration_runs=run.n_calibration_runs,
        history=[m for _, m in recorder.messages],
        wall_time_s=run.wall_time_s,
        stop_test=str(run.details.get('stop_test', '')),
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
            'suspension_tuning_interfaces/msg/OptimisationResult',
            [latched],
        )
        bag.write('/optimisation/run_config', serialize_message(String(data=text)), first - 1)
        bag.add_metadata('run_config', run_config_metadata(text))
        for stamp, msg in recorder.messages:
            bag.write('/optimisation/progress', serialize_message(msg), stamp)
        bag.write('/optimisation/result', serialize_message(result), last + 1)
    return path



def cal_label(run: StudyRun) -> str:
    """Calibration sample count of a simplified-gradient run, '-' for the others."""
    return str(run.calibration_samples) if run.method == 'dq_simplified' else '-'


def fmt(value: float, digits: int = 4) -> str:
    """A number with ``digits`` decimals, '-' when not finite."""
    return f'{value:.{digits}f}' if math.isfinite(value) else '-'


def fmt_g(value: float) -> str:
    """A number with 3 significant digits, '-' when not finite."""
    return f'{value:.3g}' if math.isfinite(value) else '-'

