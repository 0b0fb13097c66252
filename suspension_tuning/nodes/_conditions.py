"""The coordinator's goal over a set of operating conditions (suspension_tuning.conditions).

The loop is the library's (:func:`suspension_tuning.tuning.optimise_conditions`); this
module gives it the workers and the gradient evaluator:

* the full model of a batch of designs in every condition goes out as ONE batch over
  the pool of simulation workers (``SimulationPool.evaluate(..., conditions=...)``):
  with as many workers as conditions, a design's runs take the wall time of one run;
* each condition's simplified model is calibrated in that condition
  (``Calibrate.condition``; cached by the gradient evaluator) and its gradient asked for
  in it (``EvaluateGradient.condition``);
* the result carries the per-condition objectives and physical metrics of the reported
  design and of the baseline, and the worst condition;
* the reported design of the built-in model is run once more in every condition at the
  tighter solver tolerance (in this process, :mod:`suspension_tuning.answer_check`),
  and the result carries both verdicts.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from suspension_tuning_interfaces.action import Optimise
from suspension_tuning_interfaces.msg import IterationRecord, TimeHistories
from suspension_tuning_interfaces.srv import Calibrate, EvaluateGradient

from suspension_tuning.answer_check import check_condition_options
from suspension_tuning.nodes._services import ServiceCallError, call
from suspension_tuning.optim.simplified_gradient import run_calibration_samples
from suspension_tuning.physical_metrics import SHOWN, physical_metrics
from suspension_tuning.tuning import (
    FullEvaluation,
    RunCancelled,
    RunCounter,
    TuningRequest,
    combined_objective,
    optimise_conditions,
    physical_settings,
)
from suspension_tuning.vehicle.design import load_design_space

#: The physical metrics shown per condition, per scenario (units in the names).
CONDITION_METRICS = {scenario: [shown for _, shown, _ in SHOWN[scenario]]
                     for scenario in ('ride', 'handling')}


def condition_model(node: Any, request: TuningRequest):
    """Designs (m, n) in every condition, one batch over the pool (condition-major).

    A handling run of one design brings the simplified model's inputs of each
    condition's run (``FullEvaluation.inputs``, a TimeHistories message).
    """

    def run(designs: np.ndarray, conditions: Sequence[Any]) -> list[FullEvaluation]:
        designs = np.atleast_2d(np.asarray(designs, float))
        m = len(designs)
        texts = [c.as_text() for c in conditions]
        inputs = (request.scenario == 'handling' and m == 1
                  and request.gradient_source == 'simplified')
        try:
            responses = node.pool.evaluate(
                request.scenario, request.n_vars, np.vstack([designs] * len(texts)),
                integrator=request.integrator, return_inputs=inputs,
                conditions=[text for text in texts for _ in range(m)])
        except (ValueError, ServiceCallError) as error:
            if node._cancel_requested():
                raise RunCancelled(str(error)) from error
            raise
        f = np.concatenate([np.asarray(r.f, float) for r in responses])
        g = np.concatenate([np.asarray(r.g, float).reshape(r.n_designs, r.n_constraints)
                            for r in responses])
        metrics = np.concatenate([np.asarray(r.metrics, float).reshape(
            r.n_designs, len(r.metric_names)) for r in responses])
        names = list(responses[0].metric_names)
        # one design: each condition's run is a piece (a response) of its own, in order
        first = [r.inputs[0] if inputs and len(r.inputs) else None for r in responses]
        return [FullEvaluation(f=f[c * m:(c + 1) * m], g=g[c * m:(c + 1) * m],
                               inputs=first[c],
                               metric_names=names, metrics=metrics[c * m:(c + 1) * m])
                for c in range(len(texts))]

    return run


def condition_gradient(node: Any, request: TuningRequest, condition: Any):
    """The scaled simplified gradient in one condition, from the gradient evaluator."""
    text = condition.as_text()

    def gradient(x: np.ndarray, inputs: Any) -> tuple[np.ndarray, np.ndarray, Any]:
        try:
            response = call(node, node.gradient_client, EvaluateGradient.Request(
                scenario=request.scenario, n_vars=request.n_vars,
                x=np.asarray(x, float).tolist(), step=request.fd_step,
                inputs=TimeHistories() if inputs is None else inputs, condition=text),
                node.timeout_s, node._stopped)
        except ServiceCallError as error:
            if node._cancel_requested():
                raise RunCancelled(str(error)) from error
            raise
        if not response.success:
            raise ValueError(f'gradient evaluator: {response.error}')
        dg = np.asarray(response.dg, float).reshape(response.n_constraints, request.n_vars)
        values = np.asarray(response.values, float) if len(response.values) else None
        return np.asarray(response.df, float), dg, values

    return gradient


def calibrate_condition(node: Any, goal_handle: Any, request: TuningRequest,
                        condition: Any) -> int:
    """Calibrate the goal's simplified model in one condition; the full runs it spent."""
    samples = run_calibration_samples(
        request.scenario, request.n_vars, int(node.get_parameter('calibration_samples').value))
    node._calibrating = (goal_handle, request.scenario, request.n_vars)
    try:
        response = call(node, node.calibrate_client, Calibrate.Request(
            scenario=request.scenario, n_vars=request.n_vars, n_samples=samples,
            unit_scaling=samples == 0, force=False,
            integrator=request.integrator, model_fingerprint=node.pool.fingerprint,
            condition=condition.as_text()), node.timeout_s * 2, node._stopped)
    finally:
        node._calibrating = None
    if not response.success:
        raise ValueError(f'calibration in condition {condition.name!r} failed: '
                         f'{response.error}')
    node._check_fit(goal_handle, request, f'{request.scenario} ({condition.name})', response)
    return int(response.n_full_runs)


