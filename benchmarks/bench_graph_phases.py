"""Where the graph's added time falls: each phase of a run, graph against in-process.

Runs the optimisation of ``bench_graph.py`` (2-variable ride, simplified gradients,
30-sample calibration) through the one-process graph and in-process, in alternating
pairs, with every model call (``evaluation.evaluate``, ``simplified_values``)
timestamped on entry and exit.  Both runs make the same model calls in the same
order, so they line up call by call:

- a *gap* is the time between two model calls (or from the start to the first one,
  or from the last one to the result): the optimiser's own Python in both runs, plus
  in the graph the service calls, the action and the feedback;
- a *call* is the time inside one model call: the same computation in both runs.

Prints, as medians over the pairs (ms): the added time of the start (goal sent to the
calibration batch), of the gaps before each gradient and before each full run of
the iterations (per gap), of the end (last full run to the result in the client),
and how much slower each kind of model call is in the graph; then the total of the
gaps and of the calls.  ``bench_graph.py`` gives the overall fraction; this tells
which part of the graph a change has to shorten.  DDS stays on loopback with a
domain of its own (``bench_graph``).
"""

from __future__ import annotations

import sys
import time

# First: it sets the loopback DDS environment and the malloc settings before threads start.
import bench_graph
import numpy as np

PAIRS = 10


def phases(calls: list[tuple[str, float, float]], start: float, end: float
           ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(kinds of the calls, gaps (n + 1), call durations (n)) of one run, s."""
    run = list(calls)
    kinds = [kind for kind, _, _ in run]
    edges = [start] + [t for _, t0, t1 in run for t in (t0, t1)] + [end]
    gaps = np.array(edges[1::2]) - np.array(edges[0::2])
    durations = np.array([t1 - t0 for _, t0, t1 in run])
    return kinds, gaps, durations


def main() -> int:
    from suspension_tuning import evaluation

    evaluation.evaluate(bench_graph.SCENARIO, np.full((1, bench_graph.N_VARS), 0.5))
    clock = bench_graph.ModelClock()  # timestamps every model call, in any thread
    graph = bench_graph.Graph()
    graph.run()  # warm-up: worker threads and their OpenMP teams
    runs: dict[str, list] = {'graph': [], 'local': []}
    for pair in range(PAIRS):
        for which in (('graph', 'local') if pair % 2 == 0 else ('local', 'graph')):
            clock.calls.clear()
            start = time.perf_counter()
            if which == 'graph':
                graph.run()
                start = graph.started  # as bench_graph times it: from the goal's send
            else:
                bench_graph.in_process(graph.options)
            runs[which].append(phases(clock.calls, start, time.perf_counter()))
    graph.close()
    kinds = runs['graph'][0][0]
    if any(run[0] != kinds for run in runs['graph'] + runs['local']) or kinds[:2] != [
            'full', 'simplified']:
        print('error: the runs made different model calls', file=sys.stderr)
        return 1
    added_gap = (np.median([run[1] for run in runs['graph']], axis=0)
                 - np.median([run[1] for run in runs['local']], axis=0)) * 1e3
    added_call = (np.median([run[2] for run in runs['graph']], axis=0)
                  - np.median([run[2] for run in runs['local']], axis=0)) * 1e3
    # Gap i comes before call i.  Calls 0 and 1 are the calibration (the full-model
    # batch, then the simplified model at the same designs for the eq. 25 fit); the
    # iterations follow: a full run, then its gradient's simplified batch, and so on.
    iteration_kinds = np.array(kinds[2:])
    iteration_gaps, iteration_calls = added_gap[2:-1], added_call[2:]
    print(f'pairs: {PAIRS}')
    print(f'model_calls_per_run: {len(kinds)} (2 calibration batches, then '
          f'{kinds.count("full") - 1} full runs and {kinds.count("simplified") - 1} '
          'gradient batches)')
    print(f'start_added_ms: {added_gap[0]:.2f}  (goal sent to the calibration batch)')
    print(f'calibration_handover_added_ms: {added_gap[1]:.2f}  '
          '(full-model samples to the simplified batch of the fit)')
    for kind, name in (('full', 'full_run'), ('simplified', 'gradient')):
        gaps = iteration_gaps[iteration_kinds == kind]
        print(f'gap_before_{name}_added_ms: {np.median(gaps):.2f}  (x{gaps.size} per run)')
    print(f'end_added_ms: {added_gap[-1]:.2f}  (last full run to the result in the client)')
    print(f'calibration_batches_slower_ms: {added_call[0]:.2f} {added_call[1]:.2f}')
    for kind, name in (('full', 'full_run'), ('simplified', 'gradient_batch')):
        slower = iteration_calls[iteration_kinds == kind]
        print(f'{name}_slower_ms: {np.median(slower):.2f}  (x{slower.size} per run)')
    print(f'gaps_added_total_ms: {added_gap.sum():.1f}')
    print(f'model_calls_slower_total_ms: {added_call.sum():.1f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
