"""Resume an optimisation from the last iteration recorded in a bag (in-process).

The bag's ``/optimisation/run_config`` says what ran (scenario, variables, gradient
source, Dynamic-Q options, calibration samples) and its ``/optimisation/progress``
records say where it got to (:func:`suspension_tuning.bag.history.last_iteration`).
The run continues from the last record with the same loop the coordinator uses
(:func:`suspension_tuning.tuning.optimise`), the physics called directly.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from typing import Any

from scipy.optimize import OptimizeResult

from suspension_tuning import evaluation
from suspension_tuning.bag.history import last_iteration
from suspension_tuning.tuning import RunCounter, TuningRequest, optimise, with_noise_levels
from suspension_tuning.vehicle.params import INTEGRATORS


def resume(bag: str | os.PathLike[str], max_iterations: int | None = None,
           callback: Callable[[dict[str, Any], RunCounter], bool | None] | None = None
           ) -> OptimizeResult:
    """Continue the optimisation recorded in ``bag`` from its last iteration.

    Parameters
    ----------
    bag : path
        Bag folder (or .mcap file) of an optimisation run.
    max_iterations : int, optional
        New iteration limit (counted from the start of the original run); default the
        run's own.
    callback : callable, optional
        As for :func:`suspension_tuning.tuning.optimise`.

    Returns
    -------
    scipy.optimize.OptimizeResult
        :func:`suspension_tuning.tuning.optimise`'s result: ``x`` is the last iterate;
        the design to report is the best one over the whole run, the bag's iterations
        included (``x_best`` ..., :func:`suspension_tuning.reported_design.reported_design`).

    Raises
    ------
    ValueError
        The bag has no run configuration or no iteration records.
    """
    state = last_iteration(bag)
    config = state.get('run_config')
    if not isinstance(config, dict) or 'scenario' not in config:
        raise ValueError(f'{bag}: no run configuration (/optimisation/run_config) to resume')
    options = dict(config.get('optimiser_options') or {})
    if max_iterations is not None:
        options['maxiter'] = int(max_iterations)
        options['maxiter_variables'] = 0
    request = TuningRequest(config['scenario'], int(config['n_vars']), config['x0'],
                            config['gradient_source'], options, float(config['fd_step']),
                            config.get('constraints') or (),
                            # 'simulation default' (no integrator named) reads as ''
                            integrator=config.get('integrator')
                            if config.get('integrator') in INTEGRATORS else '',
                            # a bag recorded before the correction existed ran without it;
                            # a resumed run learns its correction anew from here on
                            correction=config.get('gradient_correction') or {'method': 'none'})
    last = state['history'][-1]
    counter = RunCounter(full_runs=int(last['n_full_runs']),
                         simplified_runs=int(last['n_simplified_runs']))

    models = {name: evaluation.in_process_model(name, request.integrator)
              for name in (request.scenario, *request.constraint_scenarios)}
    gradients = {}
    if request.gradient_source == 'simplified':
        from suspension_tuning.optim.simplified_gradient import (
            SimplifiedGradient,
            calibrate,
            run_calibration_samples,
        )

        # the run's coordinator parameter: -1 (or a bag without it) = each case's default
        samples = (config.get('coordinator_parameters') or {}).get('calibration_samples')
        sources = request.constraint_gradient_sources()
        for name in dict.fromkeys([request.scenario, *(
                c.scenario for c, s in zip(request.constraints, sources) if s == 'simplified')]):
            n_samples = run_calibration_samples(name, request.n_vars, samples)
            scaling = calibrate(name, request.n_vars, n_samples=n_samples) if n_samples else None
            counter.calibration_runs += n_samples
            gradients[name] = SimplifiedGradient(name, request.n_vars, scaling,
                                                 request.fd_step)
    # the built-in model runs here: its noise levels and the check of the answer, as the
    # coordinator gives them for the built-in model
    from suspension_tuning.answer_check import check_options

    request = dataclasses.replace(request, options=with_noise_levels(
        request.options, request.scenario, request.integrator))
    return optimise(request, models[request.scenario], gradients.get(request.scenario),
                    callback, history=state['history'], counter=counter,
                    constraint_models=models, constraint_gradients=gradients,
                    **check_options(request.scenario, request.n_vars))
