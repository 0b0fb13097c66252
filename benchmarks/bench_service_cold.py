"""One service call's middleware work, with warm caches and right after a model run.

A service of the graph answers right after its model has run: the full model sweeps
megabytes of state and time histories through both cores' caches, and the
middleware's code and data (rclpy's conversion, rcl, Fast DDS, the introspection
event) are then cold.  This benchmark times the three middleware steps of a call on
one thread (no thread hand-over, as on the graph's model loop), with the
introspection events of the graph (CONTENTS), for an ``EvaluateDesign`` response of
one ride design:

- ``*_warm_us``: the steps back to back;
- ``*_after_model_us``: a single-design ride run (about 30 ms) before each response,
  as in the graph.

Prints the medians (us) over the calls.  The in-process optimisation has no such
steps, so whatever they cost cold is graph overhead in ``bench_graph.py``.  DDS
stays on loopback with a domain of its own (``bench_graph``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import bench_graph  # noqa: F401 - first: loopback DDS environment and malloc settings
import numpy as np

CALLS = 80


def main() -> int:
    import rclpy
    from rclpy.qos import qos_profile_services_default
    from rclpy.service_introspection import ServiceIntrospectionState
    from suspension_tuning_interfaces.srv import EvaluateDesign

    from suspension_tuning import evaluation
    from suspension_tuning.nodes._service_calls import ServiceCaller, wait_ready

    design = np.full((1, 2), 0.5)
    run = evaluation.evaluate('ride', design)  # compile / load the kernels
    rclpy.init()
    node = rclpy.create_node('bench_service_cold')
    service = node.create_service(EvaluateDesign, '/bench_service_cold/evaluate',
                                  lambda _, r: r)
    service.configure_introspection(node.get_clock(), qos_profile_services_default,
                                    ServiceIntrospectionState.CONTENTS)
    caller = ServiceCaller(node)
    client = caller.create_client(EvaluateDesign, service.srv_name)
    client.wait_for_service(timeout_sec=10.0)
    request = EvaluateDesign.Request(scenario='ride', n_vars=2, designs=[0.5, 0.5])
    response = EvaluateDesign.Response(
        success=True, n_designs=1, f=run.f.tolist(), n_constraints=run.g.shape[1],
        g=run.g.ravel().tolist(), metric_names=run.metric_names,
        metrics=run.metrics.ravel().tolist())

    def one_call(before_response: Callable[[], object]) -> tuple[float, ...] | None:
        """(request send, request take, response send) in s; None if nothing came."""
        t0 = time.perf_counter()
        future = client.call_async(request)
        t1 = time.perf_counter()
        wait_ready(node.context, 10**9, services=[service])
        with service.handle:
            t2 = time.perf_counter()
            taken, header = service.handle.service_take_request(EvaluateDesign.Request)
            t3 = time.perf_counter()
        if taken is None:  # not matched yet (the first calls): nothing to answer
            client.remove_pending_request(future)
            return None
        before_response()
        t4 = time.perf_counter()
        service.send_response(response, header)
        t5 = time.perf_counter()
        while not future.done():
            caller._take_responses([client], 1.0)
        return t1 - t0, t3 - t2, t5 - t4

    for _ in range(30):  # until the client and service have matched
        if one_call(lambda: None) is not None:
            break
    else:
        print('bench_service_cold: the request never arrived', file=sys.stderr)
        return 1
    for label, before_response in (('warm', lambda: None),
                                   ('after_model', lambda: evaluation.evaluate('ride', design))):
        times = [t for t in (one_call(before_response) for _ in range(CALLS)) if t]
        for name, column in zip(('request_send', 'request_take', 'response_send'),
                                np.array(times).T):
            print(f'{name}_{label}_us: {np.median(column) * 1e6:.1f}')
    caller.destroy()
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
