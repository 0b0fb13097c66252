"""Where the graph's own time goes: timestamps inside the nodes during an optimisation.

Runs the optimisation of ``bench_graph.py`` (2-variable ride, simplified gradients,
calibration over the graph) through the same one-process graph, with the node
callbacks, the service calls and the model calls wrapped to record a timestamp on
entry and exit.  The run is a chain (one thing happens at a time), so each pair of
consecutive timestamps is one segment of it, named by its two ends.

Prints ``name: value`` lines: the median over the runs and the calls of each segment
that exists only in the graph (ms), how often it occurs per run, and their sum per
run against the model time; and ``call_overhead_ms``, the time the service calls
take beyond their callbacks (all calls of a run, the calls nested in a callback
included).  The figures quoted in the README's benchmark section come from here.
DDS stays on loopback with a domain of its own (``bench_graph``).
"""

from __future__ import annotations

import collections
import functools
import sys
import time
from collections.abc import Callable
from typing import Any

# First: it sets the loopback DDS environment and the malloc settings before threads start.
import bench_graph
import numpy as np

RUNS = 8

#: Segment (from event, to event) -> printed name.  ``*_cb`` matches every service
#: callback (sim_cb, grad_cb, cal_cb).
SEGMENTS = {
    ('send', 'execute>'): 'goal_to_execute_ms',
    ('execute>', 'runconfig>'): 'execute_start_ms',
    ('runconfig>', '<runconfig'): 'run_config_ms',
    ('call>', 'take>'): 'request_send_ms',
    ('take>', '*_cb>'): 'request_take_ms',
    ('send>', '<send'): 'response_send_ms',
    ('fb>', '<fb'): 'feedback_ms',
    ('<execute', 'done'): 'result_to_client_ms',
}

events: list[tuple[float, str]] = []


def wrap(owner: Any, name: str, label: str) -> None:
    """Replace ``owner.name`` by a wrapper recording ``label>`` and ``<label``."""
    function: Callable = getattr(owner, name)

    @functools.wraps(function)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        events.append((time.perf_counter(), label + '>'))
        try:
            return function(*args, **kwargs)
        finally:
            events.append((time.perf_counter(), '<' + label))

    setattr(owner, name, wrapper)


def instrument() -> None:
    """Wrap the node callbacks, service calls, feedback and models (before the nodes exist)."""
    from rclpy.action.server import ServerGoalHandle
    from rclpy.service import Service

    import suspension_tuning.optim.simplified_gradient as simplified
    from suspension_tuning import evaluation
    from suspension_tuning.nodes import _service_calls
    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.gradient_evaluator import GradientEvaluatorNode

    wrap(CoordinatorNode, '_execute', 'execute')
    wrap(CoordinatorNode, '_publish_run_config', 'runconfig')
    wrap(FullVehicleSimNode, '_on_evaluate', 'sim_cb')
    wrap(GradientEvaluatorNode, '_on_gradient', 'grad_cb')
    wrap(GradientEvaluatorNode, '_on_calibrate', 'cal_cb')
    wrap(_service_calls.ServiceCaller, 'call_many', 'call')
    wrap(_service_calls.ServiceCaller, '_take_responses', 'take')
    wrap(Service, 'send_response', 'send')
    wrap(ServerGoalHandle, 'publish_feedback', 'fb')
    wrap(evaluation, 'evaluate', 'model')
    wrap(simplified, 'simplified_values', 'model')


def segments(run: list[tuple[float, str]]) -> dict[str, list[float]]:
    """Durations (ms) of the named segments of one run's event chain."""
    found: dict[str, list[float]] = collections.defaultdict(list)
    for (t0, a), (t1, b) in zip(run, run[1:]):
        key = (a, '*_cb>' if b.endswith('_cb>') else b)
        if key in SEGMENTS:
            found[SEGMENTS[key]].append((t1 - t0) * 1e3)
    return found


def inside_ms(run: list[tuple[float, str]], label: str) -> float:
    """Time inside the wrapped calls named ``label`` in one run (ms), nested ones once."""
    total, depth, start = 0.0, 0, 0.0
    for t, event in run:
        if event == label + '>':
            depth += 1
            if depth == 1:
                start = t
        elif event == '<' + label:
            depth -= 1
            if depth == 0:
                total += t - start
    return total * 1e3


def model_ms(run: list[tuple[float, str]]) -> float:
    """Time inside the models in one run (ms)."""
    return inside_ms(run, 'model')


def call_overhead_ms(run: list[tuple[float, str]]) -> float:
    """Time of the service calls beyond their callbacks in one run (ms).

    Every call and every callback counted on its own: a call nested in a callback
    (the calibration's samples) adds its own overhead and leaves its callback's.
    """
    open_at: dict[str, list[float]] = collections.defaultdict(list)
    spans = {'call': 0.0, 'cb': 0.0}
    for t, event in run:
        name = event.strip('<>')
        kind = 'call' if name == 'call' else 'cb' if name.endswith('_cb') else None
        if kind is None:
            continue
        if event.endswith('>'):
            open_at[name].append(t)
        else:
            spans[kind] += t - open_at[name].pop()
    return (spans['call'] - spans['cb']) * 1e3


def main() -> int:
    from suspension_tuning import evaluation

    evaluation.evaluate('ride', np.full((1, 2), 0.5))  # compile / load the kernels
    instrument()
    graph = bench_graph.Graph()
    graph.run()  # warm-up, as in bench_graph
    runs = []
    for _ in range(RUNS):
        events.clear()
        events.append((time.perf_counter(), 'send'))
        graph.run()
        events.append((time.perf_counter(), 'done'))
        runs.append(list(events))
    graph.close()
    per_run = [segments(run) for run in runs]
    print(f'runs: {RUNS}')
    total = np.zeros(RUNS)
    for name in SEGMENTS.values():
        values = [v for found in per_run for v in found.get(name, [])]
        counts = [len(found.get(name, [])) for found in per_run]
        total += [sum(found.get(name, [])) for found in per_run]
        print(f'{name}: {np.median(values):.3f}  (x{int(np.median(counts))} per run)')
    print(f'named_segments_sum_ms: {np.median(total):.1f}')
    calls = [sum(1 for _, event in r if event == 'call>') for r in runs]
    overhead = [call_overhead_ms(r) for r in runs]
    print(f'call_overhead_ms: {np.median(overhead):.1f}  (x{int(np.median(calls))} calls per '
          f'run, {np.median(np.array(overhead) / calls):.3f} per call)')
    print(f'run_wall_ms: {np.median([(r[-1][0] - r[0][0]) * 1e3 for r in runs]):.1f}')
    print(f'model_ms: {np.median([model_ms(r) for r in runs]):.1f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
