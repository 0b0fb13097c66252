"""The closed-loop (mixed) scenario over topics against the same run in-process.

One design of the ``mixed`` scenario (rough road, then the ISO 3888-1 lane change;
1,440 control periods of the 4S4 valve controller, one step-locked DDS round trip
each): the simulation node on a multi-threaded executor (as ``ros2 run
suspension_tuning full_vehicle_sim`` spins it) and the valve controller node on an
executor of its own, both spun by the test kit's ``spinning_executor`` in this process
with DDS on loopback, against ``evaluation.evaluate('mixed', ...)`` with the same
controller called in-process.  One untimed run of each first (numba's kernels load
from the cache).  Prints ``name: value`` lines:

- ``closed_loop_inprocess_s`` and ``closed_loop_topics_s``: median wall time of
  ``--repeats`` runs of each, in alternating order;
- ``closed_loop_steps``: the control periods of the run (valve states exchanged);
- ``closed_loop_round_trip_ms``: the time the topics add per control period (the
  difference of the medians over the steps): publishing ``/clock`` and the vehicle
  state, the controller's answer and its hand-over to the integrating thread;
- ``closed_loop_same_bits``: 1 when every run over topics gives the in-process f and g.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', '93')

import numpy as np  # noqa: E402

# As in the node executables: one malloc arena, set before any thread allocates.
import suspension_tuning.nodes  # noqa: E402, F401
from suspension_tuning import evaluation  # noqa: E402

DESIGN = [0.5005, 0.5005]  # the centre of the 2-variable design space


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeats', type=int, default=3, help='timed runs of each (3)')
    args = parser.parse_args()

    from rclpy.node import Node
    from suspension_tuning_interfaces.srv import EvaluateDesign

    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.valve_controller import ValveControllerNode
    from suspension_tuning.testing import call_service, isolated_context, spinning_executor

    first = evaluation.evaluate('mixed', np.array([DESIGN]))
    reference = first.f, first.g
    steps = int(np.asarray(first.result.valve_log[0]).shape[1])  # (4, periods)
    times: dict[str, list[float]] = {'inprocess': [], 'topics': []}
    same = True
    with (isolated_context() as context, spinning_executor(context) as sim_executor,
          spinning_executor(context, num_threads=1) as valve_executor):
        client_node = Node('bench_closed_loop', context=context)
        sim_executor.add(FullVehicleSimNode(context=context), client_node)
        valve_executor.add(ValveControllerNode(context=context))
        client = client_node.create_client(EvaluateDesign, '/full_vehicle_sim/evaluate')
        request = EvaluateDesign.Request(scenario='mixed', n_vars=2, designs=DESIGN)

        def over_topics():
            response = call_service(client, request, timeout_s=900.0)
            if not response.success:
                raise SystemExit(f'closed-loop run failed: {response.error}')
            return np.asarray(response.f), np.reshape(response.g, (1, -1))

        def in_process():
            result = evaluation.evaluate('mixed', np.array([DESIGN]))
            return result.f, result.g

        over_topics()
        for k in range(args.repeats):
            for name in (('inprocess', 'topics') if k % 2 == 0 else ('topics', 'inprocess')):
                start = time.perf_counter()
                f, g = in_process() if name == 'inprocess' else over_topics()
                times[name].append(time.perf_counter() - start)
                same = same and np.array_equal(f, reference[0]) and np.array_equal(
                    g, reference[1])

    inprocess, topics = (statistics.median(times[n]) for n in ('inprocess', 'topics'))
    print(f'closed_loop_inprocess_s: {inprocess:.3f}')
    print(f'closed_loop_topics_s: {topics:.3f}')
    print(f'closed_loop_steps: {steps}')
    print(f'closed_loop_round_trip_ms: {1000.0 * (topics - inprocess) / steps:.3f}')
    print(f'closed_loop_same_bits: {int(same)}')


if __name__ == '__main__':
    main()
