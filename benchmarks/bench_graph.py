"""ROS overhead of the tuning graph: the same optimisation through the graph and in-process.

Runs the 2-variable ride optimisation with simplified-model gradients (eq. 25
calibration from 30 full-model samples included) twice:

- in-process: ``tuning.optimise`` calling the physics directly;
- through the graph: the nodes of ``graph`` and ``make demo`` (``graph.build_nodes``,
  without the recorder) in this process, spinning as there (``graph.SpinningGraph``),
  the goal sent by an action client (calibration over the graph too, from an empty
  cache each time).  The graph stays up for all runs, as a deployed graph does; one
  untimed warm-up goal first starts its worker threads.

Prints ``name: value`` lines, ending with ``ros_overhead_fraction`` = graph wall time /
in-process wall time - 1 (target <= 0.05 on 2 cores): the median over 20 pairs of runs made
next to each other, in alternating order, so that the machine's drift of its speed
(+-10 % over minutes on a shared machine) cancels within a pair; the interquartile
range of the pairs, a bootstrap 95 % interval of their median
(``ros_overhead_fraction_ci95``) and the ratio of the two medians are printed too
(``--pairs N`` for another number of pairs).  Both runs must
reach the same bits.  What the added time is made of: the time the graph adds
outside the models (service calls, serialisation, executors, the action; model time
removed from both runs, ``graph_added_time_s``) and the time the models themselves
take longer in the graph (other threads, ``model_time_added_s``), per service round
trip too, the bare round trip of a service without a model (``bare_round_trip_ms``)
and what the round trips at that cost leave of the added time
(``graph_added_beyond_bare_calls_s``), and the transport of the evaluate and gradient
round trips (``request_latency_ms``, ``response_latency_ms``: the median time from a
call to its server callback's start and from the callback's end to the caller holding
the response; ``transport_time_per_run_s``).  DDS stays on loopback with a domain of
its own.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import threading
import time

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', '91')

import numpy as np  # noqa: E402

# As in the node executables: one malloc arena, set before any thread allocates.
import suspension_tuning.nodes  # noqa: E402, F401

SCENARIO, N_VARS, SAMPLES, REPEATS = 'ride', 2, 30, 20



def timed(function, record):
    """``function`` wrapped to pass its entry and exit times (perf_counter, s) to ``record``."""
    def wrapped(*args, **kwargs):
        start = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            record(start, time.perf_counter())
    return wrapped

class ModelClock:
    """Wall time spent inside the models (full and simplified), in any thread.

    Physics dominates both runs and varies by +-10 % from run to run on a shared
    machine; subtracting it leaves the time the graph itself adds (service calls,
    serialisation, executors), which is what the ROS overhead is.  Each call is
    also kept in :attr:`calls` as ``(kind, entry time, exit time)``, kind 'full' or
    'simplified'.
    """

    def __init__(self) -> None:
        import suspension_tuning.optim.simplified_gradient as simplified
        from suspension_tuning import evaluation

        self.seconds = 0.0
        self.calls: list[tuple[str, float, float]] = []
        self._lock = threading.Lock()
        for module, name, kind in ((evaluation, 'evaluate', 'full'),
                                   (simplified, 'simplified_values', 'simplified')):
            setattr(module, name, timed(getattr(module, name),
                                        lambda a, b, kind=kind: self._add(kind, a, b)))

    def _add(self, kind: str, start: float, end: float) -> None:
        with self._lock:
            self.seconds += end - start
            self.calls.append((kind, start, end))

    def take(self) -> float:
        """Model seconds since the last call."""
        with self._lock:
            seconds, self.seconds = self.seconds, 0.0
        return seconds


class CallClock:
    """Each service round trip of a graph run split into its transport and its callback.

    Wraps ``_services.call_many`` (the caller's wait, one request at a time in this
    benchmark) and the evaluate and gradient callbacks of the server nodes (before the
    nodes are built: ``serve`` takes the bound methods then).  A round trip whose wait
    holds exactly one callback gives the request latency (send to callback start) and
    the response latency (callback end to the caller holding the response).
    """

    def __init__(self) -> None:
        from suspension_tuning.nodes import _services, full_vehicle_sim, gradient_evaluator

        self.waits: list[tuple[float, float]] = []
        self.callbacks: list[tuple[float, float]] = []
        self._lock = threading.Lock()
        _services.call_many = timed(_services.call_many,
                                    lambda a, b: self._add(self.waits, a, b))
        for cls, name in ((full_vehicle_sim.FullVehicleSimNode, '_on_evaluate'),
                          (gradient_evaluator.GradientEvaluatorNode, '_on_gradient')):
            setattr(cls, name, timed(getattr(cls, name),
                                     lambda a, b: self._add(self.callbacks, a, b)))

    def _add(self, into: list, start: float, end: float) -> None:
        with self._lock:
            into.append((start, end))

    def take(self) -> np.ndarray:
        """(request, response) latency of each round trip since the last take, s."""
        with self._lock:
            waits, callbacks = self.waits[:], self.callbacks[:]
            self.waits.clear()
            self.callbacks.clear()
        pairs = []
        for start, end in waits:
            inside = [(a, b) for a, b in callbacks if a >= start and b <= end]
            if len(inside) == 1:
                pairs.append((inside[0][0] - start, end - inside[0][1]))
        return np.array(pairs).reshape(-1, 2)

def in_process(options: dict) -> tuple[float, object]:
    from suspension_tuning import evaluation
    from suspension_tuning.optim.simplified_gradient import SimplifiedGradient, calibrate
    from suspension_tuning.tuning import FullEvaluation, RunCounter, TuningRequest, optimise

    start = time.perf_counter()
    # The full-model samples go through evaluation.evaluate, as in the graph's node.
    scaling = calibrate(SCENARIO, N_VARS, n_samples=SAMPLES,
                        run_full=lambda name, x: evaluation.evaluate(name, x).result)

    def full_model(points):
        run = evaluation.evaluate(SCENARIO, points)
        return FullEvaluation(run.f, run.g, run.result)

    result = optimise(TuningRequest(SCENARIO, N_VARS, None, 'simplified', options), full_model,
                      SimplifiedGradient(SCENARIO, N_VARS, scaling),
                      counter=RunCounter(calibration_runs=SAMPLES))
    return time.perf_counter() - start, result


class Graph:
    """The graph in this process, up for the whole benchmark (as a deployed graph is)."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.action import ActionClient
        from rclpy.node import Node
        from rclpy.parameter import Parameter
        from suspension_tuning_interfaces.action import Optimise

        from suspension_tuning.graph import SpinningGraph, build_nodes
        from suspension_tuning.nodes.coordinator import CoordinatorNode

        rclpy.init()
        self.cache = tempfile.mkdtemp(prefix='bench_graph_calibration_')
        # The nodes of `graph` (graph.build_nodes), without the recorder.
        self.nodes = build_nodes(workers=1, record=False, overrides={
            'gradient_evaluator': [Parameter('calibration_dir', value=self.cache)],
            'coordinator': [Parameter('calibration_samples', value=SAMPLES),
                            Parameter('final_telemetry', value=False)]})
        self.coordinator = next(n for n in self.nodes if isinstance(n, CoordinatorNode))
        self.client_node = Node('bench_graph_client')
        self.graph = SpinningGraph(self.nodes, [self.client_node])
        self.client = ActionClient(self.client_node, Optimise, '/coordinator/optimise')
        self.client.wait_for_server(timeout_sec=30.0)
        self.goal = Optimise.Goal(scenario=SCENARIO, n_vars=N_VARS,
                                  gradient_source='simplified')
        self.options = self.coordinator.options.as_dict()

    def run(self) -> tuple[float, object]:
        """One optimisation from an empty calibration cache; (wall time, result)."""
        from suspension_tuning.nodes._spin import wait_future

        shutil.rmtree(self.cache)
        os.mkdir(self.cache)
        start = self.started = time.perf_counter()
        handle = wait_future(self.client.send_goal_async(self.goal))
        result = wait_future(handle.get_result_async()).result
        return time.perf_counter() - start, result

    def bare_round_trip_s(self, calls: int = 200) -> float:
        """Median time of a call to the simulation worker's get_parameters service.

        From a client of the coordinator, as an evaluate call is made, to the worker
        node's executor: the cost of one service call without a model run.
        """
        from rcl_interfaces.srv import GetParameters
        from rclpy.callback_groups import ReentrantCallbackGroup

        from suspension_tuning.nodes._services import call

        client = self.coordinator.create_client(GetParameters,
                                                '/full_vehicle_sim/get_parameters',
                                                callback_group=ReentrantCallbackGroup())
        request = GetParameters.Request(names=['telemetry_decimation'])
        times = []
        for _ in range(calls):
            start = time.perf_counter()
            call(self.coordinator, client, request, 5.0)
            times.append(time.perf_counter() - start)
        return float(np.median(times))

    def close(self) -> None:
        import rclpy

        self.graph.shutdown()
        rclpy.shutdown()
        shutil.rmtree(self.cache, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    import argparse

    from suspension_tuning import evaluation

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--pairs', type=int, default=REPEATS,
                        help=f'pairs of runs to take the median over (default {REPEATS})')
    pairs = parser.parse_args(argv).pairs

    evaluation.evaluate(SCENARIO, np.full((1, N_VARS), 0.5))  # compile / load the kernels
    clock = ModelClock()
    calls = CallClock()  # before the graph's nodes are built
    graph = Graph()
    # Warm-up: the first goal also starts the executor's worker threads and their
    # OpenMP thread teams (numba's parallel kernel), a one-off cost of a new graph.
    graph.run()
    calls.take()  # the warm-up's round trips are not counted
    graph_times, local_times, graph_model, local_model = [], [], [], []
    latencies: list[np.ndarray] = []
    for repeat in range(pairs):
        # Pairs close in time, in alternating order: the machine's speed drifts by
        # +-10 % over minutes, and whichever run goes second in a pair may differ.
        for which in (('graph', 'local') if repeat % 2 == 0 else ('local', 'graph')):
            clock.take()
            if which == 'graph':
                graph_s, graph_result = graph.run()
                graph_model.append(clock.take())
                graph_times.append(graph_s)
                latencies.append(calls.take())
            else:
                local_s, local_result = in_process(graph.options)
                local_model.append(clock.take())
                local_times.append(local_s)
    bare_s = graph.bare_round_trip_s()
    graph.close()
    # The action reports the best feasible iterate (reported_design.py): the in-process
    # run's x_best, f_best.
    same = bool(np.array_equal(graph_result.x, local_result.x_best)
                and graph_result.f == local_result.f_best)
    # Medians of interleaved runs: single runs vary by +-10 % on this shared machine.
    graph_s, local_s = float(np.median(graph_times)), float(np.median(local_times))
    pair_fractions = np.array(graph_times) / np.array(local_times) - 1.0
    print(f'iterations: {graph_result.iterations}')
    print(f'full_runs: {graph_result.n_full_runs}')
    print(f'simplified_runs: {graph_result.n_simplified_runs}')
    print(f'calibration_runs: {graph_result.n_calibration_runs}')
    print(f'same_result_bits: {same}')
    print(f'in_process_wall_s: {local_s:.3f}')
    print(f'graph_wall_s: {graph_s:.3f}')
    print(f'repeats_median_of: {pairs}')
    print('graph_runs_s: ' + ' '.join(f'{t:.3f}' for t in graph_times))
    print('in_process_runs_s: ' + ' '.join(f'{t:.3f}' for t in local_times))
    # Round trips: one evaluate per iteration (n_full_runs), one gradient call per 2n
    # simplified runs, the calibration call and its batch of full-model samples.
    trips = (graph_result.n_full_runs + graph_result.n_simplified_runs // (2 * N_VARS) + 2)
    print(f'service_round_trips: {trips}')
    print(f'overhead_per_round_trip_ms: {(graph_s - local_s) / trips * 1e3:.2f}')
    print(f'bare_round_trip_ms: {bare_s * 1e3:.2f}')
    # Transport of the evaluate and gradient round trips (request: the call sent until
    # the server's callback starts; response: the callback's end until the caller holds
    # the response), medians over all runs, and its total per run.
    trips_latency = np.vstack(latencies)
    print(f'request_latency_ms: {np.median(trips_latency[:, 0]) * 1e3:.2f}')
    print(f'response_latency_ms: {np.median(trips_latency[:, 1]) * 1e3:.2f}')
    print('transport_time_per_run_s: '
          f'{np.median([lat.sum() for lat in latencies]):.4f}')
    added = [(g - gm) - (loc - lm) for g, gm, loc, lm
             in zip(graph_times, graph_model, local_times, local_model)]
    print(f'model_time_graph_s: {np.median(graph_model):.3f}')
    print(f'model_time_in_process_s: {np.median(local_model):.3f}')
    print(f'graph_added_time_s: {np.median(added):.4f}')
    print(f'graph_added_per_round_trip_ms: {np.median(added) / trips * 1e3:.2f}')
    # The rest: the action (goal, feedback, result), the run configuration, the
    # conversion of the requests and responses beyond a bare call's.
    print(f'graph_added_beyond_bare_calls_s: {np.median(added) - trips * bare_s:.4f}')
    print('model_time_added_s: '
          f'{np.median(np.array(graph_model) - np.array(local_model)):.4f}')
    print(f'ros_overhead_fraction_model_time_removed: {np.median(added) / local_s:.4f}')
    print(f'ros_overhead_fraction_of_medians: {graph_s / local_s - 1.0:.4f}')
    q1, q3 = np.percentile(pair_fractions, [25, 75])
    print(f'ros_overhead_fraction_pairs_iqr: {q1:.4f} {q3:.4f}')
    # How sure that median is: the pairs resampled with replacement (bootstrap, 2,000
    # draws, fixed seed), the 2.5 and 97.5 percentiles of the draws' medians.
    draws = np.random.default_rng(0).choice(pair_fractions, (2000, len(pair_fractions)))
    low, high = np.percentile(np.median(draws, axis=1), [2.5, 97.5])
    print(f'ros_overhead_fraction_ci95: {low:.4f} {high:.4f}')
    # Median over the pairs (graph run / in-process run next to it, minus one).
    print(f'ros_overhead_fraction: {np.median(pair_fractions):.4f}')
    return 0 if same else 1


if __name__ == '__main__':
    sys.exit(main())
