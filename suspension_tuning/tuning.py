"""The paper's optimisation loop, independent of where models run (no rclpy).

Thoresson et al. (2009), section 2: Dynamic-Q asks for the objective and the
constraints at each iterate, which always come from the full vehicle model (one run
per iteration), and for their gradients, which come either from central differences
on the full model (2n full runs per iteration) or from central differences on the
eq. 25-scaled simplified models (2n cheap runs, "0.2n + 1 function evaluations per
iteration").

With simplified gradients the loop also corrects them (``TuningRequest.correction``,
:mod:`suspension_tuning.optim.correction`): the full run at each iterate and the scaled
simplified values at the same design (one more simplified run in the gradient's batch)
give the discrepancy of the two models, whose Jacobian a secant update learns along the
iterates, so the gradients follow the full model's slopes without an extra full run.

:func:`optimise` drives :class:`~suspension_tuning.optim.dynamic_q.DynamicQ` with two
callables, so the same loop runs in-process (physics called directly) and in the ROS
coordinator (physics called through services on simulation workers and the gradient
evaluator).  It counts full-model and simplified-model runs in one place
(:class:`RunCounter`), like scipy's ``ScalarFunction`` counts ``nfev``.

Extra inequality constraints (:class:`ConstraintSpec`) bound a quantity of any
scenario's full-model run at the same design: another scenario's objective (minimise
f_ride subject to f_hand <= 0.8), its eq. 11 tyre-hop constraints, or a named metric
(roll_first_peak_deg <= 4 in the lane change).  Each becomes ``value - bound <= 0``
after the scenario's own eq. 11 constraints.  Their gradients come from the eq.
25-scaled simplified model of their scenario where one exists (the objective and the
tyre-hop constraints of 'ride' and 'handling') and from full-model central differences
otherwise (named metrics, the 'mixed' scenario); the result says which per constraint.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import OptimizeResult

from suspension_tuning.optim.correction import (
    RESTART_CAUSES,
    CorrectionOptions,
    SecantCorrection,
    poorly_seen,
)
from suspension_tuning.optim.dynamic_q import DynamicQ, DynamicQOptions
from suspension_tuning.optim.finite_diff import central_difference
from suspension_tuning.vehicle.design import (
    X_LOWER,
    X_UPPER,
    DesignSpace,
    load_design_space,
    validate_design,
)
from suspension_tuning.vehicle.params import INTEGRATORS
from suspension_tuning.vehicle.simplified import INPUT_SCENARIOS, SIMPLIFIED_SCENARIOS

Array = NDArray[np.float64]

#: Gradient sources of the Optimise action.
GRADIENT_SOURCES = ('simplified', 'full')


class RunCancelled(Exception):  # noqa: N818 - a stop, not an error
    """Raised by a full model or gradient whose run was cancelled mid-iteration.

    :func:`optimise` then stops as on a cancelling callback: its result holds the
    iterations completed before (the best design among them), status 99.
    """
#: Scenarios that can be optimised ('mixed': rough road then lane change, the valves
#: switched closed-loop; both 4S4 states at once with a design that names them).
OPTIMISATION_SCENARIOS = ('ride', 'handling', 'mixed')
#: Scenarios whose full-model run can give an extra constraint.
CONSTRAINT_SCENARIOS = ('ride', 'handling', 'mixed')
#: Names of each scenario's objective in a constraint (besides 'f'): eqs. 9 and 10,
#: and the mixed scenario's mean of the two.
OBJECTIVE_NAMES = {'ride': 'f_ride', 'handling': 'f_hand', 'mixed': 'f_mixed'}
#: Names of the eq. 11 tyre-hop constraints in a constraint (FL, FR, RL, RR).
TYRE_HOP_NAMES = ('g_fl', 'g_fr', 'g_rl', 'g_rr')
# SIMPLIFIED_SCENARIOS: scenarios with an eq. 25-scaled simplified model of f and g
# (paper section 6; 'mixed': both of the paper's, each in its valve state);
# INPUT_SCENARIOS: those whose simplified model needs the full run's inputs (steer, slip
# angles).  Both from vehicle.simplified, imported above.


@dataclass
class FullEvaluation:
    """Full-model values of a batch of designs.

    Attributes
    ----------
    f : ndarray, shape (m,)
        Objective, eq. 9 (ride) or eq. 10 (handling).
    g : ndarray, shape (m, k)
        Inequality constraints, eq. 11 (<= 0 feasible).
    inputs : object, optional
        What the simplified model of this scenario needs from the full model's run of
        the first design (steering and slip angles for handling); passed through to
        the simplified gradient unchanged.
    metric_names : sequence of str
        Names of the metric columns (``evaluation.metric_table``); needed only when a
        constraint bounds a named metric of this scenario.
    metrics : ndarray, shape (m, len(metric_names)), optional
        Metric values.
    """

    f: Array
    g: Array
    inputs: Any = None
    metric_names: Sequence[str] = ()
    metrics: Array | None = None


#: How a run continues when the check at a tighter tolerance finds its answer
#: infeasible (:func:`optimise`'s ``check_continue_by``; config/vehicle.yaml
#: ``integration.check.continue_by``): 'shift' (on the run's model, the eq. 11
#: constraints shifted by the offset the check measured) or 'tighter_model' (on the
#: check's model itself, from the answer).
CONTINUE_BY = ('shift', 'tighter_model')
#: Where a continuation on the check's model started (``check['continued_from']``, the
#: keys), in words (the coordinator's ``check_note``, the bag, ``tune``).
CONTINUED_FROM = {
    'answer': 'from the answer, which the check found infeasible',
    'answer, noise stop': ("from the answer, where the noise test ended the run within "
                           "its model's noise"),
    'last_iterate': ('from the last iterate, where the run converged away from its '
                     'answer'),
    'last_iterate, answer kept': ('from the last iterate, where the run converged away '
                                  'from its answer; nothing better was found there, so '
                                  'the answer stays'),
}

#: Full model on a batch: designs (m, n) -> FullEvaluation.
FullModel = Callable[[Array], FullEvaluation]
#: Scaled simplified-model gradient at x with the full model's inputs -> (df, dg,
#: values): the gradient of f, the Jacobian of g and the scaled simplified values
#: (f, g) at x itself, which the first-order correction needs.  A source that returns
#: only (df, dg) runs without the correction.
SimplifiedGradient = Callable[[Array, Any], tuple[Array, ...]]


@dataclass
class RunCounter:
    """Model runs spent by one optimisation (the paper's cost measure)."""

    full_runs: int = 0
    simplified_runs: int = 0
    calibration_runs: int = 0

    def as_dict(self) -> dict[str, int]:
        """Return the counts as a plain dict."""
        return {'n_full_runs': self.full_runs, 'n_simplified_runs': self.simplified_runs,
                'n_calibration_runs': self.calibration_runs}


@dataclass(frozen=True)
class ConstraintSpec:
    """An extra inequality constraint: ``quantity(scenario's run at x) <= upper_bound``.

    Parameters
    ----------
    scenario : str
        'ride', 'handling' or 'mixed' (:data:`CONSTRAINT_SCENARIOS`).
    quantity : str
        'f' or the scenario's objective name (:data:`OBJECTIVE_NAMES`), an eq. 11
        tyre-hop constraint (:data:`TYRE_HOP_NAMES`) or a metric name of the scenario
        (``evaluation.METRIC_NAMES``, with its unit in the name).
    upper_bound : float
        Upper bound in the quantity's units.

    Raises
    ------
    ValueError
        Unknown scenario or quantity, or a bound that is not a finite number.
    """

    scenario: str
    quantity: str
    upper_bound: float

    def __post_init__(self) -> None:
        """Validate the fields; the objective's name is stored as 'f'."""
        from suspension_tuning.metric_names import METRIC_NAMES

        if self.scenario not in CONSTRAINT_SCENARIOS:
            raise ValueError(f'constraint: unknown scenario {self.scenario!r}; '
                             f'valid: {", ".join(CONSTRAINT_SCENARIOS)}')
        quantity = 'f' if self.quantity == OBJECTIVE_NAMES[self.scenario] else self.quantity
        valid = ('f', OBJECTIVE_NAMES[self.scenario], *TYRE_HOP_NAMES,
                 *METRIC_NAMES[self.scenario])
        if quantity not in valid:
            raise ValueError(f'constraint: unknown metric {self.quantity!r} of scenario '
                             f'{self.scenario!r}; valid: {", ".join(valid)}')
        try:
            bound = float(self.upper_bound)
        except (TypeError, ValueError):
            raise ValueError(f'constraint {self.scenario}:{self.quantity}: the upper bound '
                             f'must be a number, got {self.upper_bound!r}') from None
        if not np.isfinite(bound):
            raise ValueError(f'constraint {self.scenario}:{self.quantity}: the upper bound '
                             f'must be finite, got {bound}')
        object.__setattr__(self, 'quantity', quantity)
        object.__setattr__(self, 'upper_bound', bound)

    @classmethod
    def parse(cls, text: str) -> ConstraintSpec:
        """Read ``'<scenario>:<quantity><=<bound>'``, e.g. ``'handling:f_hand<=0.8'``."""
        head, sep, bound = str(text).partition('<=')
        scenario, colon, quantity = head.partition(':')
        if not sep or not colon:
            raise ValueError(f"constraint {text!r}: expected '<scenario>:<quantity><=<bound>', "
                             "e.g. 'handling:f_hand<=0.8'")
        try:
            value = float(bound)
        except ValueError:
            raise ValueError(f'constraint {text!r}: the upper bound {bound.strip()!r} is not '
                             f'a number') from None
        return cls(scenario.strip(), quantity.strip(), value)

    @classmethod
    def coerce(cls, spec: Any) -> ConstraintSpec:
        """A ConstraintSpec from itself, a ``'s:q<=b'`` string, a mapping or a 3-sequence."""
        if isinstance(spec, ConstraintSpec):
            return spec
        if isinstance(spec, str):
            return cls.parse(spec)
        if isinstance(spec, Mapping):
            try:
                return cls(spec['scenario'], spec['quantity'], spec['upper_bound'])
            except KeyError as missing:
                raise ValueError(f'constraint {dict(spec)!r} has no {missing}') from None
        if isinstance(spec, Sequence) and len(spec) == 3:
            return cls(*spec)
        raise ValueError(f'cannot read a constraint from {spec!r}: give (scenario, quantity, '
                         "upper bound) or '<scenario>:<quantity><=<bound>'")

    @property
    def has_simplified_model(self) -> bool:
        """Whether an eq. 25-scaled simplified model gives this quantity's gradient."""
        return self.scenario in SIMPLIFIED_SCENARIOS and (
            self.quantity == 'f' or self.quantity in TYRE_HOP_NAMES)

    @property
    def label(self) -> str:
        """``'<scenario>:<quantity><=<bound>'`` (the objective by its name)."""
        name = OBJECTIVE_NAMES[self.scenario] if self.quantity == 'f' else self.quantity
        return f'{self.scenario}:{name}<={self.upper_bound:g}'

    def as_dict(self) -> dict[str, Any]:
        """Plain dict of the three fields (JSON, run configurations)."""
        return {'scenario': self.scenario, 'quantity': self.quantity,
                'upper_bound': self.upper_bound}

    def values(self, evaluation: FullEvaluation) -> Array:
        """The quantity of every design of a full evaluation of its scenario, (m,)."""
        if self.quantity == 'f':
            return np.asarray(evaluation.f, float)
        if self.quantity in TYRE_HOP_NAMES:
            return np.asarray(evaluation.g, float)[:, TYRE_HOP_NAMES.index(self.quantity)]
        names = list(evaluation.metric_names)
        if self.quantity not in names or evaluation.metrics is None:
            raise ValueError(f'constraint {self.label}: the {self.scenario} full model '
                             f'returned no metric {self.quantity!r}')
        return np.asarray(evaluation.metrics, float)[:, names.index(self.quantity)]

    def simplified_value(self, values: Array) -> float:
        """The quantity from a simplified model's values (f, then g FL..RR)."""
        values = np.asarray(values, float)
        if self.quantity == 'f':
            return float(values[0])
        return float(values[1 + TYRE_HOP_NAMES.index(self.quantity)])

    def derivative(self, df: Array, dg: Array) -> Array:
        """The quantity's row of a simplified gradient ``(df (n,), dg (4, n))``."""
        if self.quantity == 'f':
            return np.asarray(df, float)
        return np.asarray(dg, float)[TYRE_HOP_NAMES.index(self.quantity)]


def constraint_specs(specs: Sequence[Any] | None) -> tuple[ConstraintSpec, ...]:
    """Validate a list of constraint specifications (see :meth:`ConstraintSpec.coerce`)."""
    if specs is None:
        return ()
    if isinstance(specs, (str, Mapping)):
        specs = [specs]
    return tuple(ConstraintSpec.coerce(spec) for spec in specs)


@dataclass(frozen=True)
class TuningRequest:
    """What to optimise (the Optimise action's goal, validated).

    Parameters
    ----------
    scenario : str
        'ride' or 'handling'.
    n_vars : int
        2 (eq. 5) or 4 (eq. 7) design variables.
    x0 : array_like, optional
        Normalised start point; None = centre of the design space.
    gradient_source : str
        'simplified' or 'full'.
    options : mapping, optional
        Dynamic-Q options (see :class:`DynamicQOptions`).
    fd_step : float
        Central-difference half step of full-model gradients, normalised units.
    constraints : sequence, optional
        Extra inequality constraints (:class:`ConstraintSpec`, or anything
        :meth:`ConstraintSpec.coerce` reads), after the eq. 11 constraints in g.
    integrator : str
        Full-model integrator: 'fixed_step', 'variable_step' or '' (the simulation's
        default, config/vehicle.yaml).
    correction : mapping, optional
        Options of the first-order correction of simplified gradients
        (:class:`~suspension_tuning.optim.correction.CorrectionOptions`; default:
        the secant correction).
    road : str
        Ride road in place of config/scenarios.yaml's: a road of config/road.yaml, a
        road file or an entry as YAML (:func:`~suspension_tuning.vehicle.road.
        resolve_road`); '' = the configured one.  Checked here (a bad road file is a bad
        goal); the mixed scenario drives it too.
    conditions : str
        A set of operating conditions (:mod:`suspension_tuning.conditions`): a condition
        file's path, or the set as JSON text (:meth:`ConditionSet.as_text`); '' = the
        single condition of config/scenarios.yaml.  Ride or handling, without a goal
        road (each condition names its road); extra constraints bound quantities of the
        goal's scenario, each in every condition.  Checked here; parsed into
        ``condition_set``.  Optimised by :func:`optimise_conditions`.
    condition_form : str
        'worst' (min-max in epigraph form; the default for '') or 'mean' (weighted).
    """

    scenario: str
    n_vars: int
    x0: ArrayLike | None = None
    gradient_source: str = 'simplified'
    options: Mapping[str, Any] | None = None
    fd_step: float = 0.025
    constraints: Sequence[Any] = ()
    integrator: str = ''
    correction: Mapping[str, Any] | None = None
    road: str = ''
    conditions: str = ''
    condition_form: str = ''
    start: Array = field(init=False, repr=False)
    condition_set: Any = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        """Validate every field; raise ValueError naming the problem."""
        if self.scenario not in OPTIMISATION_SCENARIOS:
            raise ValueError(f'unknown scenario {self.scenario!r}; '
                             f'valid: {", ".join(OPTIMISATION_SCENARIOS)}')
        load_design_space().check_size(self.n_vars)
        if self.gradient_source not in GRADIENT_SOURCES:
            raise ValueError(f'unknown gradient source {self.gradient_source!r}; '
                             f'valid: {", ".join(GRADIENT_SOURCES)}')
        if self.integrator not in ('', *INTEGRATORS):
            raise ValueError(f'unknown integrator {self.integrator!r}; '
                             f'valid: {", ".join(INTEGRATORS)} or empty (default)')
        if not (np.isfinite(self.fd_step) and 0.0 < self.fd_step <= 0.25):
            raise ValueError(f'fd_step must lie in (0, 0.25], got {self.fd_step}')
        x0 = centre(self.n_vars) if self.x0 is None or len(self.x0) == 0 else self.x0
        object.__setattr__(self, 'start', validate_design(x0, self.n_vars)[0])
        DynamicQOptions.from_mapping(self.options)
        object.__setattr__(self, 'correction',
                           CorrectionOptions.from_mapping(self.correction).as_dict())
        object.__setattr__(self, 'constraints', constraint_specs(self.constraints))
        if self.conditions:
            from suspension_tuning.conditions import ConditionSet, check_form

            object.__setattr__(self, 'condition_form', check_form(self.condition_form))
            from suspension_tuning.conditions import CONDITION_SCENARIOS

            if self.scenario not in CONDITION_SCENARIOS:
                raise ValueError('operating conditions are for the ride and handling '
                                 f'scenarios, not {self.scenario!r}')
            other = [c.label for c in self.constraints if c.scenario != self.scenario]
            if other:
                raise ValueError(
                    f'constraint {other[0]}: with a condition set, a constraint bounds a '
                    f'{self.scenario} quantity (the goal\'s scenario, e.g. '
                    f"'{self.scenario}:{OBJECTIVE_NAMES[self.scenario]}<=0.5'), which then "
                    'holds in every condition')
            if self.road:
                raise ValueError('a goal road does not combine with a condition set: each '
                                 'condition names its road')
            object.__setattr__(self, 'condition_set', ConditionSet.from_text(self.conditions))
        elif self.condition_form:
            from suspension_tuning.conditions import check_form

            check_form(self.condition_form)
        if self.road:
            from suspension_tuning.vehicle.road import resolve_road
            from suspension_tuning.vehicle.road_files import FileRoadSpec, file_length_m

            spec = resolve_road(self.road)
            if isinstance(spec, FileRoadSpec):
                file_length_m(spec)  # an unreadable file is refused with the goal

    @property
    def constraint_scenarios(self) -> tuple[str, ...]:
        """Scenarios other than the objective's that the constraints need, in order."""
        names = [c.scenario for c in self.constraints if c.scenario != self.scenario]
        return tuple(dict.fromkeys(names))

    def constraint_gradient_sources(self) -> list[str]:
        """Per extra constraint: 'simplified' or 'full' (central differences)."""
        return ['simplified' if self.gradient_source == 'simplified'
                and c.has_simplified_model else 'full' for c in self.constraints]


def physical_settings(x: ArrayLike, space: DesignSpace | None = None) -> dict[str, float]:
    """Physical settings of one normalised design by name, units at the edge.

    Parameters
    ----------
    x : array_like, shape (2,) or (4,)
        Normalised design (eqs. 4-8).
    space : DesignSpace, optional
        The design space (default config/design_space.yaml).

    Returns
    -------
    dict
        The four per-axle names of the design space with their units
        (``dpsf_front``, ``gas_volume_front_l``, ``dpsf_rear``, ``gas_volume_rear_l`` for
        the paper's), each value in its variable's unit.
    """
    return (space if space is not None else load_design_space()).physical_values(x)


def centre(n_vars: int) -> Array:
    """Centre of the normalised design space (eqs. 6 and 8)."""
    return np.full(n_vars, 0.5 * (X_LOWER + X_UPPER))


def optimise(request: TuningRequest, full_model: FullModel,
             simplified_gradient: SimplifiedGradient | None = None,
             callback: Callable[[dict[str, Any], RunCounter], bool | None] | None = None,
             history: Sequence[Mapping[str, Any]] | None = None,
             counter: RunCounter | None = None,
             constraint_models: Mapping[str, FullModel] | None = None,
             constraint_gradients: Mapping[str, SimplifiedGradient] | None = None,
             check_model: FullModel | None = None,
             check_gtol: float = 5e-3,
             check_continuations: int = 2,
             check_continue_by: str = 'shift',
             check_noise: tuple[float, float] | None = None,
             check_last_gap: float = 0.0,
             check_refine_noise_stop: bool = False,
             ) -> OptimizeResult:
    """Run Dynamic-Q on the full model with the requested gradient source.

    Parameters
    ----------
    request : TuningRequest
        Scenario, number of variables, start point, gradient source, options and the
        extra constraints.
    full_model : callable
        Designs (m, n) -> :class:`FullEvaluation`; called with one design per
        iteration, and with the 2n central-difference designs when the gradient
        source is 'full'.
    simplified_gradient : callable, optional
        ``(x, inputs) -> (df (n,), dg (k, n))`` from the eq. 25-scaled simplified
        model (2n simplified runs each); required for gradient source 'simplified'.
    callback : callable, optional
        Called with each iteration's record and the run counter; returning True
        stops the run (cancellation).  A model or gradient raising
        :class:`RunCancelled` stops it too, within an iteration.
    history : sequence of mappings, optional
        Records of an earlier run to resume from (``result.history``).
    counter : RunCounter, optional
        Counter to continue (e.g. one that holds the calibration runs).
    constraint_models : mapping, optional
        Scenario name -> full model of that scenario, for every scenario of the extra
        constraints other than the objective's (``request.constraint_scenarios``).
    constraint_gradients : mapping, optional
        Scenario name -> simplified gradient of that scenario, for every other scenario
        of an extra constraint with a simplified model, when the gradient source is
        'simplified'.
    check_model : callable, optional
        The objective scenario's full model at a tighter solver tolerance
        (:mod:`~suspension_tuning.answer_check`).  After the stop the reported design
        runs on it once (a paid full run, counted in ``counter.full_runs``).  When
        that run finds it infeasible (max g > ``check_gtol``) while the run's own model
        found it feasible, the run continues from it with every eq. 11 constraint
        shifted by the offset measured there (``g + max(0, g_check - g)``, summed over
        at most ``check_continuations`` continuations), and each new answer is checked
        again.  With ``check_continue_by`` 'tighter_model' the run continues instead on
        ``check_model`` itself, from the answer (the check's run is its first
        evaluation; the objective scenario's runs go to ``check_model`` from then on,
        with Dynamic-Q's noise levels ``check_noise``), and reports that model's
        answer.  The result's ``check`` says both verdicts (:func:`check_summary`).
    check_gtol, check_continuations, check_continue_by : float, int, str
        See ``check_model`` (config/vehicle.yaml ``integration.check``).
    check_noise : (float, float), optional
        Noise levels (f, g) of ``check_model`` for a run continued on it
        (``DynamicQOptions.noise_f``, ``noise_g``); None keeps the run's.
    check_last_gap : float
        With 'tighter_model': a run that a stop test ended at a last iterate infeasible
        on its model, whose answer's f lies more than this fraction above that
        iterate's, converged away from its answer; the last iterate is checked too
        (one more paid run) and the run goes on from it on ``check_model``.  The
        answer checked first stays the answer when the continuation finds nothing
        better and feasible on ``check_model``.  0 (default): never.
    check_refine_noise_stop : bool
        With 'tighter_model': a run the noise test ended on a model whose f noise
        exceeds ``check_noise``'s goes on from its answer on ``check_model`` even when
        the check confirms it (the noise test tolerates steps within twice the run's
        noise, 1.3 % of f on the built-in variable-step ride).

    Returns
    -------
    scipy.optimize.OptimizeResult
        Dynamic-Q's result plus ``n_full_runs``, ``n_simplified_runs``,
        ``n_calibration_runs`` and ``scenario``, ``n_vars``, ``gradient_source``;
        ``constraints`` (the extra constraints as dicts), ``constraint_values`` (their
        quantities at x, in their units) and ``constraint_gradient_sources``
        ('simplified' or 'full' each).  ``g`` holds the eq. 11 constraints, then
        ``value - bound`` of each extra constraint.  ``x`` is the last iterate; the
        answer to report is the best point (``x_best``, ``f_best``, ``g_best``,
        ``best_iteration``, ``best_feasible`` and ``constraint_values_best``; see
        :func:`~suspension_tuning.optim.dynamic_q.dynamic_q`).  ``stop_test`` names
        the test that ended the run ('xtol', 'ftol', 'noise', 'bound_kkt', 'rho_min', 'maxiter',
        'cancelled'); ``restarts``: how often a corrected run that ended by one of
        CorrectionOptions ``restart_after`` started again from its answer
        (``restarts``; ``restarted_after`` the stop tests it restarted after; the
        history holds every run's records, numbered on, and the message says so);
        with ``check_model``, ``check`` holds the check's verdicts
        (:func:`check_summary`).  Every history record
        whose full run returned named metrics holds them (``metrics``: name -> value,
        the objective scenario's), and ``metrics_best`` those of the reported design.
    """
    if request.gradient_source == 'simplified' and simplified_gradient is None:
        raise ValueError("gradient source 'simplified' needs a simplified_gradient")
    if check_continue_by not in CONTINUE_BY:
        raise ValueError(f'check_continue_by must be one of {", ".join(CONTINUE_BY)}, '
                         f'got {check_continue_by!r}')
    counter = counter or RunCounter()
    terms = _ConstraintTerms(request, full_model, simplified_gradient, constraint_models,
                             constraint_gradients, counter)
    n = request.n_vars
    lower, upper = np.full(n, X_LOWER), np.full(n, X_UPPER)
    # The eq. 11 tyre-hop constraints (the scenario's own, and extra ones on another
    # scenario's) are counts of samples: linearised at simplified-gradient iterates
    # (DynamicQOptions.surrogate_constraint_curvature); smooth extra constraints are not.
    extra_staircase = [c.quantity in TYRE_HOP_NAMES for c in request.constraints]

    def staircase(m: int) -> list[bool]:
        return [True] * (m - len(extra_staircase)) + extra_staircase

    options = DynamicQOptions.from_mapping(request.options).as_dict()
    correction_options = CorrectionOptions.from_mapping(request.correction)
    correct = (request.gradient_source == 'simplified'
               and correction_options.applies_to(request.scenario))
    corrections: list[SecantCorrection | None] = [None]
    # Full-model values at every evaluated design (the history's too, when resumed):
    # the correction compares them with the simplified values at the same design.
    evaluated = {np.asarray(r['x'], float).tobytes(): np.r_[float(r['f']), np.asarray(
        r['g'], float)] for r in (history or ()) if correct}
    run = _Run(request, terms, evaluated, correct, correction_options, corrections,
               callback, counter, lower, upper, options, staircase)
    opt = DynamicQ(request.start, lower, upper, options, history=history,
                   gradient_source=request.gradient_source,
                   surrogate_rule_constraints=staircase)
    cancelled = _drive(opt, run, 0)
    result, cancelled, restarted_after = _restart_after_stop(opt.result(), cancelled, run)
    _note_restarts(result, restarted_after)
    check: dict[str, Any] | None = None
    if check_model is not None and not cancelled and 'x_best' in result:
        result, check = _check_and_continue(result, run, check_model, check_gtol,
                                            check_continuations, check_continue_by,
                                            check_noise, check_last_gap,
                                            check_refine_noise_stop)
    correction = corrections[0]
    return _finish(result, request, terms, counter, correction, check)


@dataclass
class _Run:
    """What :func:`optimise`'s loop and its restarts and continuations share.

    ``evaluated``: full-model values (f, then g) at every evaluated design, which the
    correction compares with the simplified values; ``corrections``: the one slot of
    the secant correction (None until the first gradient, and after a restart);
    ``options``: Dynamic-Q's; ``staircase``: which of m constraints are eq. 11 counts.
    """

    request: TuningRequest
    terms: _ConstraintTerms
    evaluated: dict[bytes, Array]
    correct: bool
    correction_options: CorrectionOptions
    corrections: list[SecantCorrection | None]
    callback: Callable[[dict[str, Any], RunCounter], bool | None] | None
    counter: RunCounter
    lower: Array
    upper: Array
    options: Mapping[str, Any]
    staircase: Callable[[int], list[bool]]
    #: The correction of the run that stopped, until the restart's first gradient.
    previous_correction: Array | None = None
    #: The correction of the run continued on the check's model, until the
    #: continuation's first gradient (``CorrectionOptions.carry_to_check``).
    carried_correction: Array | None = None


def _drive(opt: DynamicQ, run: _Run, first_iteration: int) -> bool:
    """Answer Dynamic-Q's requests until it stops; True when cancelled.

    Records go to ``callback`` with their iteration numbers after ``first_iteration``
    (a continuation after the check numbers on).
    """
    request, terms, evaluated, correct = run.request, run.terms, run.evaluated, run.correct
    correction_options, corrections = run.correction_options, run.corrections
    callback, counter, lower, upper = run.callback, run.counter, run.lower, run.upper
    cancelled = False
    verified: dict[tuple[int, int], tuple[Array, float, Array, Array]] = {}
    while (ask := opt.ask()) is not None:
        kind, x = ask
        try:
            if kind == 'evaluate':
                f, g = terms.evaluate(x)
                if correct:
                    evaluated[x.tobytes()] = np.r_[f, g]
                record = opt.tell((f, g, None))
            elif request.gradient_source == 'full':
                def values(points: Array) -> Array:
                    return terms.stacked_values(points)

                jac = central_difference(values, x, request.fd_step, lower, upper)
                record = opt.tell((jac[0], jac[1:], None), source='full')
            else:
                df, dg, values = terms.simplified_gradient(x, lower, upper)
                full = evaluated.get(x.tobytes())
                if correct and values is not None and full is not None:
                    raw = np.vstack([df, dg])
                    if corrections[0] is None:
                        corrections[0] = _start_correction(run, x, full, values, raw)
                    corrections[0].observe(x, full, values)
                    jac = corrections[0].correct(raw)
                    if correction_options.verify_bounds and verify_bounds(
                            corrections[0], terms, x, full, values, raw, jac,
                            correction_options.seed_step, lower, upper, verified):
                        jac = corrections[0].correct(raw)
                    df, dg = jac[0], jac[1:]
                record = opt.tell((df, dg, None), source='simplified')
        except RunCancelled:
            opt.stop('cancelled')
            cancelled = True
            break
        if record is not None and 'metrics' not in record:
            metrics = terms.metrics.get(np.asarray(record['x'], float).tobytes())
            if metrics is not None:
                record['metrics'] = metrics
        if record is not None and first_iteration:
            record['iteration'] = int(record['iteration']) + first_iteration
        if record is not None and callback is not None and callback(record, counter):
            opt.stop('cancelled')
            cancelled = True
    return cancelled


def _start_correction(run: _Run, x: Array, full: Array, values: Array, raw: Array
                      ) -> SecantCorrection:
    """A run's correction at its first corrected gradient, at ``x``.

    The blind variables' columns seeded (``seed_blind``); at a restart, the columns the
    stopped run found poorly seen set from the full model (``reseed_ratio``); on a
    continuation on the check's model, those columns kept from the run continued
    (``carry_to_check``).  ``full``, ``values``: the full and the scaled simplified
    values at ``x``; ``raw``: the scaled simplified Jacobian there.
    """
    options = run.correction_options
    correction = SecantCorrection(full.size, run.request.n_vars, options.min_step)
    blind = blind_columns(raw) if options.seed_blind else []
    seed_columns(correction, run.terms, x, full, values, raw, blind, options.seed_step,
                 run.lower, run.upper)
    if run.previous_correction is not None:
        seed_columns(correction, run.terms, x, full, values, raw,
                     poorly_seen(run.previous_correction, raw, options.reseed_ratio),
                     options.seed_step, run.lower, run.upper, central=True)
        run.previous_correction = None
    if run.carried_correction is not None:
        correction.carry_columns(
            poorly_seen(run.carried_correction, raw, options.reseed_ratio),
            run.carried_correction)
        run.carried_correction = None
    return correction


def _restart_after_stop(result: OptimizeResult, cancelled: bool, run: _Run
                        ) -> tuple[OptimizeResult, bool, list[str]]:
    """Start a corrected run that ended by a restarting stop test again from its answer.

    A run whose correction learnt from its full runs (the simplified models gave values)
    and that ended by one of ``correction_options.restart_after`` (the iteration limit,
    the ftol test) starts again, at most ``correction_options.restarts`` times: the
    correction afresh at the answer (a blind variable's column seeded there again, and
    the columns the stopped run's correction found the simplified models to see poorly,
    ``reseed_ratio``), Dynamic-Q with its first move limit.  Returns (result, cancelled,
    the stop tests it restarted after).
    """
    after: list[str] = []
    while (run.corrections[0] is not None and not cancelled and 'x_best' in result
           and run.correction_options.restarts_after(result.get('stop_test'), len(after))):
        after.append(str(result['stop_test']))
        run.previous_correction = run.corrections[0].jacobian.copy()
        run.corrections[0] = None
        result, cancelled = _run_from_answer(result, run)
    return result, cancelled, after


def _note_restarts(result: OptimizeResult, after: Sequence[str]) -> None:
    """Note the run's restarts from its answer in ``result`` and its message.

    ``restarts``: how often; ``restarted_after``: after which stop tests.
    """
    result['restarts'] = len(after)
    result['restarted_after'] = list(after)
    if after:
        causes = ', '.join(RESTART_CAUSES.get(a, a) for a in after)
        result['message'] = (f'{result.message} (the run restarted {len(after)} time(s) '
                             f'from its answer: {causes})')


def _run_from_answer(result: OptimizeResult, run: _Run) -> tuple[OptimizeResult, bool]:
    """A new Dynamic-Q run from ``result``'s answer, numbered on after its history.

    The answer's values come from the cache (no full run); the new run's result
    carries both histories and iteration counts.  Returns (result, cancelled).
    """
    first = len(result.history)
    opt = DynamicQ(np.asarray(result.x_best, float), run.lower, run.upper, run.options,
                   gradient_source=run.request.gradient_source,
                   surrogate_rule_constraints=run.staircase)
    cancelled = _drive(opt, run, first)
    second = opt.result()
    for rec in second.history:
        if int(rec['iteration']) < first:
            rec['iteration'] = int(rec['iteration']) + first
    second.update(history=list(result.history) + list(second.history),
                  nit=int(result.nit) + int(second.nit),
                  iterations=int(result.nit) + int(second.nit))
    if 'best_iteration' in second:
        second.update(best_iteration=int(second.best_iteration) + first)
    return second, cancelled


def check_summary(g_run: ArrayLike, g_check: ArrayLike, f_check: float, gtol: float
                  ) -> dict[str, Any]:
    """The check's verdicts on one design (see :func:`optimise`'s ``check_model``).

    ``feasible_run`` and ``feasible_check`` (max g <= gtol on the run's model and at
    the tighter tolerance), ``f_check``, ``max_violation_check``, ``offset`` (g_check -
    g_run of the eq. 11 constraints).
    """
    g_run, g_check = np.asarray(g_run, float), np.asarray(g_check, float)
    viol = float(max(0.0, np.max(g_check))) if g_check.size else 0.0
    return {'feasible_run': bool(g_run.size == 0 or np.max(g_run) <= gtol),
            'feasible_check': bool(viol <= gtol), 'f_check': float(f_check),
            'max_violation_check': viol, 'offset': (g_check - g_run[:g_check.size]).tolist()}


def _check_and_continue(result: OptimizeResult, run: _Run,
                        check_model: FullModel, check_gtol: float, continuations: int,
                        continue_by: str = 'shift',
                        check_noise: tuple[float, float] | None = None,
                        last_gap: float = 0.0, refine_noise_stop: bool = False
                        ) -> tuple[OptimizeResult, dict[str, Any]]:
    """Check the reported design at the tighter tolerance; continue if needed.

    The check's verdict is feasible when its max g <= ``check_gtol``.  When it is not
    while the run's model found the design feasible, Dynamic-Q goes on from it:
    ``continue_by`` 'shift', on the run's model with the eq. 11 constraints shifted by
    the offset measured there (accumulated over at most ``continuations``
    continuations), the new answer checked again; 'tighter_model', once, on the check
    model itself (:func:`_continue_on_check_model`), and from the last iterate instead
    when the run converged away from its answer (:func:`_converged_elsewhere`,
    ``last_gap``).  With ``refine_noise_stop`` a run the noise test ended on a model
    noisier than the check's goes on from its answer on the check model, feasible or
    not (:func:`_noise_limited`).
    """
    terms, evaluated = run.terms, run.evaluated
    def checked(x: Array) -> tuple[float, Array, FullEvaluation]:
        evaluation = check_model(np.asarray(x, float)[None, :])
        run.counter.full_runs += 1
        return float(evaluation.f[0]), np.asarray(evaluation.g[0], float), evaluation

    x_best = np.asarray(result.x_best, float)
    # the g rows (eq. 11, then the extra constraints) as reported: no run of x_best,
    # which a resumed run may have only in the bag's history
    k = len(np.asarray(result.g_best, float))
    f_c, g_c, answer_run = checked(x_best)
    check = check_summary(np.asarray(result.g_best, float)[:len(g_c)], g_c, f_c, check_gtol)
    check.update(continued=False, continuations=0, first=dict(check),
                 x_checked=x_best.tolist(), check_gtol=check_gtol, continue_by=continue_by)
    if continue_by == 'tighter_model' and continuations > 0:
        if _converged_elsewhere(result, run, last_gap):
            last_run = checked(result.x)[2]
            return _continue_from_last(result, run, check_model, check, last_run,
                                       answer_run, check_noise)
        refine = refine_noise_stop and _noise_limited(result, run, check_noise)
        if refine or (not check['feasible_check'] and check['feasible_run']):
            check.update(continued_from='answer, noise stop' if refine else 'answer')
            return _continue_on_check_model(result, run, check_model, check, answer_run,
                                            check_noise)
    shift = np.zeros(k)
    while (continue_by == 'shift' and not check['feasible_check'] and check['feasible_run']
           and check['continuations'] < continuations):
        # An engineer's correction of the same kind as the secant one: the constraints
        # shifted up by the offset the check measured at the answer.
        shift[:len(g_c)] += np.maximum(0.0, np.asarray(check['offset'], float))
        terms.shift = shift.copy()
        for key in list(evaluated):
            full = terms.values.get(key)
            if full is not None:
                evaluated[key] = np.r_[full[0], full[1] + shift]
        first = len(result.history)
        second, cancelled = _run_from_answer(result, run)
        terms.shift = None
        # the answer's values as the model gave them (the shift was the run's)
        for name in ('g', 'g_best'):
            if name in second:
                second[name] = np.asarray(second[name], float) - shift
        if 'g_best' in second:
            second.update(max_violation_best=float(max(0.0, np.max(second.g_best))))
        result = second
        check.update(continued=True, continuations=check['continuations'] + 1,
                     shift=shift.tolist(), first_iteration=check.get('first_iteration',
                                                                     first))
        if cancelled or 'x_best' not in result:
            break
        x_best = np.asarray(result.x_best, float)
        f_c, g_c, _ = checked(x_best)
        check.update(check_summary(np.asarray(result.g_best, float)[:len(g_c)], g_c, f_c,
                                   check_gtol), x_checked=x_best.tolist())
    return result, check


def _noise_limited(result: OptimizeResult, run: _Run,
                   check_noise: tuple[float, float] | None) -> bool:
    """True when the noise test ended the run on a model noisier in f than the check's.

    The noise test passes steps whose predicted change of f is within twice the run's
    f noise: on the built-in variable-step model 1.3 % of the ride objective, more than
    the accuracy an engineer asks of the answer; the check's model resolves 45 times
    finer (config/optimiser.yaml ``noise_levels``).
    """
    if check_noise is None or str(result.get('stop_test', '')) != 'noise':
        return False
    return float(check_noise[0]) < float(run.options.get('noise_f', 0.0))


def _converged_elsewhere(result: OptimizeResult, run: _Run, last_gap: float) -> bool:
    """True when a stop test ended the run away from its answer.

    The run's last iterate is infeasible on its model (max g > ``gtol``) and the answer,
    its best feasible (or least violating) iterate, has an f more than ``last_gap``
    (relative) above it: the run converged where its model calls no design feasible,
    and its answer comes from elsewhere (on a noisy model, an early iterate).
    """
    if last_gap <= 0.0 or 'f' not in result or 'f_best' not in result:
        return False
    if str(result.get('stop_test', '')) in ('', 'maxiter', 'cancelled'):
        return False
    f_last = float(result.f)
    return (float(result.max_violation) > float(run.options['gtol'])
            and float(result.f_best) > f_last + last_gap * abs(f_last))


def _continue_from_last(result: OptimizeResult, run: _Run, check_model: FullModel,
                        check: dict[str, Any], last_run: FullEvaluation,
                        answer_run: FullEvaluation,
                        check_noise: tuple[float, float] | None
                        ) -> tuple[OptimizeResult, dict[str, Any]]:
    """Go on from the last iterate on the check model (the run converged elsewhere).

    ``last_run`` and ``answer_run`` are the check model's runs of the last iterate and
    of the answer (``check`` holds the answer's verdicts).  The continuation is
    :func:`_continue_on_check_model`'s from the last iterate; the answer stays when the
    check found it feasible and the continuation has nothing feasible below its f.
    """
    answer = {name: result[name] for name in
              ('x_best', 'f_best', 'g_best', 'h_best', 'best_iteration', 'best_feasible',
               'max_violation_best') if name in result}
    start = OptimizeResult(result)
    start.update(x_best=np.asarray(result.x, float).copy(), f_best=float(result.f),
                 g_best=np.asarray(result.g, float).copy())
    second, check = _continue_on_check_model(start, run, check_model, check, last_run,
                                             check_noise)
    first = check['first']
    f_answer = float(answer_run.f[0])
    better = (bool(second.get('best_feasible')) and 'f_best' in second
              and float(second.f_best) < f_answer)
    check.update(continued_from='last_iterate')
    if first['feasible_check'] and not better:
        k = len(answer_run.g[0])
        g_best = np.r_[np.asarray(answer_run.g[0], float),
                       np.asarray(answer['g_best'], float)[k:]]
        second.update(answer, f_best=f_answer, g_best=g_best,
                      max_violation_best=float(max(0.0, np.max(g_best))) if g_best.size
                      else 0.0)
        check.update({name: first[name] for name in
                      ('f_check', 'max_violation_check', 'feasible_check')},
                     x_checked=np.asarray(answer['x_best'], float).tolist(),
                     continued_from='last_iterate, answer kept')
    return second, check


def _continue_on_check_model(result: OptimizeResult, run: _Run, check_model: FullModel,
                             check: dict[str, Any], check_run: FullEvaluation,
                             check_noise: tuple[float, float] | None
                             ) -> tuple[OptimizeResult, dict[str, Any]]:
    """Go on from the answer on the check model (``continue_by`` 'tighter_model').

    The objective scenario's full runs go to ``check_model`` from here on
    (:meth:`_ConstraintTerms.continue_on`): the values of the run's model are forgotten
    (the continuation compares designs on one model), the check's run of the answer is
    the continuation's first evaluation (no new run), the secant correction starts
    afresh at the answer (what it learnt was the discrepancy to the other model, noise
    included) but for the columns of the variables the simplified models see poorly,
    which it keeps (``CorrectionOptions.carry_to_check``), and Dynamic-Q takes the check
    model's noise levels.  Extra constraints
    on other scenarios keep their models and values.  The answer is that model's: its
    verdict is the check's.
    """
    x_best = np.asarray(result.x_best, float)
    f_c, g_c = run.terms.continue_on(check_model, x_best, check_run,
                                     np.asarray(result.g_best, float))
    run.evaluated.clear()
    if run.correct:
        run.evaluated[x_best.tobytes()] = np.r_[f_c, g_c]
        if run.corrections[0] is not None and run.correction_options.carry_to_check:
            run = replace(run, carried_correction=run.corrections[0].jacobian.copy())
        run.corrections[0] = None
    if check_noise is not None:
        run = replace(run, options={**run.options, 'noise_f': float(check_noise[0]),
                                    'noise_g': float(check_noise[1])})
    first = len(result.history)
    second, cancelled = _run_from_answer(result, run)
    # as the run itself does: after a restarting stop test, once more from the answer
    second, cancelled, after = _restart_after_stop(second, cancelled, run)
    _note_restarts(second, list(result.get('restarted_after', ())) + after)
    check.update(continued=True, continuations=1, first_iteration=first)
    if 'x_best' in second:
        # the answer's g is the check model's own: its verdict, on both sides
        g_best = np.asarray(second.g_best, float)[:len(check_run.g[0])]
        verdict = check_summary(g_best, g_best, float(second.f_best), check['check_gtol'])
        check.update({name: verdict[name] for name in
                      ('f_check', 'max_violation_check', 'feasible_check')},
                     x_checked=np.asarray(second.x_best, float).tolist(), offset=[])
    return second, check


def _finish(result: OptimizeResult, request: TuningRequest, terms: _ConstraintTerms,
            counter: RunCounter, correction: SecantCorrection | None,
            check: dict[str, Any] | None) -> OptimizeResult:
    """The result's counts, constraints, metrics and correction summary."""
    n = request.n_vars
    for rec in result.history:  # records the loop above did not see (several in one tell)
        metrics = terms.metrics.get(np.asarray(rec['x'], float).tobytes())
        if metrics is not None and 'metrics' not in rec:
            rec['metrics'] = metrics
    k = len(request.constraints)

    def constraint_values(g: ArrayLike) -> list[float]:
        extra = np.asarray(g, float)[len(g) - k:] if k else np.zeros(0)
        return [float(v + c.upper_bound) for v, c in zip(extra, request.constraints)]

    result.update(counter.as_dict(), scenario=request.scenario, n_vars=n,
                  gradient_source=request.gradient_source,
                  constraints=[c.as_dict() for c in request.constraints],
                  constraint_values=constraint_values(result.g) if 'g' in result else [],
                  constraint_gradient_sources=request.constraint_gradient_sources())
    if 'g_best' in result:
        result.update(constraint_values_best=constraint_values(result.g_best))
        best = next((r for r in result.history if r['iteration'] == result.best_iteration), {})
        metrics = best.get('metrics') or terms.metrics.get(
            np.asarray(result.x_best, float).tobytes())
        if metrics is not None:
            result.update(metrics_best=dict(metrics))
    if correction is not None:
        summary = correction.summary()
    else:
        summary = {'method': 'none'}
        if request.scenario in request.correction['off_for_scenarios']:
            summary['off_for_scenario'] = request.scenario
    result.update(correction=summary)
    if check is not None:
        result.update(check=check)
    return result


def noise_levels(scenario: str, integrator: str = '') -> tuple[float, float]:
    """Noise levels (f, g) of the built-in full model (config/optimiser.yaml
    ``noise_levels``); (0, 0) for a scenario or integrator without an entry.
    """  # noqa: D205
    from suspension_tuning.paths import config_dir, read_yaml

    if not integrator:
        from suspension_tuning.vehicle.params import load_vehicle_params

        integrator = load_vehicle_params().integrator.method
    levels = read_yaml(config_dir() / 'optimiser.yaml').get('noise_levels', {})
    entry = levels.get(scenario, {}).get(integrator)
    if not entry:
        return 0.0, 0.0
    return float(entry['f']), float(entry['g'])


def with_noise_levels(options: Mapping[str, Any] | None, scenario: str,
                      integrator: str = '') -> dict[str, Any]:
    """Dynamic-Q options with ``noise_f`` and ``noise_g`` of the model filled in.

    Options that set either to a positive value keep theirs; else (unset or both 0,
    the defaults) :func:`noise_levels` gives them.
    """
    out = DynamicQOptions.from_mapping(options).as_dict()
    if out['noise_f'] <= 0.0 and out['noise_g'] <= 0.0:
        out['noise_f'], out['noise_g'] = noise_levels(scenario, integrator)
    return out


def blind_columns(jacobian: Array) -> Array:
    """Variables no simplified model sees: columns of ``jacobian`` zero in every row.

    (A bar in the pitch-plane model, docs/design_space.md.)
    """
    return np.flatnonzero(np.all(np.asarray(jacobian, float) == 0.0, axis=0))


def seed_columns(correction: SecantCorrection, terms: _ConstraintTerms, x: Array,
                 full: Array, values: Array, jacobian: Array, columns: ArrayLike,
                 step: float, lower: Array, upper: Array, central: bool = False) -> None:
    """Set the correction's ``columns`` from the full model's differences along them.

    One-sided (``central`` False): one full run per variable j at ``x + step e_j``
    (``- step`` where that leaves the box).  Central: two, at ``x +- step e_j``, where
    both lie in the box (else one-sided): its error is O(step^2), which matters where
    the slope is near zero (a variable near its own optimum, where a one-sided step of
    0.1 on a curvature of 2 errs by 0.1).  Every run is counted as a full run of the
    optimisation.  Each column becomes the full model's difference less the simplified
    slope ``jacobian[:, j]`` (zero for a blind variable, :func:`blind_columns`).
    """
    columns = np.asarray(columns, dtype=int).reshape(-1)
    if columns.size == 0:
        return
    up = x[columns] + step <= upper[columns]
    both = up & (x[columns] - step >= lower[columns]) & bool(central)
    steps = np.where(up, step, -step)
    points = np.repeat(x[None, :], columns.size + int(both.sum()), axis=0)
    points[np.arange(columns.size), columns] += steps
    points[columns.size + np.arange(int(both.sum())), columns[both]] -= step
    stepped = terms.stacked_values(points)
    # each difference's far end is x + h; its near end x (span h) or x - h (span 2h)
    near = np.repeat(np.asarray(full, float)[None, :], columns.size, axis=0)
    near[both] = stepped[columns.size:]
    spans = np.where(both, 2.0 * steps, steps)
    slopes = np.asarray(jacobian, float)
    for row, j in enumerate(columns):
        correction.seed_column(int(j), x, float(spans[row]), near[row], stepped[row],
                               values, slopes[:, j])


def verify_bounds(correction: SecantCorrection, terms: _ConstraintTerms, x: Array,
                  full: Array, values: Array, raw: Array, corrected: Array, step: float,
                  lower: Array, upper: Array,
                  verified: dict[tuple[int, int], tuple[Array, float, Array, Array]]
                  ) -> bool:
    """Check with a full run each bound that the correction alone decides.

    A variable on a bound whose simplified objective slope points inward while the
    corrected one points outward (the correction reversed it) gets one full run at
    ``x + step`` inward, which sets its correction column from the full model
    (:mod:`suspension_tuning.optim.correction` module notes).  ``verified`` keeps each
    variable's and bound's last check (design, step, full values at both ends): less
    than ``step`` from there, the column is set again from it without a new run (the
    secant updates of later steps may have reversed it again).  The new runs are
    counted as full runs of the optimisation.

    Returns
    -------
    bool
        Whether a column was set (the corrected Jacobian is then to be rebuilt).
    """
    tol = 1e-9
    flips = []
    for j in range(x.size):
        if x[j] <= lower[j] + tol and raw[0, j] < 0.0 < corrected[0, j]:
            flips.append((j, 1))
        elif x[j] >= upper[j] - tol and raw[0, j] > 0.0 > corrected[0, j]:
            flips.append((j, -1))
    if not flips:
        return False
    known = [key for key in flips if key in verified
             and np.linalg.norm(x - verified[key][0]) < step]
    new = [key for key in flips if key not in known]
    for j, side in known:
        x_v, h, full_v, stepped_v = verified[j, side]
        correction.seed_column(j, x, h, full_v, stepped_v, values, raw[:, j])
    if new:
        points = np.repeat(x[None, :], len(new), axis=0)
        steps = [side * min(step, float(upper[j] - lower[j])) for j, side in new]
        for row, ((j, _), h) in enumerate(zip(new, steps)):
            points[row, j] += h
        stepped = terms.stacked_values(points)
        for row, ((j, side), h) in enumerate(zip(new, steps)):
            correction.seed_column(j, x, h, full, stepped[row], values, raw[:, j])
            verified[j, side] = (x.copy(), h, np.asarray(full, float).copy(),
                                 np.asarray(stepped[row], float).copy())
    return True


class _ConstraintTerms:
    """The objective's scenario plus the extra constraints' scenarios at one design.

    Runs every scenario the constraints need once per evaluation (one full run each),
    keeps the full model's inputs per scenario for the simplified models, and builds
    the gradients: simplified-model rows where a term has a simplified model, one
    batch of 2n full-model central-difference runs per scenario for the others.
    """

    def __init__(self, request: TuningRequest, full_model: FullModel,
                 simplified_gradient: SimplifiedGradient | None,
                 models: Mapping[str, FullModel] | None,
                 gradients: Mapping[str, SimplifiedGradient] | None,
                 counter: RunCounter) -> None:
        self.request = request
        self.counter = counter
        self.models: dict[str, FullModel] = {request.scenario: full_model}
        self.gradients: dict[str, SimplifiedGradient | None] = {
            request.scenario: simplified_gradient}
        for name in request.constraint_scenarios:
            model = (models or {}).get(name)
            if model is None:
                raise ValueError(f'a constraint on scenario {name!r} needs its full model '
                                 f'(constraint_models[{name!r}])')
            self.models[name] = model
        sources = request.constraint_gradient_sources()
        for spec, source in zip(request.constraints, sources):
            if source == 'simplified' and spec.scenario not in self.gradients:
                gradient = (gradients or {}).get(spec.scenario)
                if gradient is None:
                    raise ValueError(f'the constraint {spec.label} needs the simplified '
                                     f'gradient of {spec.scenario!r} '
                                     f'(constraint_gradients[{spec.scenario!r}])')
                self.gradients[spec.scenario] = gradient
        self.sources = sources
        self.inputs: dict[str, Any] = {}
        #: Named metrics of the objective scenario's run at each evaluated design (keyed
        #: by x's bytes), when its full model returns them.
        self.metrics: dict[bytes, dict[str, float]] = {}
        #: Full-model (f, g) at each evaluated design, unshifted (keyed by x's bytes).
        self.values: dict[bytes, tuple[float, Array]] = {}
        self._inputs_at: dict[bytes, dict[str, Any]] = {}
        #: Shift added to g (the check's continuation), or None.
        self.shift: Array | None = None

    def _run(self, scenario: str, points: Array) -> FullEvaluation:
        evaluation = self.models[scenario](points)
        self.counter.full_runs += len(points)
        return evaluation

    def _constraint_values(self, runs: Mapping[str, FullEvaluation]) -> Array:
        columns = [spec.values(runs[spec.scenario]) - spec.upper_bound
                   for spec in self.request.constraints]
        m = len(runs[self.request.scenario].f)
        return np.column_stack(columns) if columns else np.zeros((m, 0))

    def evaluate(self, x: Array) -> tuple[float, Array]:
        """Objective and all constraints at x, plus the shift (one full run per scenario).

        A design run before is answered from its values (no run): the continuation
        after the check starts at the reported design.
        """
        f, g = self.evaluate_cached(x)
        return f, g if self.shift is None else g + self.shift

    def evaluate_cached(self, x: Array) -> tuple[float, Array]:
        """Unshifted objective and constraints at x (a run only for a new design)."""
        key = np.asarray(x, float).tobytes()
        if key not in self.values:
            self.values[key] = self._evaluate(x)
            self._inputs_at[key] = dict(self.inputs)
        else:  # the simplified models' inputs of that design's runs (handling)
            self.inputs.update(self._inputs_at[key])
        f, g = self.values[key]
        return f, g.copy()

    def _evaluate(self, x: Array) -> tuple[float, Array]:
        runs = {name: self._run(name, x[None, :]) for name in self.models}
        for name, run in runs.items():
            self.inputs[name] = run.inputs
        primary = runs[self.request.scenario]
        self._keep_metrics(x, primary)
        g = np.concatenate([np.asarray(primary.g[0], float), self._constraint_values(runs)[0]])
        return float(primary.f[0]), g

    def _keep_metrics(self, x: Array, run: FullEvaluation) -> None:
        """The named metrics of the objective scenario's run of x, when it gave any."""
        if run.metrics is not None and len(run.metric_names):
            self.metrics[np.asarray(x, float).tobytes()] = {
                str(name): float(value)
                for name, value in zip(run.metric_names, np.asarray(run.metrics)[0])}

    def continue_on(self, model: FullModel, x: Array, run: FullEvaluation,
                    g_reported: Array) -> tuple[float, Array]:
        """Run the objective scenario on ``model`` from here on, ``run`` its run of x.

        Every value of the old model is forgotten; x's are ``run``'s f and eq. 11 g,
        then the extra constraints' as evaluated before (``g_reported`` when x was not
        run here: a resumed answer).  Returns x's (f, g).
        """
        key = np.asarray(x, float).tobytes()
        own = self.values.get(key)
        k = np.asarray(run.g, float).shape[1]
        extra = np.asarray(own[1] if own is not None else g_reported, float)[k:]
        self.models[self.request.scenario] = model
        self.values.clear()
        self._inputs_at.clear()
        f, g = float(run.f[0]), np.r_[np.asarray(run.g[0], float), extra]
        self.values[key] = (f, g)
        self._inputs_at[key] = {**self.inputs, self.request.scenario: run.inputs}
        self._keep_metrics(x, run)
        return f, g.copy()

    def stacked_values(self, points: Array) -> Array:
        """Columns f, g (eq. 11 then extra) of every point (full model, every scenario)."""
        runs = {name: self._run(name, points) for name in self.models}
        primary = runs[self.request.scenario]
        return np.column_stack([primary.f, primary.g, self._constraint_values(runs)])

    def _inputs(self, scenario: str, x: Array) -> Any:
        if self.inputs.get(scenario) is None and scenario in INPUT_SCENARIOS:
            # Resumed from a history: the simplified handling model needs the full
            # model's steering and slip angles at x (paper 6.1), so run it once.
            self.inputs[scenario] = self._run(scenario, x[None, :]).inputs
        return self.inputs.get(scenario)

    def _simplified(self, scenario: str, x: Array) -> tuple[Array, Array, Array | None]:
        gradient = self.gradients[scenario]
        assert gradient is not None
        df, dg, *rest = gradient(x, self._inputs(scenario, x))
        values = np.asarray(rest[0], float) if rest and rest[0] is not None else None
        self.counter.simplified_runs += 2 * self.request.n_vars + (values is not None)
        return np.asarray(df, float), np.asarray(dg, float), values

    def simplified_gradient(self, x: Array, lower: Array, upper: Array
                            ) -> tuple[Array, Array, Array | None]:
        """Gradient of f and Jacobian of g: simplified rows where possible, else full.

        Also the scaled simplified values at x in the same rows (f, then g), NaN in the
        rows from full-model central differences; None when a simplified source gave
        no values.
        """
        request = self.request
        simplified = {request.scenario: self._simplified(request.scenario, x)}
        df, dg, primary_values = simplified[request.scenario]
        rows: list[Array | None] = []
        row_values: list[float] = []
        for spec, source in zip(request.constraints, self.sources):
            if source == 'simplified':
                if spec.scenario not in simplified:
                    simplified[spec.scenario] = self._simplified(spec.scenario, x)
                sdf, sdg, svalues = simplified[spec.scenario]
                rows.append(spec.derivative(sdf, sdg))
                row_values.append(math.nan if svalues is None else
                                  spec.simplified_value(svalues) - spec.upper_bound)
            else:
                rows.append(None)
                row_values.append(math.nan)
        full_terms = [i for i, row in enumerate(rows) if row is None]
        by_scenario: dict[str, list[int]] = {}
        for i in full_terms:
            by_scenario.setdefault(request.constraints[i].scenario, []).append(i)
        for scenario, indices in by_scenario.items():
            specs = [request.constraints[i] for i in indices]

            def values(points: Array, scenario: str = scenario,
                       specs: list[ConstraintSpec] = specs) -> Array:
                run = self._run(scenario, points)
                return np.column_stack([spec.values(run) for spec in specs])

            jac = central_difference(values, x, request.fd_step, lower, upper)
            for i, row in zip(indices, jac):
                rows[i] = row
        extra = np.array(rows, dtype=float).reshape(len(rows), request.n_vars)
        values = None
        if all(v[2] is not None for v in simplified.values()):
            values = np.r_[primary_values, row_values]
        return df, np.vstack([np.asarray(dg, float).reshape(-1, request.n_vars), extra]), values


# ---------------------------------------------------------------------------------------
# A set of operating conditions (suspension_tuning.conditions) in one optimisation.

#: Full model over conditions: (designs (m, n), conditions) -> one FullEvaluation per
#: condition, in the conditions' order; all m x C runs may go out as one batch.
ConditionModel = Callable[[Array, Sequence[Any]], list[FullEvaluation]]


def combined_objective(f_conditions: ArrayLike, weights: ArrayLike, form: str) -> float:
    """The objective over a condition set: the worst (max) or the weighted mean of f_c."""
    f = np.asarray(f_conditions, float)
    return float(np.max(f)) if form == 'worst' else float(np.dot(np.asarray(weights), f))


class _ConditionTerms:
    """Full runs per condition at each design (one batch of all conditions), cached."""

    def __init__(self, model: ConditionModel, conditions: Sequence[Any],
                 counter: RunCounter) -> None:
        self.model = model
        self.conditions = list(conditions)
        self.counter = counter
        #: x's bytes -> (f_c (C,), g_c (C, 4), metrics per condition)
        self.values: dict[bytes, tuple[Array, Array, list[dict[str, float]]]] = {}
        #: x's bytes -> the simplified models' inputs of x's run in each condition
        self.inputs: dict[bytes, list[Any]] = {}

    def batch(self, points: Array) -> tuple[Array, Array, list[list[dict[str, float]]]]:
        """f (m, C), g (m, C, k) and metrics [m][C] of designs, one batch of m x C runs."""
        points = np.atleast_2d(np.asarray(points, float))
        runs = self.model(points, self.conditions)
        self.counter.full_runs += len(points) * len(self.conditions)
        if len(points) == 1:  # one design: its runs' inputs (handling's simplified model)
            self.inputs[points[0].tobytes()] = [r.inputs for r in runs]
        f = np.column_stack([np.asarray(r.f, float) for r in runs])
        g = np.stack([np.asarray(r.g, float).reshape(len(points), -1) for r in runs], axis=1)
        metrics = [[{str(k): float(v) for k, v in zip(r.metric_names, np.asarray(r.metrics)[i])}
                    if r.metrics is not None else {} for r in runs]
                   for i in range(len(points))]
        return f, g, metrics

    def at(self, x: Array) -> tuple[Array, Array, list[dict[str, float]]]:
        """Per-condition values of one design (runs only for a new design)."""
        key = np.asarray(x, float).tobytes()
        if key not in self.values:
            f, g, metrics = self.batch(np.asarray(x, float)[None, :])
            self.values[key] = (f[0], g[0], metrics[0])
        return self.values[key]

    def inputs_at(self, x: Array) -> list[Any]:
        """The simplified models' inputs of x's run in each condition (None each: none)."""
        self.at(x)
        return self.inputs.get(np.asarray(x, float).tobytes(), [None] * len(self.conditions))


def condition_constraint_values(specs: Sequence[ConstraintSpec], f_c: ArrayLike,
                                g_c: ArrayLike, metrics: Sequence[Mapping[str, float]]
                                ) -> Array:
    """Each extra ride constraint's quantity in each condition, (S, C), its units.

    ``f_c`` (C,), ``g_c`` (C, 4) and ``metrics`` (one dict per condition) are a
    design's full runs in the conditions (:class:`_ConditionTerms`).
    """
    f_c, g_c = np.asarray(f_c, float), np.asarray(g_c, float).reshape(len(metrics), -1)
    rows = []
    for spec in specs:
        if spec.quantity == 'f':
            rows.append(f_c)
        elif spec.quantity in TYRE_HOP_NAMES:
            rows.append(g_c[:, TYRE_HOP_NAMES.index(spec.quantity)])
        else:
            missing = [c for c, values in enumerate(metrics) if spec.quantity not in values]
            if missing:
                raise ValueError(f'constraint {spec.label}: the ride full model returned no '
                                 f'metric {spec.quantity!r}')
            rows.append(np.array([float(values[spec.quantity]) for values in metrics]))
    return np.asarray(rows, float).reshape(len(specs), len(metrics))


def optimise_conditions(request: TuningRequest, model: ConditionModel,
                        gradients: Mapping[str, SimplifiedGradient] | None = None,
                        callback: Callable[[dict[str, Any], RunCounter], bool | None]
                        | None = None,
                        counter: RunCounter | None = None,
                        check_model: ConditionModel | None = None,
                        check_gtol: float = 5e-3,
                        check_continuations: int = 0) -> OptimizeResult:
    """Dynamic-Q over a set of operating conditions (``request.condition_set``).

    The objective is the weighted mean of the per-condition objectives (form 'mean') or
    the worst of them (form 'worst'), posed in epigraph form for Dynamic-Q: one extra
    variable t, minimise t subject to ``f_c(x) - t <= 0`` for every condition c, so
    that the subproblems stay smooth (a max of functions has kinks where two cross).
    The eq. 11 tyre-hop constraints hold in every condition (4 per condition), and so
    does each extra constraint (``request.constraints``, ride quantities): one row
    ``value_c - bound`` per constraint and condition, after the tyre-hop rows.  An
    extra constraint on the objective or a tyre-hop constraint takes its gradient from
    the condition's (corrected) simplified gradient; one on a metric from central
    differences of the full model in every condition (one batch of 2n designs x C).

    Parameters
    ----------
    request : TuningRequest
        The ride or handling scenario with ``conditions`` set.
    model : callable
        ``(designs (m, n), conditions) -> [FullEvaluation per condition]``: the full
        model of every design in every condition; the m x C runs of one call may go out
        as one batch over a pool of workers.
    gradients : mapping, optional
        Condition name -> the scaled simplified gradient in that condition
        (``(x, inputs) -> (df, dg, values)``, calibrated for that condition); required
        for gradient source 'simplified'.  Each condition's gradients are corrected by
        a secant correction of its own (:mod:`suspension_tuning.optim.correction`)
        from its full run at each iterate.
    callback : callable, optional
        Called with each iteration's record (x the design, f the combined objective,
        g the tyre-hop constraints of every condition, ``condition_f``) and the run
        counter; returning True stops the run.
    counter : RunCounter, optional
        Counter to continue (e.g. one holding the calibration runs).
    check_model : callable, optional
        The full model over conditions at a tighter solver tolerance
        (:func:`suspension_tuning.answer_check.check_condition_options`): the reported
        design runs once more in every condition (C paid full runs), and ``check``
        holds both verdicts (max g <= ``check_gtol`` at the check), the combined
        objective and each condition's f and largest g at the check.  An answer
        feasible on the run's model and infeasible at the check is continued, as
        :func:`optimise` does for one condition, with every g row shifted up by the
        offset the check measured there (at most ``check_continuations`` times); the
        continued run's answer is the best by its shifted constraints, checked again.

    Returns
    -------
    scipy.optimize.OptimizeResult
        As :func:`optimise` (``x_best``, ``f_best`` the combined objective, ``g_best``
        the 4 C tyre-hop constraints, ``best_iteration``, ``best_feasible``...), plus
        ``condition_names``, ``condition_form``, ``condition_f_best`` (C,),
        ``condition_g_best`` (C, 4), ``condition_metrics_best`` (one dict per condition)
        and ``worst_condition`` (the condition with the largest f at the reported
        design).  ``constraint_values`` (and ``_best``) hold each extra constraint's
        largest value over the conditions; ``condition_constraint_values_best`` all of
        them, (S, C).  Full runs count condition-runs (a design in C conditions is C runs);
        ``rounds`` counts the batches of full runs (one per evaluated design, 2n per
        full-model gradient: the wall time with C workers).
    """
    from suspension_tuning.reported_design import best_record

    conditions = request.condition_set
    if conditions is None:
        raise ValueError('optimise_conditions needs a request with conditions')
    if request.gradient_source == 'simplified':
        missing = [name for name in conditions.names if name not in (gradients or {})]
        if missing:
            raise ValueError(f"gradient source 'simplified' needs the simplified gradient of "
                             f"every condition; missing: {', '.join(missing)}")
    counter = counter or RunCounter()
    terms = _ConditionTerms(model, conditions.conditions, counter)
    n, n_c = request.n_vars, len(conditions)
    weights = np.asarray(conditions.weights)
    worst = request.condition_form == 'worst'
    lower, upper = np.full(n, X_LOWER), np.full(n, X_UPPER)
    rounds = [0]
    x0 = request.start
    start = x0
    if worst:  # t starts at the worst condition's objective at x0 (that batch is x0's run)
        f0 = terms.at(x0)[0]
        rounds[0] += 1
        spread = float(np.ptp(f0)) + 1.0
        lower = np.r_[lower, float(np.min(f0)) - spread]
        upper = np.r_[upper, float(np.max(f0)) + spread]
        start = np.r_[x0, float(np.max(f0))]
    options = DynamicQOptions.from_mapping(request.options).as_dict()
    gtol = float(options['gtol'])
    specs = list(request.constraints)
    bounds = np.array([spec.upper_bound for spec in specs], float).reshape(-1, 1)
    # per extra constraint: from the simplified gradient, or full central differences
    by_simplified = [request.gradient_source == 'simplified' and spec.has_simplified_model
                     for spec in specs]
    staircase = (([False] * n_c if worst else []) + [True] * (4 * n_c)
                 + [spec.quantity in TYRE_HOP_NAMES for spec in specs for _ in range(n_c)])
    correction_options = CorrectionOptions.from_mapping(request.correction)
    correct = (request.gradient_source == 'simplified'
               and correction_options.applies_to(request.scenario))
    corrections: dict[str, SecantCorrection] = {}
    records: list[dict[str, Any]] = []
    #: added to the g rows (tyre hop, extra constraints) after a check found the answer
    #: infeasible at the tighter tolerance (the offset it measured there)
    shift = np.zeros(4 * n_c + len(specs) * n_c)

    def problem_values(z: Array) -> tuple[float, Array]:
        x = z[:n]
        known = np.asarray(x, float).tobytes() in terms.values
        f_c, g_c, metrics = terms.at(x)
        rounds[0] += 0 if known else 1
        g_all = np.r_[g_c.reshape(-1), extra_g(f_c, g_c, metrics)] + shift
        if worst:
            return float(z[n]), np.r_[f_c - z[n], g_all]
        return float(np.dot(weights, f_c)), g_all

    def extra_g(f_c: Array, g_c: Array, metrics: list[dict[str, float]]) -> Array:
        """value - bound of every extra constraint in every condition (constraint-major)."""
        if not specs:
            return np.zeros(0)
        return (condition_constraint_values(specs, f_c, g_c, metrics) - bounds).reshape(-1)

    def full_jacobian(x: Array) -> Array:
        """Central differences of f (C), g (4 C) and the extra rows (S C): one batch."""
        def values(points: Array) -> Array:
            f, g, metrics = terms.batch(points)
            rounds[0] += 1
            return np.column_stack([f, g.reshape(len(points), -1), np.array(
                [extra_g(f[i], g[i], metrics[i]) for i in range(len(points))]
            ).reshape(len(points), -1)])

        return central_difference(values, x, request.fd_step, lower[:n], upper[:n])

    def problem_gradient(z: Array) -> tuple[Array, Array]:
        x = z[:n]
        if request.gradient_source == 'full':
            jac = full_jacobian(x)
            df_c, dg_c = jac[:n_c], jac[n_c:5 * n_c].reshape(n_c, -1, n)
            d_extra = jac[5 * n_c:]
        else:
            f_c, g_c, _ = terms.at(x)
            inputs = terms.inputs_at(x)
            rows_f, rows_g = [], []
            for c, condition in enumerate(conditions.conditions):
                df, dg, *rest = gradients[condition.name](x, inputs[c])
                values = np.asarray(rest[0], float) if rest and rest[0] is not None else None
                counter.simplified_runs += 2 * n + (values is not None)
                jac = np.vstack([np.asarray(df, float), np.asarray(dg, float)])
                if correct and values is not None:
                    corr = corrections.get(condition.name)
                    if corr is None:
                        corr = corrections[condition.name] = SecantCorrection(
                            jac.shape[0], n, correction_options.min_step)
                    corr.observe(x, np.r_[f_c[c], g_c[c]], values)
                    jac = corr.correct(jac)
                rows_f.append(jac[0])
                rows_g.append(jac[1:])
            df_c, dg_c = np.asarray(rows_f), np.asarray(rows_g)
            d_extra = np.zeros((len(specs) * n_c, n))
            if specs and not all(by_simplified):
                d_extra = full_jacobian(x)[5 * n_c:]
            for k, spec in enumerate(specs):
                if by_simplified[k]:
                    d_extra[k * n_c:(k + 1) * n_c] = [
                        spec.derivative(df_c[c], dg_c[c]) for c in range(n_c)]
        dg_rows = np.vstack([dg_c.reshape(-1, n), d_extra])
        if worst:
            df = np.r_[np.zeros(n), 1.0]
            dg = np.vstack([np.column_stack([df_c, -np.ones(n_c)]),
                            np.column_stack([dg_rows, np.zeros(len(dg_rows))])])
            return df, dg
        return weights @ df_c, dg_rows

    def drive(start_z: Array) -> tuple[OptimizeResult, bool]:
        """One Dynamic-Q run from ``start_z`` on the g rows + ``shift``; records appended."""
        opt = DynamicQ(start_z, lower, upper, options, gradient_source=request.gradient_source,
                       surrogate_rule_constraints=lambda m: staircase[:m] + [True] * (
                           m - len(staircase)))
        first = len(records)
        while (ask := opt.ask()) is not None:
            kind, z = ask
            try:
                if kind == 'evaluate':
                    f, g = problem_values(z)
                    record = opt.tell((f, g, None))
                else:
                    df, dg = problem_gradient(z)
                    record = opt.tell((df, dg, None), source=request.gradient_source)
            except RunCancelled:
                opt.stop('cancelled')
                return opt.result(), True
            if record is None:
                continue
            x = np.asarray(record['x'], float)[:n]
            f_c, g_c, metrics = terms.at(x)
            g_all = np.r_[g_c.reshape(-1), extra_g(f_c, g_c, metrics)]
            out = {'iteration': first + int(record['iteration']), 'x': x,
                   'f': combined_objective(f_c, weights, request.condition_form),
                   'g': g_all, 'rho': record['rho'], 'rho_next': record['rho_next'],
                   'max_violation': float(max(0.0, np.max(g_all))),
                   'condition_f': f_c.tolist(), 'condition_metrics': metrics}
            if worst:
                out['epigraph_t'] = float(record['x'][n])
            if shift.any():
                out['shift'] = shift.tolist()
            records.append(out)
            if callback is not None and callback(out, counter):
                opt.stop('cancelled')
                return opt.result(), True
        return opt.result(), False

    def start_at(x: Array) -> Array:
        """Dynamic-Q's start for design x (in the worst form with t = its largest f_c)."""
        return np.r_[x, float(np.max(terms.at(x)[0]))] if worst else np.asarray(x, float)

    result, cancelled = drive(start)
    nit = int(result.nit)

    def worst_values(x: Array) -> tuple[list[float], Array]:
        """Each extra constraint's largest value over the conditions, and all (S, C)."""
        key = np.asarray(x, float)[:n].tobytes()
        if not specs or key not in terms.values:  # no run of x: nothing to say
            return [], np.zeros((0, n_c))
        values = condition_constraint_values(specs, *terms.values[key])
        return values.max(axis=1).tolist(), values

    def best_of(first: int) -> tuple[int, bool] | None:
        """The run's answer among the records from ``first`` on, by their shifted g."""
        chosen = [dict(rec, g=np.asarray(rec['g'], float) + np.asarray(
                      rec.get('shift', np.zeros_like(shift)), float)) for rec in records[first:]]
        for rec in chosen:
            rec['max_violation'] = float(max(0.0, np.max(rec['g'])))
        best = best_record(chosen, gtol)
        return None if best is None else (first + best[0], best[1])

    def checked(x: Array, g_run: Array) -> dict[str, Any]:
        """The check of design x in every condition (C paid full runs)."""
        runs = check_model(np.asarray(x, float)[None, :], conditions.conditions)
        counter.full_runs += n_c
        f_chk = np.array([float(r.f[0]) for r in runs])
        g_chk = np.array([np.asarray(r.g, float).reshape(-1)[:4] for r in runs])
        m_chk = [{str(k): float(v) for k, v in zip(r.metric_names, np.asarray(r.metrics)[0])}
                 if r.metrics is not None else {} for r in runs]
        g_check = np.r_[g_chk.reshape(-1), extra_g(f_chk, g_chk, m_chk)]
        out = check_summary(g_run, g_check, combined_objective(
            f_chk, weights, request.condition_form), check_gtol)
        out.update(x_checked=np.asarray(x, float).tolist(), condition_f_check=f_chk.tolist(),
                   condition_max_g_check=[float(np.max(row))
                                          for row in g_check[:4 * n_c].reshape(n_c, 4)])
        return out

    after: list[str] = []
    # As in optimise: a run whose corrections learnt from its full runs and that ended by
    # a restarting stop test starts again from its answer (best_of), the
    # corrections afresh there, Dynamic-Q with its first move limit.
    while (corrections and not cancelled
           and correction_options.restarts_after(result.get('stop_test'), len(after))):
        found = best_of(0)
        if found is None:
            break
        after.append(str(result['stop_test']))
        corrections.clear()
        result, cancelled = drive(start_at(np.asarray(records[found[0]]['x'], float)))
        nit += int(result.nit)
    best = best_of(0)
    check: dict[str, Any] | None = None
    if best is not None and check_model is not None and not cancelled:
        rec = records[best[0]]
        check = checked(rec['x'], np.asarray(rec['g'], float))
        check.update(continued=False, continuations=0, first=dict(check),
                     check_gtol=check_gtol, condition_names=conditions.names)
        # An infeasible answer at the tighter tolerance: Dynamic-Q goes on from it with
        # the g rows shifted up by the offset the check measured there (accumulated), as
        # optimise does for one condition, and the new answer is checked again.
        while (not check['feasible_check'] and check['feasible_run']
               and check['continuations'] < check_continuations and not cancelled):
            shift += np.maximum(0.0, np.asarray(check['offset'], float))
            first = len(records)
            result, cancelled = drive(start_at(np.asarray(records[best[0]]['x'], float)))
            nit += int(result.nit)
            check.update(continued=True, continuations=check['continuations'] + 1,
                         shift=shift.tolist(), first_iteration=first)
            found = best_of(first)
            if found is None or cancelled:
                break
            best = found
            rec = records[best[0]]
            check.update(checked(rec['x'], np.asarray(rec['g'], float)))
        if not check['feasible_check'] and not check['continued']:
            check['not_continued'] = ('no continuation with shifted constraints left '
                                      f'(check_continuations {check_continuations})')

    last = np.asarray(result.x, float)[:n]
    result.update(counter.as_dict(), scenario=request.scenario, n_vars=n,
                  gradient_source=request.gradient_source,
                  constraints=[spec.as_dict() for spec in specs],
                  constraint_values=worst_values(last)[0],
                  constraint_gradient_sources=['simplified' if simplified else 'full'
                                               for simplified in by_simplified],
                  condition_names=conditions.names, condition_form=request.condition_form,
                  conditions=conditions.as_dict(), history=records, rounds=rounds[0],
                  x=last, cancelled=cancelled, nit=nit,
                  correction={name: c.summary() for name, c in corrections.items()}
                  if corrections else {'method': 'none' if not correct else 'secant'})
    if best is not None:
        k, feasible = best
        rec = records[k]
        f_c, g_c, metrics = terms.at(rec['x'])
        result.update(x_best=np.asarray(rec['x'], float), f_best=float(rec['f']),
                      g_best=np.asarray(rec['g'], float), best_iteration=rec['iteration'],
                      best_feasible=feasible, max_violation_best=rec['max_violation'],
                      constraint_values_best=worst_values(rec['x'])[0],
                      condition_constraint_values_best=worst_values(rec['x'])[1].tolist(),
                      condition_f_best=f_c.tolist(),
                      condition_g_best=g_c.tolist(), condition_metrics_best=metrics,
                      worst_condition=conditions.names[int(np.argmax(f_c))])
    _note_restarts(result, after)
    if check is not None:
        result.update(check=check)
    return result


def condition_values(model: ConditionModel, x: ArrayLike, conditions: Sequence[Any]
                     ) -> tuple[Array, list[dict[str, float]]]:
    """f per condition (C,) and the metrics per condition of one design (C runs)."""
    terms = _ConditionTerms(model, conditions, RunCounter())
    f_c, _, metrics = terms.at(np.asarray(x, float))
    return f_c, metrics
