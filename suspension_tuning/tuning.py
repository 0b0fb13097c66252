"""The paper's optimisation loop, independent of where models run (no rclpy).

Thoresson et al. (2009), section 2: Dynamic-Q asks for the objective and the
constraints at each iterate, which always come from the full vehicle model (one run
per iteration), and for their gradients, which come either from central differences
on the full model (2n full runs per iteration) or from central differences on the
eq. 25-scaled simplified models (2n cheap runs, "0.2n + 1 function evaluations per
iteration").

:func:`optimise` drives :class:`~suspension_tuning.optim.dynamic_q.DynamicQ` with two
callables, so the same loop runs in-process (physics called directly) and in the ROS
coordinator (physics called through services on simulation workers and the gradient
evaluator).  It counts full-model and simplified-model runs in one place
(:class:`RunCounter`), like scipy's ``ScalarFunction`` counts ``nfev``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import OptimizeResult

from suspension_tuning.optim.dynamic_q import DynamicQ, DynamicQOptions
from suspension_tuning.optim.finite_diff import central_difference
from suspension_tuning.vehicle.design import (
    VARIABLE_NAMES,
    X_LOWER,
    X_UPPER,
    to_physical,
    validate_design,
)
from suspension_tuning.vehicle.params import INTEGRATORS

Array = NDArray[np.float64]

#: Gradient sources of the Optimise action.
GRADIENT_SOURCES = ('simplified', 'full')
#: Scenarios that can be optimised (the mixed scenario is a closed-loop check only).
OPTIMISATION_SCENARIOS = ('ride', 'handling')


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
    """

    f: Array
    g: Array
    inputs: Any = None


#: Full model on a batch: designs (m, n) -> FullEvaluation.
FullModel = Callable[[Array], FullEvaluation]
#: Scaled simplified-model gradient at x with the full model's inputs -> (df, dg).
SimplifiedGradient = Callable[[Array, Any], tuple[Array, Array]]


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
    integrator : str
        Full-model integrator: 'fixed_step', 'variable_step' or '' (the simulation's
        default, config/vehicle.yaml).
    """

    scenario: str
    n_vars: int
    x0: ArrayLike | None = None
    gradient_source: str = 'simplified'
    options: Mapping[str, Any] | None = None
    fd_step: float = 0.025
    integrator: str = ''
    start: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Validate every field; raise ValueError naming the problem."""
        if self.scenario not in OPTIMISATION_SCENARIOS:
            raise ValueError(f'unknown scenario {self.scenario!r}; '
                             f'valid: {", ".join(OPTIMISATION_SCENARIOS)}')
        if self.n_vars not in VARIABLE_NAMES:
            raise ValueError(f'n_vars must be 2 or 4, got {self.n_vars}')
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


def physical_settings(x: ArrayLike) -> dict[str, float]:
    """Physical 4S4 settings of one normalised design, units at the edge (litres).

    Parameters
    ----------
    x : array_like, shape (2,) or (4,)
        Normalised design (eqs. 4-8).

    Returns
    -------
    dict
        ``dpsf_front``, ``gas_volume_front_l``, ``dpsf_rear``, ``gas_volume_rear_l``.
    """
    axles = to_physical(np.asarray(x, dtype=float))
    return {'dpsf_front': float(axles.dpsf_front[0]),
            'gas_volume_front_l': float(axles.gas_volume_front_m3[0]) * 1e3,
            'dpsf_rear': float(axles.dpsf_rear[0]),
            'gas_volume_rear_l': float(axles.gas_volume_rear_m3[0]) * 1e3}


def centre(n_vars: int) -> Array:
    """Centre of the normalised design space (eqs. 6 and 8)."""
    return np.full(n_vars, 0.5 * (X_LOWER + X_UPPER))


def optimise(request: TuningRequest, full_model: FullModel,
             simplified_gradient: SimplifiedGradient | None = None,
             callback: Callable[[dict[str, Any], RunCounter], bool | None] | None = None,
             history: Sequence[Mapping[str, Any]] | None = None,
             counter: RunCounter | None = None) -> OptimizeResult:
    """Run Dynamic-Q on the full model with the requested gradient source.

    Parameters
    ----------
    request : TuningRequest
        Scenario, number of variables, start point, gradient source, options.
    full_model : callable
        Designs (m, n) -> :class:`FullEvaluation`; called with one design per
        iteration, and with the 2n central-difference designs when the gradient
        source is 'full'.
    simplified_gradient : callable, optional
        ``(x, inputs) -> (df (n,), dg (k, n))`` from the eq. 25-scaled simplified
        model (2n simplified runs each); required for gradient source 'simplified'.
    callback : callable, optional
        Called with each iteration's record and the run counter; returning True
        stops the run (cancellation).
    history : sequence of mappings, optional
        Records of an earlier run to resume from (``result.history``).
    counter : RunCounter, optional
        Counter to continue (e.g. one that holds the calibration runs).

    Returns
    -------
    scipy.optimize.OptimizeResult
        Dynamic-Q's result plus ``n_full_runs``, ``n_simplified_runs``,
        ``n_calibration_runs`` and ``scenario``, ``n_vars``, ``gradient_source``.
    """
    if request.gradient_source == 'simplified' and simplified_gradient is None:
        raise ValueError("gradient source 'simplified' needs a simplified_gradient")
    counter = counter or RunCounter()
    n = request.n_vars
    lower, upper = np.full(n, X_LOWER), np.full(n, X_UPPER)
    opt = DynamicQ(request.start, lower, upper, request.options, history=history,
                   gradient_source=request.gradient_source)
    inputs = None
    while (ask := opt.ask()) is not None:
        kind, x = ask
        if kind == 'evaluate':
            evaluation = full_model(x[None, :])
            counter.full_runs += 1
            inputs = evaluation.inputs
            record = opt.tell((float(evaluation.f[0]), evaluation.g[0], None))
        elif request.gradient_source == 'full':
            def values(points: Array) -> Array:
                batch = full_model(points)
                counter.full_runs += len(points)
                return np.column_stack([batch.f, batch.g])

            jac = central_difference(values, x, request.fd_step, lower, upper)
            record = opt.tell((jac[0], jac[1:], None), source='full')
        else:
            if inputs is None and request.scenario == 'handling':
                # Resumed from a history: the simplified handling model needs the full
                # model's steering and slip angles at x (paper 6.1), so run it once.
                inputs = full_model(x[None, :]).inputs
                counter.full_runs += 1
            df, dg = simplified_gradient(x, inputs)
            counter.simplified_runs += 2 * n
            record = opt.tell((np.asarray(df, float), np.asarray(dg, float), None),
                              source='simplified')
        if record is not None and callback is not None and callback(record, counter):
            opt.stop('cancelled')
    result = opt.result()
    result.update(counter.as_dict(), scenario=request.scenario, n_vars=n,
                  gradient_source=request.gradient_source)
    return result
