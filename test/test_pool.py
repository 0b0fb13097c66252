"""The pool of simulation workers: sharing by pull, hangs, models and namespaces.

Stand-in workers answer ``~/evaluate`` with f = the sum of a design's variables after
a set delay per design, each in a DDS participant of its own (an rclpy context), as a
worker process on another host would be; the pool under test is the one the
coordinator and the gradient evaluator use (:mod:`suspension_tuning.nodes._pool`).
A worker process killed mid-goal is in test_worker_pool.py and test_pool_hosts.py.
"""

from __future__ import annotations

import contextlib
import time

import numpy as np
import pytest
import yaml

from suspension_tuning.nodes._pool import matches

pytestmark = pytest.mark.ros


class StandIn:
    """A worker serving ``/<name>/evaluate`` (pings too) and a latched, live ``/<name>/model``."""

    #: The test session's ROS domain (set by the ``stand_in`` fixture).
    domain_id = 0

    def __init__(self, stack: contextlib.ExitStack, name: str, delay_s: float,
                 fingerprint: str = 'aaaa', namespace: str = '/') -> None:
        from rclpy.node import Node
        from std_msgs.msg import String
        from suspension_tuning_interfaces.srv import EvaluateDesign

        from suspension_tuning.nodes._pool import model_qos
        from suspension_tuning.testing import isolated_context, spinning_executor

        self.context = stack.enter_context(isolated_context(self.domain_id))
        self.node = Node(name, namespace=namespace, context=self.context)
        self.delay_s, self.fingerprint, self.designs = delay_s, fingerprint, 0
        self.paused = False  #: answer as a worker on its way to a new participant
        self.node.create_service(EvaluateDesign, '~/evaluate', self._evaluate)
        model = self.node.create_publisher(String, '~/model', model_qos(0.2))
        model.publish(String(data=yaml.safe_dump({'fingerprint': fingerprint})))
        stack.enter_context(spinning_executor(self.context, num_threads=1)).add(self.node)

    def _evaluate(self, request, response):
        response.model_fingerprint = self.fingerprint
        if self.paused:  # as full_vehicle_sim after a pause (nodes/_pause.py)
            from suspension_tuning.nodes._pause import PAUSED_ERROR

            response.success, response.error = False, PAUSED_ERROR + f'{self.node.get_name()}'
            return response
        if not request.scenario and not request.designs:  # a ping, as full_vehicle_sim
            response.success = True
            return response
        x = np.reshape(request.designs, (-1, request.n_vars))
        time.sleep(self.delay_s * len(x))
        self.designs += len(x)
        response.success, response.n_designs = True, len(x)
        response.f, response.n_constraints = x.sum(axis=1).tolist(), 0
        response.model_fingerprint = self.fingerprint
        return response


@pytest.fixture(autouse=True)
def _stand_in_domain(ros_domain_id):
    StandIn.domain_id = ros_domain_id


def make_pool(ros_context, executor, **options):
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.node import Node

    from suspension_tuning.nodes._pool import SimulationPool

    node = Node('pool_under_test', context=ros_context)
    executor.add(node)
    return SimulationPool(node, ReentrantCallbackGroup(), refresh_s=0.2, **options)


def wait_until(predicate, timeout_s=20.0):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, 'condition not reached'
        time.sleep(0.05)


def designs(n):
    return np.linspace(0.1, 0.9, 2 * n).reshape(n, 2)


def f_of(responses):
    return np.concatenate([r.f for r in responses])


def test_worker_names_fit_patterns_segment_by_segment():
    assert matches('/*', '/sim_0')
    assert not matches('/*', '/lab/sim_0')  # another namespace's graph
    assert matches('/lab/*', '/lab/sim_0') and not matches('/lab/*', '/sim_0')
    assert matches('/*/sim_*', '/hostb/sim_3') and not matches('/*/sim_*', '/hostb/other')


def test_a_slow_worker_takes_fewer_designs_and_single_designs_go_to_either(
        ros_context, executor):
    with contextlib.ExitStack() as stack:
        fast = StandIn(stack, 'fast', 0.01)
        slow = StandIn(stack, 'slow', 0.25)
        pool = make_pool(ros_context, executor)
        wait_until(lambda: pool.alive == ['/fast', '/slow'])
        assert pool.check_models() == 'aaaa'
        x = designs(24)
        # 24 designs, 2 workers, 3 pieces each: 6 pieces of 4 designs.  The slow one
        # (1 s a piece) has one piece while the fast one does the other five (0.04 s).
        np.testing.assert_array_equal(f_of(pool.evaluate('ride', 2, x)), x.sum(axis=1))
        assert (fast.designs, slow.designs) == (20, 4)
        # One-design requests go to the worker idle longest, not always the first.
        before = slow.designs
        for i in range(4):
            pool.evaluate('ride', 2, x[i:i + 1])
        assert slow.designs - before == 2 and fast.designs == 22