def condition_fields(message: Any, result: Any, conditions: Any,
                     baseline: tuple[np.ndarray, list[dict[str, float]]] | None,
                     scenario: str = 'ride') -> None:
    """Per-condition fields of a result: objectives, metrics, worst condition, rounds."""
    shown = CONDITION_METRICS[scenario]
    message.condition_names = list(conditions.names)
    message.condition_metric_names = list(shown)
    message.n_rounds = int(result.get('rounds', 0))

    def table(per_condition: Sequence[dict[str, float]]) -> list[float]:
        rows = [physical_metrics(scenario, (), values) for values in per_condition]
        return [float(row.get(name, math.nan)) for row in rows for name in shown]

    if 'condition_f_best' in result:
        message.condition_f = [float(v) for v in result.condition_f_best]
        message.condition_metrics = table(result.condition_metrics_best)
        message.worst_condition = str(result.worst_condition)
    if baseline is not None:
        f_base, metrics_base = baseline
        message.condition_baseline_f = [float(v) for v in f_base]
        message.condition_baseline_metrics = table(metrics_base)
        message.baseline_f = combined_objective(f_base, conditions.weights,
                                                str(result.get('condition_form', 'worst')))


def run_condition_goal(node: Any, goal_handle: Any, request: TuningRequest,
                       fingerprint: str, t0: float, results: Any) -> Optimise.Result:
    """Optimise ``request`` over its condition set on the workers (the goal's execution).

    ``results``: the coordinator's result builders (``action_result``, ``config_first``,
    ``record_to_msg``, ``result_topic_message``), so that a condition goal reports as
    any goal does.
    """
    action_result, config_first = results.action_result, results.config_first
    record_to_msg, result_topic_message = results.record_to_msg, results.result_topic_message
    conditions = request.condition_set
    counter = RunCounter()
    history_msgs: list[IterationRecord] = []

    def on_iteration(record: dict[str, Any], counts: RunCounter) -> bool:
        msg = record_to_msg(record, counts, t0)
        history_msgs.append(msg)
        goal_handle.publish_feedback(Optimise.Feedback(phase='iteration', latest=msg))
        node.progress_pub.publish(msg)
        return goal_handle.is_cancel_requested

    model = condition_model(node, request)
    node.get_logger().info(f'optimising the {request.scenario} over {len(conditions)} '
                           'conditions '
                           f'({", ".join(conditions.names)}), {request.condition_form} case, '
                           f'{request.n_vars} variables, {request.gradient_source} gradients, '
                           f'model {fingerprint}')
    try:
        gradients = {}
        if request.gradient_source == 'simplified':
            for condition in conditions.conditions:
                counter.calibration_runs += calibrate_condition(node, goal_handle, request,
                                                                condition)
                gradients[condition.name] = condition_gradient(node, request, condition)
        checking, note = node._check_options(request, fingerprint)  # the built-in model
        if checking['check_model'] is not None:
            checking = check_condition_options(request.scenario, request.n_vars)
        result = optimise_conditions(request, model, gradients, on_iteration, counter,
                                     checking['check_model'], checking['check_gtol'],
                                     checking['check_continuations'])
    except (ValueError, ServiceCallError) as error:
        if node._cancel_requested():
            node.get_logger().info(f'goal cancelled ({error})')
            goal_handle.canceled()
            text = 'cancelled'
        else:
            text = str(error) if node.stopping else config_first(str(error))
            node.get_logger().error(f'optimisation failed: {text}')
            goal_handle.abort()
        message = Optimise.Result(success=False, message=text, history=history_msgs,
                                  wall_time_s=time.monotonic() - t0,
                                  model_fingerprint=fingerprint, **counter.as_dict())
        node.result_pub.publish(result_topic_message(message))
        return message
    message = action_result(result, history_msgs, t0, counter)
    message.model_fingerprint = fingerprint
    if not result.get('check'):
        message.check_note = note or 'not checked at a tighter solver tolerance'
    baseline = None
    if 'x_best' in result and not goal_handle.is_cancel_requested:
        x_base = load_design_space().baseline_x(request.n_vars)
        try:
            runs = model(x_base[None, :], conditions.conditions)
            baseline = (np.array([float(r.f[0]) for r in runs]),
                        [dict(zip(r.metric_names, np.asarray(r.metrics)[0])) for r in runs])
            message.baseline_x = x_base.tolist()
            message.baseline_physical_values = list(physical_settings(x_base).values())
        except (ValueError, ServiceCallError, RunCancelled) as error:
            node.get_logger().warning(f'run of the baseline design failed: {error}')
    condition_fields(message, result, conditions, baseline, request.scenario)
    if ('x_best' in result and node.get_parameter('final_telemetry').value
            and not goal_handle.is_cancel_requested):
        worst = conditions.conditions[conditions.names.index(str(result.worst_condition))]
        try:  # the reported design's telemetry in its worst condition, for the bag
            node.pool.evaluate(request.scenario, request.n_vars,
                               np.asarray(result.x_best, float)[None, :],
                               publish_telemetry=True, integrator=request.integrator,
                               conditions=[worst.as_text()])
        except (ValueError, ServiceCallError) as error:
            node.get_logger().warning(f'telemetry run of the reported design failed: '
                                      f'{error}')
    message.wall_time_s = time.monotonic() - t0
    if goal_handle.is_cancel_requested:
        goal_handle.canceled()
        message.message = 'cancelled'
    else:
        goal_handle.succeed()
    node.result_pub.publish(result_topic_message(message))
    return message
