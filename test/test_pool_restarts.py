"""Workers that come back: restarted under their name, or resumed after a stop.

Stand-in worker processes (test/fixtures/stand_in_worker.py: answers at once, a live
``~/model`` with a 0.5 s liveliness lease, as full_vehicle_sim) are killed and restarted
at once, or stopped (SIGSTOP) mid-batch and continued (SIGCONT).  The pool under test
is the coordinator's (:mod:`suspension_tuning.nodes._pool`).  The restart waits past the
dead process's DDS participant lease (Fast DDS: 20 s by default), when the graph
forgets it, before the next batch; a stop lasts a few seconds (past the worker's
liveliness lease) or past the participant lease, when DDS may not match the continued
process again: the worker then joins the graph as a new participant
(:mod:`suspension_tuning.nodes._pause`).
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from suspension_tuning.testing import wait_until

pytestmark = pytest.mark.ros

STAND_IN = Path(__file__).parent / 'fixtures' / 'stand_in_worker.py'
#: Fast DDS's default participant lease, s: a dead process stays on the graph this long.
PARTICIPANT_LEASE_S = 20.0


def start(name: str, log_dir: Path) -> subprocess.Popen:
    log = open(log_dir / f'{name}.log', 'a')  # noqa: SIM115 - closed with the process
    return subprocess.Popen([sys.executable, str(STAND_IN), name], stdout=log,
                            stderr=subprocess.STDOUT)


@pytest.fixture
def pool_and_workers(ros_context, executor, tmp_path):
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.node import Node

    from suspension_tuning.nodes._pool import SimulationPool

    workers = {name: start(name, tmp_path) for name in ('sim_0', 'sim_1')}
    node = Node('pool_restarts', context=ros_context)
    executor.add(node)
    pool = SimulationPool(node, ReentrantCallbackGroup(), allow=['/sim_0', '/sim_1'],
                          design_timeout_s=5.0, refresh_s=0.2)
    try:
        assert wait_until(lambda: pool.alive == ['/sim_0', '/sim_1'], 60.0), 'workers not up'
        yield pool, workers, tmp_path
    finally:
        for process in workers.values():
            if process.poll() is None:
                process.send_signal(signal.SIGCONT)
                process.send_signal(signal.SIGINT)
                try:
                    process.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    process.kill()


def _state(pool) -> str:
    """The events and sim_1's state as the pool sees it, for a failure's message."""
    w = pool.workers['/sim_1']
    return (f'{list(pool.events)}; sim_1: alive {w.alive}, gone {w.gone}, failed '
            f'{w.failed!r}, ready {w.ready}, ping out {w.ping is not None}, evaluate '
            f'matched {w.client.service_is_ready()}, refused {w.refused!r}')


def _events(pool, kind: str, since: float) -> list:
    return [e for e in list(pool.events)
            if e.kind == kind and e.worker == '/sim_1' and e.time_s >= since]


def _stopped(pid: int) -> bool:
    """Every thread of process ``pid`` stopped (state T in /proc).

    A SIGSTOP stops a process once one of its threads takes the signal: on a loaded
    machine the thread woken for it may wait for a core while another thread of the
    process still answers a request.
    """
    def state(task: Path) -> str:
        stat = (task / 'stat').read_text()
        return stat[stat.rindex(')') + 2]  # the field after the command's name

    return all(state(task) in 'Tt' for task in Path(f'/proc/{pid}/task').iterdir())


def _batch_designs_of_sim_1(pool) -> int:
    """Designs sim_1 answers of one 12-design batch (checked against f = sum of x)."""
    before = pool.designs_by_worker()['/sim_1']
    x = np.linspace(0.1, 0.9, 24).reshape(12, 2)
    pool.check_models()
    responses = pool.evaluate('ride', 2, x)
    np.testing.assert_array_equal(np.concatenate([r.f for r in responses]), x.sum(axis=1))
    return pool.designs_by_worker()['/sim_1'] - before


def test_a_worker_killed_and_restarted_at_once_is_taken_back_past_the_old_lease(
        pool_and_workers):
    pool, workers, log_dir = pool_and_workers
    killed_at = time.monotonic()
    workers['sim_1'].send_signal(signal.SIGKILL)
    workers['sim_1'].wait(timeout=10)
    workers['sim_1'] = start('sim_1', log_dir)
    assert wait_until(lambda: _events(pool, 'back', killed_at), 30.0), list(pool.events)
    # past the dead process's participant lease, when the graph forgets it
    time.sleep(max(0.0, killed_at + PARTICIPANT_LEASE_S + 3.0 - time.monotonic()))
    assert pool.alive == ['/sim_0', '/sim_1'], list(pool.events)
    # pieces go out to the free worker idle longest: sim_1 gets some of 6 pieces
    assert _batch_designs_of_sim_1(pool) > 0, list(pool.events)
    assert len(_events(pool, 'back', killed_at)) == 1, list(pool.events)


@pytest.mark.parametrize('stop_s', [
    6.0,  # a debugger's break: past the worker's liveliness lease, within its DDS lease
    PARTICIPANT_LEASE_S + 3.0,  # a laptop's lid: past the lease, a new participant
], ids=['within_dds_lease', 'past_dds_lease'])
def test_a_worker_stopped_mid_batch_and_continued_is_taken_back(pool_and_workers, stop_s):
    pool, workers, log_dir = pool_and_workers
    stopped_at = time.monotonic()
    workers['sim_1'].send_signal(signal.SIGSTOP)
    assert wait_until(lambda: _stopped(workers['sim_1'].pid), 5.0), 'sim_1 not stopped'
    # A batch at once: sim_1 takes a piece and does not answer; its liveliness ends
    # within the lease, and the piece goes to sim_0 (f checked against sum of x).
    assert _batch_designs_of_sim_1(pool) == 0
    assert _events(pool, 'lost', stopped_at) and _events(pool, 'resent', stopped_at)
    time.sleep(max(0.0, stopped_at + stop_s - time.monotonic()))
    resumed_at = time.monotonic()
    workers['sim_1'].send_signal(signal.SIGCONT)
    assert wait_until(lambda: _events(pool, 'back', resumed_at), 30.0), _state(pool)
    # rediscovered by the graph, it answers a ping before it gets a piece
    assert wait_until(lambda: pool.alive == ['/sim_0', '/sim_1'], 30.0), _state(pool)
    assert _batch_designs_of_sim_1(pool) > 0, _state(pool)
    assert len(_events(pool, 'back', stopped_at)) == 1, _state(pool)
    said = (log_dir / 'sim_1.log').read_text()
    # PAUSE_S (10 s) is the bound between the two cases: a new participant past it only
    assert ('joins the graph again as a new DDS participant' in said) == (stop_s > 10.0), said
