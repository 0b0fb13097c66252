"""ROS 2 node ``gradient_evaluator``: gradients from the scaled simplified models.

Service ``~/calibrate`` (Calibrate): the eq. 25 scaling of the simplified model of a
scenario onto the full model, from N full-model samples (default 30, paper 6.3.1)
fetched over the graph from the simulation workers (found as the coordinator finds
its own, :mod:`suspension_tuning.nodes._pool`: every worker takes pieces of the batch
as it is free, and a lost or hung worker's pieces go to another); after each piece
``~/calibration_progress`` (CalibrationProgress) says how many of the samples are
done, which the coordinator passes on in its action feedback.  A request with
``unit_scaling`` spends no samples: the gradients then come from the unscaled
simplified model (the coordinator's first-order correction maps them onto the full
model along the run).  The
scaling is cached in ``calibration_dir`` under a key of scenario, n_vars, samples, seed,
a hash of the simplified models' configuration, the fingerprint of the workers'
full model (:mod:`suspension_tuning.model_identity`) and, for a request's own ride road
(``road``), that road and its file's SHA-256, so it costs its N full runs once per model
and road and is never used for another; the simplified model drives the same road.
Workers whose fingerprints differ from the pool's are left out; a pool whose model
differs from the caller's (``model_fingerprint`` of the request) is refused.

Service ``~/gradient`` (EvaluateGradient): the gradient of f and the Jacobian of g by
central differences of the scaled simplified model, all 2n perturbations in one batch
(:class:`suspension_tuning.optim.simplified_gradient.SimplifiedGradient`).  The
handling model needs the full model's steering and slip angles at x (paper 6.1); the
request carries them.  Bad requests get ``success = false`` and the reason.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from suspension_tuning_interfaces.msg import CalibrationProgress
from suspension_tuning_interfaces.srv import Calibrate, EvaluateGradient

from suspension_tuning import simplified_inputs
from suspension_tuning.conditions import Condition
from suspension_tuning.config_check import check_config
from suspension_tuning.model_identity import ModelMismatchError
from suspension_tuning.nodes._parameters import declare_numbers, read_only
from suspension_tuning.nodes._pool import pool_from_parameters
from suspension_tuning.nodes._services import ServiceCallError, serve
from suspension_tuning.nodes._spin import run_node
from suspension_tuning.optim.scaling import Scaling, scaling_key
from suspension_tuning.optim.simplified_gradient import (
    SimplifiedGradient,
    calibration_designs,
    calibration_settings,
    fit_calibration,
)
from suspension_tuning.vehicle.design import load_design_space, validate_design
from suspension_tuning.vehicle.road import road_identity
from suspension_tuning.vehicle.simplified import INPUT_SCENARIOS, SIMPLIFIED_SCENARIOS

SCENARIOS = SIMPLIFIED_SCENARIOS


class GradientEvaluatorNode(Node):
    """Service adapter over the eq. 25 calibration and the simplified gradient.

    Multi-threaded: ``calibrate`` waits for the simulation worker's response, which
    the client's callback group takes meanwhile, and ``gradient`` (a callback group of
    its own) is answered while a calibration runs.
    """

    EXECUTOR = MultiThreadedExecutor

    def __init__(self, **kwargs) -> None:
        check_config(builtin_model=False)  # ConfigError: one line, before the node exists
        super().__init__('gradient_evaluator', **kwargs)
        self.declare_parameter('calibration_dir', '')
        declare_numbers(self, {'default_samples': 16, 'default_step': 0.025})
        read_only(self, ['calibration_dir'])  # the defaults act when set
        directory = str(self.get_parameter('calibration_dir').value)
        self.calibration_dir = Path(directory or Path.home() / '.cache' / 'suspension_tuning'
                                    / 'calibration')
        # None: unit scaling (a request's unit_scaling)
        self.scalings: dict[tuple[str, int, str, str], Scaling | None] = {}
        self.simplified_runs = 0
        self.stopping = False  # set by destroy_node: a calibration stops waiting
        self.pool = pool_from_parameters(self, ReentrantCallbackGroup(), lambda: self.stopping)
        self.progress_pub = self.create_publisher(CalibrationProgress,
                                                  '~/calibration_progress', 100)
        serve(self, EvaluateGradient, '~/gradient', self._on_gradient,
              MutuallyExclusiveCallbackGroup())
        serve(self, Calibrate, '~/calibrate', self._on_calibrate,
              MutuallyExclusiveCallbackGroup())

    # ---------------------------------------------------------------- calibrate
    def _cache_path(self, key: dict) -> Path:
        tail = f"_{key['integrator']}" if 'integrator' in key else ''
        if 'road' in key:  # a request's own road: a short hash of its identity
            tail += '_road_' + hashlib.sha256(json.dumps(key['road'], sort_keys=True)
                                              .encode()).hexdigest()[:12]
        if 'condition' in key:  # an operating condition: a short hash of it
            tail += '_condition_' + hashlib.sha256(str(key['condition']).encode()
                                                   ).hexdigest()[:12]
        return self.calibration_dir / (f"v{key['calibration_version']}_"
                                       f"{key['scenario']}_{key['n_vars']}var_"
                                       f"{key['n_samples']}s_{key['seed']}_"
                                       f"{key['config_hash']}_"
                                       f"model_{key['model_fingerprint']}{tail}.json")

    def _on_calibrate(self, request: Calibrate.Request,
                      response: Calibrate.Response) -> Calibrate.Response:
        start = time.monotonic()
        try:
            scenario, n_vars = self._check(request.scenario, request.n_vars)
            n_samples, seed = calibration_settings(
                int(request.n_samples or self.get_parameter('default_samples').value))
            fingerprint = self.pool.check_models()
            if request.model_fingerprint and request.model_fingerprint != fingerprint:
                raise ModelMismatchError(
                    f'the caller runs model {request.model_fingerprint}, but the gradient '
                    f'evaluator\'s workers ({", ".join(self.pool.alive)}) run model '
                    f'{fingerprint}: give both nodes the same sim_workers and '
                    'sim_worker_pattern')
            response.model_fingerprint = fingerprint
            if request.unit_scaling:  # nothing to sample or cache
                self.scalings[(scenario, n_vars, request.road, request.condition)] = None
                response.success = True
                response.wall_time_s = time.monotonic() - start
                self.get_logger().info(f'{scenario}/{n_vars}: no calibration, unit scaling '
                                       '(the caller corrects along its run)')
                return response
            key = scaling_key(scenario, n_vars, n_samples, seed, fingerprint)
            if request.integrator:  # samples of a named integrator get their own cache
                key['integrator'] = request.integrator
            if request.road:  # and samples on a request's own road
                key['road'] = road_identity(request.road)
            if request.condition:  # and samples in an operating condition
                key['condition'] = Condition.from_text(request.condition).as_text()
            path = self._cache_path(key)
            scaling = None
            if path.exists() and not request.force:
                try:
                    scaling = Scaling.load(path, expected_key=key)
                    response.from_cache = True
                except ValueError as error:
                    self.get_logger().warning(f'stale calibration {path}: {error}')
            if scaling is None:  # the designs are sampled only now (~7 ms)
                x, _, _ = calibration_designs(n_vars, n_samples, seed)
                scaling = self._calibrate_remote(scenario, n_vars, x, key, request.road,
                                                 request.condition)
                response.n_full_runs = n_samples
                path.parent.mkdir(parents=True, exist_ok=True)
                scaling.save(path)
        except (ValueError, ServiceCallError) as error:
            response.success, response.error = False, str(error)
            self.get_logger().error(f'calibration failed: {error}')
            return response
        self.scalings[(scenario, n_vars, request.road, request.condition)] = scaling
        for function in scaling.functions:
            response.function_names.append(function.name)
            response.simplified_min.append(function.f_m_min)
            response.simplified_max.append(function.f_m_max)
            response.full_min.append(function.f_a_min)
            response.full_max.append(function.f_a_max)
            response.r_squared.append(float(function.r2))
        response.success = True
        response.wall_time_s = time.monotonic() - start
        self.get_logger().info(
            f'{scenario}/{n_vars} calibrated for model {response.model_fingerprint} '
            f'({"cache" if response.from_cache else "full runs"}): '
            + ', '.join(f'{f.name} R2={f.r2:.3f}' if f.rule == 'eq25' else f'{f.name} {f.rule}'
                        for f in scaling.functions))
        return response

    def _calibrate_remote(self, scenario: str, n_vars: int, x: np.ndarray,
                          key: dict, road: str = '', condition: str = '') -> Scaling:
        """Full-model samples from the simulation workers, then the eq. 25 fit."""
        # Only the handling model (of 'handling' and 'mixed') needs each sample's inputs
        # (simplified_inputs.py).
        start = time.monotonic()

        def progress(done: int) -> None:
            self.progress_pub.publish(CalibrationProgress(
                scenario=scenario, n_vars=n_vars, samples_done=done, samples_total=len(x),
                wall_time_s=time.monotonic() - start))

        try:
            answers = self.pool.evaluate(scenario, n_vars, x,
                                         return_inputs=scenario in INPUT_SCENARIOS,
                                         integrator=key.get('integrator', ''), road=road,
                                         on_piece=progress,
                                         conditions=[condition] * len(x) if condition
                                         else None)
        except ValueError as error:
            raise ValueError(f'full-model samples failed: {error}') from error
        full_f = np.concatenate([np.asarray(a.f, dtype=float) for a in answers])
        full_g = np.concatenate([np.asarray(a.g, dtype=float).reshape(a.n_designs,
                                                                      a.n_constraints)
                                 for a in answers])
        messages = [message for a in answers for message in a.inputs]
        inputs = [simplified_inputs.unpack(scenario, message, x[i])
                  for i, message in enumerate(messages)] or None
        self.simplified_runs += len(x)
        return fit_calibration(scenario, n_vars, x, full_f, full_g, inputs, key, road,
                               condition=condition)

    # ----------------------------------------------------------------- gradient
    def _on_gradient(self, request: EvaluateGradient.Request,
                     response: EvaluateGradient.Response) -> EvaluateGradient.Response:
        start = time.monotonic()
        try:
            scenario, n_vars = self._check(request.scenario, request.n_vars)
            x = validate_design(np.asarray(request.x, dtype=float), n_vars)[0]
            case = (scenario, n_vars, request.road, request.condition)
            scaling = self.scalings.get(case)
            if case not in self.scalings:
                road = f' on road {request.road!r}' if request.road else ''
                if request.condition:
                    road += f' in condition {Condition.from_text(request.condition).name!r}'
                raise ValueError(f'no calibration for {scenario} with {n_vars} variables{road}: '
                                 'call ~/calibrate first (eq. 25 needs full-model samples)')
            step = float(request.step or self.get_parameter('default_step').value)
            source = SimplifiedGradient(scenario, n_vars, scaling, step, request.road,
                                        condition=request.condition)
            inputs = simplified_inputs.unpack(scenario, request.inputs, x)
            df, dg, values = source(x, inputs)
        except ValueError as error:
            response.success, response.error = False, str(error)
            self.get_logger().warning(f'bad gradient request: {error}')
            return response
        self.simplified_runs += source.n_runs
        response.success = True
        response.df = np.asarray(df, dtype=float).tolist()
        response.n_constraints = int(dg.shape[0])
        response.dg = np.asarray(dg, dtype=float).ravel().tolist()
        response.values = np.asarray(values, dtype=float).tolist()
        response.n_model_runs = int(source.n_runs)
        response.wall_time_s = time.monotonic() - start
        return response

    @staticmethod
    def _check(scenario: str, n_vars: int) -> tuple[str, int]:
        if scenario not in SCENARIOS:
            raise ValueError(f'unknown scenario {scenario!r}; valid: {", ".join(SCENARIOS)}')
        load_design_space().check_size(int(n_vars))
        return scenario, int(n_vars)

    def destroy_node(self) -> None:
        """Let a calibration's wait end (within a second), then destroy the node."""
        self.stopping = True
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning gradient_evaluator``."""
    run_node(GradientEvaluatorNode, args, name='gradient_evaluator')


if __name__ == '__main__':
    main()