def test_a_hung_worker_is_left_after_design_timeout_and_its_designs_go_elsewhere(
        ros_context, executor):
    with contextlib.ExitStack() as stack:
        StandIn(stack, 'hung', 30.0)  # "hangs": 30 s per design
        healthy = StandIn(stack, 'healthy', 0.01)
        pool = make_pool(ros_context, executor, design_timeout_s=0.5)
        wait_until(lambda: len(pool.alive) == 2)
        pool.check_models()
        x = designs(4)
        start = time.monotonic()
        np.testing.assert_array_equal(f_of(pool.evaluate('ride', 2, x)), x.sum(axis=1))
        # The hung worker's piece (2 designs: 1 s allowed) is sent again after it; the
        # pool looks at pieces out once a second (POLL_S) when nothing else happens.
        assert time.monotonic() - start < 1.0 + 1.0 + 1.0
        assert healthy.designs == 4
        resent = [e for e in pool.events if e.kind == 'resent']
        assert resent and resent[0].worker == '/hung' and 'hung' in resent[0].text
        assert pool.alive == ['/healthy']


def test_a_worker_answering_paused_gets_its_piece_sent_elsewhere_and_no_more_until_it_answers(
        ros_context, executor):
    with contextlib.ExitStack() as stack:
        paused = StandIn(stack, 'paused', 0.01)
        other = StandIn(stack, 'other', 0.01)
        pool = make_pool(ros_context, executor)
        wait_until(lambda: pool.alive == ['/other', '/paused'])
        pool.check_models()
        paused.paused = True
        x = designs(8)
        # its answer "paused" is no answer: the piece goes to the other worker, the
        # batch's f is exact, and no error reaches the caller
        np.testing.assert_array_equal(f_of(pool.evaluate('ride', 2, x)), x.sum(axis=1))
        assert (paused.designs, other.designs) == (0, 8)
        resent = [e for e in pool.events if e.kind == 'resent']
        assert [e.worker for e in resent] == ['/paused'] and 'was paused' in resent[0].text
        pool.revive()  # the next goal: pinged again, and "paused" is no answer either
        time.sleep(2.0)  # pings at 0.5 s, 1 s and 2 s after the first
        assert pool.alive == ['/other']
        paused.paused = False  # its new participant answers
        wait_until(lambda: pool.alive == ['/other', '/paused'], 10.0)


def test_models_other_than_the_pools_are_left_out_or_refuse_when_listed(
        ros_context, executor):
    from suspension_tuning.model_identity import ModelMismatchError

    with contextlib.ExitStack() as stack:
        a = StandIn(stack, 'a', 0.0, 'aaaa')
        StandIn(stack, 'b', 0.0, 'bbbb')
        pool = make_pool(ros_context, executor)
        wait_until(lambda: len(pool.alive) == 2)
        with pytest.raises(ModelMismatchError, match='none is run by most'):
            pool.check_models()  # one each: which model is meant?
        StandIn(stack, 'c', 0.0, 'aaaa')
        wait_until(lambda: len(pool.models) == 3)
        assert pool.check_models() == 'aaaa'  # the model most workers run
        refused = [e.text for e in pool.events if e.kind == 'refused']
        assert refused == ['worker /b runs model bbbb, the pool runs model aaaa: not used '
                           '(another vehicle, FMU, mapping or configuration on that host)']
        pool.evaluate('ride', 2, designs(6))
        assert a.designs > 0 and pool.designs_by_worker()['/b'] == 0
        listed = make_pool(ros_context, executor, allow=['/a', '/b'])
        wait_until(lambda: len(listed.models) == 2)
        with pytest.raises(ModelMismatchError, match='/a: aaaa.*/b: bbbb'):
            listed.check_models()


def test_a_worker_in_another_namespace_is_not_pooled(ros_context, executor):
    with contextlib.ExitStack() as stack:
        StandIn(stack, 'sim_0', 0.0)
        StandIn(stack, 'sim_0', 0.0, namespace='/other_graph')
        pool = make_pool(ros_context, executor)
        wait_until(lambda: pool.alive == ['/sim_0'])
        time.sleep(0.5)  # a few more looks at the graph
        assert pool.alive == ['/sim_0'] and '/other_graph/sim_0' not in pool.workers
