"""ROS 2 node ``gradient_evaluator``: gradients from the scaled simplified models.

Service ``~/calibrate`` (Calibrate): the eq. 25 scaling of the simplified model of a
scenario onto the full model, from N full-model samples (default 30, paper 6.3.1)
fetched over the graph from a simulation worker (``sim_service``) in one batch.  The
scaling is cached in ``calibration_dir`` under a key of scenario, n_vars, samples, seed
and a hash of the model configuration, so it costs its N full runs once.

Service ``~/gradient`` (EvaluateGradient): the gradient of f and the Jacobian of g by
central differences of the scaled simplified model, all 2n perturbations in one batch
(:class:`suspension_tuning.optim.simplified_gradient.SimplifiedGradient`).  The
handling model needs the full model's steering and slip angles at x (paper 6.1); the
request carries them.  Bad requests get ``success = false`` and the reason.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from rclpy.node import Node
from suspension_tuning_interfaces.srv import Calibrate, EvaluateDesign, EvaluateGradient

from suspension_tuning import simplified_inputs
from suspension_tuning.nodes import _logging
from suspension_tuning.nodes._service_calls import ServiceCaller, ServiceCallError
from suspension_tuning.nodes._service_thread import ServiceLoop, ServiceThread
from suspension_tuning.nodes._spin import run_node
from suspension_tuning.optim.scaling import Scaling, scaling_key
from suspension_tuning.optim.simplified_gradient import (
    SimplifiedGradient,
    calibration_designs,
    calibration_settings,
    fit_calibration,
)
from suspension_tuning.vehicle.design import VARIABLE_NAMES, validate_design

SCENARIOS = ('ride', 'handling')


class GradientEvaluatorNode(Node):
    """Service adapter over the eq. 25 calibration and the simplified gradient."""

    def __init__(self, service_loop: ServiceLoop | None = None, **kwargs) -> None:
        """``service_loop``: serve ``gradient`` and ``calibrate`` on this shared loop.

        By default ``gradient`` and ``calibrate`` have a loop (thread) each, and a
        gradient is answered while a calibration runs.  On a shared loop, the
        calibration's wait for the simulation worker answers the loop's requests
        (the worker's ``evaluate`` among them, ``_service_calls.ServiceCaller``).
        """
        super().__init__('gradient_evaluator', **kwargs)
        self.declare_parameter('sim_service', '/full_vehicle_sim/evaluate')
        self.declare_parameter('calibration_dir', '')
        self.declare_parameter('default_samples', 30)
        self.declare_parameter('default_step', 0.025)
        self.declare_parameter('call_timeout_s', 600.0)
        directory = str(self.get_parameter('calibration_dir').value)
        self.calibration_dir = Path(directory or Path.home() / '.cache' / 'suspension_tuning'
                                    / 'calibration')
        self.scalings: dict[tuple[str, int], Scaling] = {}
        self.caller = ServiceCaller(self, serve_loop=service_loop)
        self.sim_client = self.caller.create_client(EvaluateDesign,
                                                    str(self.get_parameter('sim_service').value))
        self.simplified_runs = 0
        # Served outside the node's executor: no executor is in the path of a request.
        self.service_threads = [
            ServiceThread(self, EvaluateGradient, 'gradient', self._on_gradient,
                          loop=service_loop),
            ServiceThread(self, Calibrate, 'calibrate', self._on_calibrate,
                          loop=service_loop)]

    # ---------------------------------------------------------------- calibrate
    def _cache_path(self, key: dict) -> Path:
        tail = f"_{key['integrator']}" if 'integrator' in key else ''
        return self.calibration_dir / (f"{key['scenario']}_{key['n_vars']}var_"
                                       f"{key['n_samples']}s_{key['seed']}_"
                                       f"{key['config_hash']}{tail}.json")

    def _on_calibrate(self, request: Calibrate.Request,
                      response: Calibrate.Response) -> Calibrate.Response:
        start = time.monotonic()
        try:
            scenario, n_vars = self._check(request.scenario, request.n_vars)
            n_samples, seed = calibration_settings(
                int(request.n_samples or self.get_parameter('default_samples').value))
            key = scaling_key(scenario, n_vars, n_samples, seed)
            if request.integrator:  # samples of a named integrator get their own cache
                key['integrator'] = request.integrator
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
                scaling = self._calibrate_remote(scenario, n_vars, x, key)
                response.n_full_runs = n_samples
                path.parent.mkdir(parents=True, exist_ok=True)
                scaling.save(path)
        except (ValueError, ServiceCallError) as error:
            response.success, response.error = False, str(error)
            self.get_logger().error(f'calibration failed: {error}')
            return response
        self.scalings[(scenario, n_vars)] = scaling
        for function in scaling.functions:
            response.function_names.append(function.name)
            response.simplified_min.append(function.f_m_min)
            response.simplified_max.append(function.f_m_max)
            response.full_min.append(function.f_a_min)
            response.full_max.append(function.f_a_max)
            response.r_squared.append(float(function.r2))
        response.success = True
        response.wall_time_s = time.monotonic() - start
        _logging.info(
            self,
            f'{scenario}/{n_vars} calibrated ({"cache" if response.from_cache else "full runs"}): '
            + ', '.join(f'{f.name} R2={f.r2:.3f}' if f.rule == 'eq25' else f'{f.name} {f.rule}'
                        for f in scaling.functions))
        return response

    def _calibrate_remote(self, scenario: str, n_vars: int, x: np.ndarray,
                          key: dict) -> Scaling:
        """Full-model samples from a simulation worker, then the eq. 25 fit."""
        timeout = float(self.get_parameter('call_timeout_s').value)
        # Only the handling model needs each sample's inputs (simplified_inputs.py).
        answer = self.caller.call(self.sim_client, EvaluateDesign.Request(
            scenario=scenario, n_vars=n_vars, designs=x.ravel().tolist(),
            return_inputs=scenario == 'handling', integrator=key.get('integrator', '')),
            timeout)
        if not answer.success:
            raise ValueError(f'full-model samples failed: {answer.error}')
        full_f = np.asarray(answer.f, dtype=float)
        full_g = np.asarray(answer.g, dtype=float).reshape(len(x), answer.n_constraints)
        inputs = [simplified_inputs.unpack(scenario, message, x[i])
                  for i, message in enumerate(answer.inputs)] or None
        self.simplified_runs += len(x)
        return fit_calibration(scenario, n_vars, x, full_f, full_g, inputs, key)

    # ----------------------------------------------------------------- gradient
    def _on_gradient(self, request: EvaluateGradient.Request,
                     response: EvaluateGradient.Response) -> EvaluateGradient.Response:
        start = time.monotonic()
        try:
            scenario, n_vars = self._check(request.scenario, request.n_vars)
            x = validate_design(np.asarray(request.x, dtype=float), n_vars)[0]
            scaling = self.scalings.get((scenario, n_vars))
            if scaling is None:
                raise ValueError(f'no calibration for {scenario} with {n_vars} variables: '
                                 'call ~/calibrate first (eq. 25 needs full-model samples)')
            step = float(request.step or self.get_parameter('default_step').value)
            source = SimplifiedGradient(scenario, n_vars, scaling, step)
            inputs = simplified_inputs.unpack(scenario, request.inputs, x)
            df, dg = source(x, inputs)
        except ValueError as error:
            response.success, response.error = False, str(error)
            self.get_logger().warning(f'bad gradient request: {error}')
            return response
        self.simplified_runs += source.n_runs
        response.success = True
        response.df = np.asarray(df, dtype=float).tolist()
        response.n_constraints = int(dg.shape[0])
        response.dg = np.asarray(dg, dtype=float).ravel().tolist()
        response.n_model_runs = int(source.n_runs)
        response.wall_time_s = time.monotonic() - start
        return response

    @staticmethod
    def _check(scenario: str, n_vars: int) -> tuple[str, int]:
        if scenario not in SCENARIOS:
            raise ValueError(f'unknown scenario {scenario!r}; valid: {", ".join(SCENARIOS)}')
        if int(n_vars) not in VARIABLE_NAMES:
            raise ValueError(f'n_vars must be 2 or 4, got {n_vars}')
        return scenario, int(n_vars)

    def destroy_node(self) -> None:
        """Destroy the service threads and the private client node too."""
        for service in self.service_threads:
            service.destroy()
        self.caller.destroy()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning gradient_evaluator``."""
    run_node(GradientEvaluatorNode, args, multithreaded=True)


if __name__ == '__main__':
    main()
