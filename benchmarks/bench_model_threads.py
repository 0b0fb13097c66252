"""The models on one thread or two: why the graph serves both from one loop.

Runs the in-process 2-variable ride optimisation of ``bench_graph.py`` (calibration
included) three ways, with no ROS at all:

- ``main``: every model call on the main thread (an in-process run);
- ``one_thread``: every model call handed to one worker thread;
- ``two_threads``: the full model on one worker thread, the simplified model on
  another (the graph with the simulation worker's ``evaluate`` and the gradient
  evaluator's ``gradient`` each served by a thread of its own).

Prints the median time of a single-design full-model run and of a 4-design simplified
gradient batch each way (ms).  numba's OpenMP team belongs to the thread that starts
a parallel region; a team that only runs the gradient batches has slept since the
previous iteration, and waking it on this 2-core virtual machine is what the
``two_threads`` figure pays.
"""

from __future__ import annotations

import collections
import queue
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import bench_graph  # first: loopback DDS environment and malloc settings
import numpy as np

ROUNDS = 6


class Worker:
    """A thread that runs the calls handed to it, one at a time."""

    def __init__(self) -> None:
        self._calls: queue.Queue = queue.Queue()
        self._results: queue.Queue = queue.Queue()
        threading.Thread(target=self._loop, daemon=True).start()

    def _loop(self) -> None:
        while True:
            function, args, kwargs = self._calls.get()
            self._results.put(function(*args, **kwargs))

    def call(self, function: Callable, *args: Any, **kwargs: Any) -> Any:
        self._calls.put((function, args, kwargs))
        return self._results.get()


def main() -> int:
    import suspension_tuning.optim.simplified_gradient as simplified
    from suspension_tuning import evaluation
    from suspension_tuning.optim.dynamic_q import load_options
    from suspension_tuning.paths import config_dir

    options = load_options(str(config_dir() / 'optimiser.yaml'), 'vehicle').as_dict()
    times: dict[tuple[str, str], list[float]] = collections.defaultdict(list)
    way = ['main']

    def timed(kind: str, function: Callable) -> Callable:
        def run(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            result = function(*args, **kwargs)
            if len(np.atleast_2d(args[1])) in (1, 4):  # one design / one gradient batch
                times[(way[0], kind)].append(time.perf_counter() - start)
            return result
        return run

    full = timed('full_model_single_design_ms', evaluation.evaluate)
    simp = timed('simplified_gradient_batch_ms', simplified.simplified_values)
    a, b = Worker(), Worker()
    ways = {
        'main': (full, simp),
        'one_thread': (lambda *x, **k: a.call(full, *x, **k),
                       lambda *x, **k: a.call(simp, *x, **k)),
        'two_threads': (lambda *x, **k: a.call(full, *x, **k),
                        lambda *x, **k: b.call(simp, *x, **k)),
    }
    evaluation.evaluate, simplified.simplified_values = ways['main']
    bench_graph.in_process(options)  # compile / load the kernels
    times.clear()
    for _ in range(ROUNDS):
        for name, (run_full, run_simplified) in ways.items():
            way[0] = name
            evaluation.evaluate, simplified.simplified_values = run_full, run_simplified
            bench_graph.in_process(options)
    for (name, kind), values in sorted(times.items()):
        print(f'{kind}_{name}: {np.median(values) * 1e3:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
