"""Simulation workers in processes of their own: batch speed-up, loss detection, call cost.

Starts four ``full_vehicle_sim`` processes (``sim_0`` ... ``sim_3``, started as a user
starts a worker, each with ``NUMBA_NUM_THREADS=1`` so that one worker uses one core),
and a pool (``nodes._pool.SimulationPool``, the coordinator's and the gradient
evaluator's) in this process on a small node spun by a MultiThreadedExecutor.  The
workers are found on the graph by name (``sim_worker_pattern``): ``/sim_[0]`` is one
worker, ``/sim_[01]`` two, ``/sim_[0-3]`` four.  Every worker first runs one and two
designs untimed (numba's compiled kernels load from the cache).  Prints ``name: value``
lines:

- ``calibration_wall_s_{1,2,4}_workers``: wall time of one eq. 25 calibration batch (the
  16 designs of the 2-variable ride calibration, ``calibration_designs(2, 16)``, each a
  30 s run on the sett paving) through a pool of 1, 2 or 4 worker processes with the
  default ``pieces_per_worker`` (3): median of ``--repeats`` rounds, the pools in turn
  within a round (the order rotating) so that the machine's drift of speed falls on
  all of them.  Four processes on this 2-core machine show what oversubscription costs.
- ``pool_speedup_calibration_2_workers``: the 1-worker median over the 2-worker median
  (target >= 1.7 on 2 cores; the default cut makes 6 pieces of 3, 3, 3, 3, 2 and 2
  designs, which fall 8 and 8 on two equal workers); ``..._pairs_min`` and
  ``..._pairs_max``: the lowest and highest ratio of two runs of the same round;
  ``..._4_pieces``: the same with ``pieces_per_worker`` 4 (8 pieces of 2 designs, 8
  designs on each worker; ``calibration_wall_s_2_workers_4_pieces`` is its wall time),
  a fourth pool in each round.
- ``other_users_cores_during_calibration``: the cores the machine spent on other
  processes meanwhile (/proc; the machine is shared): with one core taken the 2-worker
  figure falls to about 1; ``other_users_cores_per_round``: the same per round.
- ``same_result_bits``: every pool returns the same bits for every design.
- ``remote_call_overhead_s``: a one-design ride request through the pool (the time
  ``pool.evaluate`` takes) minus the worker's own ``wall_time_s`` in the response, median
  of 20: what a remote design costs beyond its simulation (transport, serialisation,
  executors on both sides, the pool's bookkeeping); ``remote_call_overhead_direct_s``:
  the same with a bare service client, without the pool.
- ``worker_loss_detection_s``: time from a worker's SIGKILL (``time.monotonic()`` just
  before the signal) to the pool's 'resent' event for that worker (its ``time_s``), the
  killed worker holding a piece of a 96-design batch on two workers (the kill comes
  0.3 s after the piece was sent; a piece takes about 1 s); median and max over
  ``--kills`` kills, a new worker (``sim_1_r1``, ``sim_1_r2``...: a pool of pattern
  ``/sim_[01]*``) started and warmed up in the killed one's place between them;
  ``worker_loss_lost_event_s``: the same up to the 'lost' event (DDS liveliness).  The
  workers offer a liveliness lease of 0.5 s (``liveliness_lease_s``), the pool requests
  2 s (``worker_loss_timeout_s``): target <= 3 s.  ``pieces_declared_hung``: pieces the
  pools sent again because a living worker did not answer within ``design_timeout_s``
  (5 s per design here; 0 expected).  The new worker takes a new name (a worker
  restarted under its name is taken back once it answers a ping: test_worker_pool.py).

DDS stays on loopback with a domain of its own; the worker processes are stopped with
SIGINT at the end and the shared-memory segments of the killed ones cleaned.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', '92')

import numpy as np  # noqa: E402

WORKERS = ('sim_0', 'sim_1', 'sim_2', 'sim_3')
# The pools: sim_worker_pattern and pieces_per_worker (default 3) per label.
POOLS = {'1_workers': ('/sim_[0]', 3), '2_workers': ('/sim_[01]', 3),
         '4_workers': ('/sim_[0-3]', 3), '2_workers_4_pieces': ('/sim_[01]', 4)}
SCENARIO, N_VARS, SAMPLES = 'ride', 2, 16  # the 2-variable ride calibration
LOSS_BATCH = 96  # designs: pieces of 16 (about 1 s each) on two workers
KILL_AFTER_S = 0.3  # the kill this long after the victim's piece went out
LEASE_S, LOSS_TIMEOUT_S = 0.5, 2.0  # liveliness_lease_s, worker_loss_timeout_s (defaults)
STARTUP_S = 180.0  # a worker's start (imports, model check) on a loaded machine
# A piece unanswered this long per design is sent elsewhere (a design takes 0.06 s on
# one core, a few times that on a loaded machine; the product's default is 360 s).
DESIGN_TIMEOUT_S = 5.0


class Workers:
    """The worker processes, started as ``python -m ...full_vehicle_sim`` with one thread."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.processes: dict[str, subprocess.Popen] = {}

    def start(self, name: str) -> None:
        env = dict(os.environ, NUMBA_NUM_THREADS='1')
        log = open(self.log_dir / f'{name}.log', 'a')  # noqa: SIM115 - the child keeps it
        self.processes[name] = subprocess.Popen(
            [sys.executable, '-m', 'suspension_tuning.nodes.full_vehicle_sim', '--ros-args',
             '-r', f'__node:={name}', '-p', f'liveliness_lease_s:={LEASE_S}'],
            env=env, stdout=log, stderr=subprocess.STDOUT)

    def kill(self, name: str) -> float:
        """SIGKILL worker ``name``; the time.monotonic() just before the signal."""
        killed_at = time.monotonic()
        self.processes[name].send_signal(signal.SIGKILL)
        self.processes[name].wait(timeout=10)
        return killed_at

    def stop(self) -> None:
        for process in self.processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for process in self.processes.values():
            try:
                process.wait(timeout=15)
            except subprocess.TimeoutExpired:
                process.kill()
        tool = Path(sys.prefix) / 'bin' / 'fastdds'  # the killed workers' segments
        if tool.exists():
            subprocess.run([str(tool), 'shm', 'clean'], capture_output=True, timeout=60,
                           check=False)

    def logs(self) -> str:
        return '\n'.join(f'--- {path.name}\n{path.read_text()[-2000:]}'
                         for path in sorted(self.log_dir.glob('*.log')))


def busy_s(pids: list[int]) -> tuple[float, float]:
    """CPU seconds the machine has run, and those of processes ``pids`` (Linux /proc).

    Their difference over a phase is what other users' work took meanwhile (in cores
    when divided by the phase's wall time): the machine is shared.
    """
    tick = os.sysconf('SC_CLK_TCK')
    fields = [int(v) for v in Path('/proc/stat').read_text().split('\n')[0].split()[1:]]
    machine = (sum(fields[:8]) - fields[3] - fields[4]) / tick  # all but idle and iowait
    own = 0.0
    for pid in pids:
        try:
            stat = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
        except FileNotFoundError:
            continue
        own += (int(stat[11]) + int(stat[12])) / tick  # utime, stime
    return machine, own


class Bench:
    """A node holding one pool per size, spun by a MultiThreadedExecutor in a thread."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.callback_groups import ReentrantCallbackGroup
        from rclpy.executors import MultiThreadedExecutor
        from rclpy.node import Node

        from suspension_tuning.nodes._pool import SimulationPool

        rclpy.init()
        self.node = Node('bench_pool')
        self.group = ReentrantCallbackGroup()
        self.pools = {label: SimulationPool(self.node, self.group, pattern=pattern,
                                            design_timeout_s=DESIGN_TIMEOUT_S,
                                            loss_timeout_s=LOSS_TIMEOUT_S,
                                            pieces_per_worker=pieces)
                      for label, (pattern, pieces) in POOLS.items()}
        # The loss runs': sim_0, sim_1 and the workers started in a killed one's place.
        self.pools['loss'] = self.loss_pool = SimulationPool(
            self.node, self.group, pattern='/sim_[01]*', design_timeout_s=DESIGN_TIMEOUT_S,
            loss_timeout_s=LOSS_TIMEOUT_S)
        self.clients: dict[str, object] = {}  # bare evaluate clients per worker
        self.executor = MultiThreadedExecutor()
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def wait_alive(self, label: str, names: list[str], workers: Workers) -> None:
        """Wait until pool ``label`` uses exactly the workers ``names``."""
        want = sorted(f'/{name}' for name in names)
        deadline = time.monotonic() + STARTUP_S
        while self.pools[label].alive != want:
            if time.monotonic() > deadline:
                raise RuntimeError(f'workers {want} not up within {STARTUP_S:g} s (pool '
                                   f'sees {self.pools[label].alive})\n{workers.logs()}')
            time.sleep(0.1)

    def warm_up(self, name: str) -> None:
        """One and two designs on worker ``name``, untimed (numba's kernels load)."""
        for n in (1, 2):
            self.direct_call(name, np.full((n, N_VARS), 0.5))

    def direct_call(self, name: str, x: np.ndarray, timeout_s: float = 120.0):
        """An evaluate request to worker ``name`` from a bare client; the response."""
        from suspension_tuning_interfaces.srv import EvaluateDesign

        from suspension_tuning.nodes._spin import wait_future

        if name not in self.clients:
            self.clients[name] = self.node.create_client(
                EvaluateDesign, f'/{name}/evaluate', callback_group=self.group)
            self.clients[name].wait_for_service(timeout_sec=STARTUP_S)
        future = self.clients[name].call_async(EvaluateDesign.Request(
            scenario=SCENARIO, n_vars=N_VARS, designs=x.ravel().tolist()))
        try:
            response = wait_future(future, timeout_s)
        except TimeoutError:
            self.clients[name].remove_pending_request(future)
            raise
        if not response.success:
            raise RuntimeError(f'{name}: {response.error}')
        return response

    def close(self) -> None:
        import rclpy

        self.executor.shutdown(timeout_sec=5.0)
        self.node.destroy_node()
        rclpy.try_shutdown()


def calibration(bench: Bench, workers: Workers, repeats: int) -> None:
    """Wall times of the calibration batch through each pool; prints the figures."""
    from suspension_tuning.optim.simplified_gradient import calibration_designs

    x, _, _ = calibration_designs(N_VARS, SAMPLES)
    times: dict[str, list[float]] = {label: [] for label in POOLS}
    answers: dict[str, np.ndarray] = {}
    for label in POOLS:
        bench.pools[label].check_models()  # as a goal does first: the model pinned
    labels = list(POOLS)
    pids = [os.getpid(), *(p.pid for p in workers.processes.values())]
    machine_0, own_0, start_0 = *busy_s(pids), time.monotonic()
    rounds = []  # other users' cores in each round
    for repeat in range(repeats):
        round_0 = (*busy_s(pids), time.monotonic())
        turn = repeat % len(labels)
        for label in labels[turn:] + labels[:turn]:
            start = time.monotonic()
            responses = bench.pools[label].evaluate(SCENARIO, N_VARS, x)
            times[label].append(time.monotonic() - start)
            answers[label] = np.concatenate([np.asarray(r.f) for r in responses])
        round_1 = busy_s(pids)
        rounds.append(((round_1[0] - round_0[0]) - (round_1[1] - round_0[1]))
                      / (time.monotonic() - round_0[2]))
    machine_1, own_1 = busy_s(pids)
    others = ((machine_1 - machine_0) - (own_1 - own_0)) / (time.monotonic() - start_0)
    print(f'other_users_cores_during_calibration: {max(0.0, others):.2f}')
    print('other_users_cores_per_round: ' + ' '.join(f'{max(0.0, c):.2f}' for c in rounds))
    for label in POOLS:
        print(f'calibration_wall_s_{label}: {np.median(times[label]):.3f}')
    for label in POOLS:
        print(f'calibration_runs_s_{label}: ' + ' '.join(f'{t:.3f}' for t in times[label]))
    print(f'calibration_designs: {len(x)}')
    print(f'calibration_repeats_median_of: {repeats}')
    same = all(np.array_equal(answers['1_workers'], answers[label]) for label in POOLS)
    print(f'same_result_bits: {same}')
    one = np.median(times['1_workers'])
    print('pool_speedup_calibration_2_workers_4_pieces: '
          f'{one / np.median(times["2_workers_4_pieces"]):.3f}')
    pairs = np.array(times['1_workers']) / np.array(times['2_workers'])
    print(f'pool_speedup_calibration_2_workers_pairs_min: {pairs.min():.3f}')
    print(f'pool_speedup_calibration_2_workers_pairs_max: {pairs.max():.3f}')
    print(f'pool_speedup_calibration_2_workers: {one / np.median(times["2_workers"]):.3f}')


def call_overhead(bench: Bench, calls: int = 20) -> None:
    """One-design round trips through the pool and bare, minus the worker's own time."""
    x = np.full((1, N_VARS), 0.5)
    pooled, direct = [], []
    for _ in range(calls):
        start = time.monotonic()
        [response] = bench.pools['1_workers'].evaluate(SCENARIO, N_VARS, x)
        pooled.append(time.monotonic() - start - response.wall_time_s)
        start = time.monotonic()
        response = bench.direct_call('sim_0', x)
        direct.append(time.monotonic() - start - response.wall_time_s)
    print(f'remote_call_overhead_s: {np.median(pooled):.4f}')
    print(f'remote_call_overhead_direct_s: {np.median(direct):.4f}')


def in_background(pool, x: np.ndarray) -> tuple[threading.Event, list[BaseException]]:
    """``pool.evaluate`` of ``x`` in a thread: an event set when it ends, and its error."""
    done = threading.Event()
    failure: list[BaseException] = []

    def run() -> None:
        try:
            pool.evaluate(SCENARIO, N_VARS, x)
        except BaseException as error:  # noqa: BLE001 - reported by the main thread
            failure.append(error)
        finally:
            done.set()

    threading.Thread(target=run, daemon=True).start()
    return done, failure


def loss_detection(bench: Bench, workers: Workers, kills: int) -> None:
    """SIGKILL sim_1 while it holds a piece; time to the pool's 'resent' event."""
    pool = bench.loss_pool
    x = np.random.default_rng(0).uniform(0.0, 1.0, (LOSS_BATCH, N_VARS))
    victim = 'sim_1'
    bench.wait_alive('loss', ['sim_0', victim], workers)
    resent, lost = [], []
    attempts = 0
    while len(resent) < kills:
        attempts += 1
        if attempts > 2 * kills:
            raise RuntimeError(f'the killed worker held no piece in {attempts - 1} tries')
        started = time.monotonic()
        done, failure = in_background(pool, x)
        while pool.workers[f'/{victim}'].last_sent_s < started:  # its first piece goes out
            if done.is_set():
                break
            time.sleep(0.005)
        time.sleep(KILL_AFTER_S)
        killed_at = workers.kill(victim)
        done.wait(600.0)
        if failure:
            raise RuntimeError(f'the batch failed: {failure[0]}\n{workers.logs()}')
        events = [e for e in list(pool.events)
                  if e.worker == f'/{victim}' and e.time_s > killed_at]
        times = {e.kind: e.time_s for e in reversed(events)  # the first of each kind
                 if e.kind == 'lost' or (e.kind == 'resent' and ' lost (' in e.text)}
        if 'resent' in times:
            resent.append(times['resent'] - killed_at)
            lost.append(times.get('lost', np.nan) - killed_at)
        victim = f'sim_1_r{attempts}'  # a new worker in its place for the next kill
        workers.start(victim)
        bench.wait_alive('loss', ['sim_0', victim], workers)
        bench.warm_up(victim)
    print(f'worker_loss_kills: {len(resent)}')
    print('worker_loss_detection_runs_s: ' + ' '.join(f'{t:.3f}' for t in resent))
    print(f'worker_loss_lost_event_s: {np.nanmedian(lost):.3f}')
    print(f'worker_loss_detection_max_s: {max(resent):.3f}')
    print(f'worker_loss_detection_s: {np.median(resent):.3f}')
    hung = [e for one in bench.pools.values() for e in one.events
            if e.kind == 'resent' and 'hung' in e.text]
    print(f'pieces_declared_hung: {len(hung)}')


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeats', type=int, default=9,
                        help='calibration rounds to take the median over (default 9)')
    parser.add_argument('--kills', type=int, default=5,
                        help='workers killed for the detection time (default 5)')
    args = parser.parse_args(argv)
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix='bench_pool_') as tmp:
        workers = Workers(Path(tmp))
        bench = None
        try:
            for name in WORKERS:
                workers.start(name)
            bench = Bench()
            bench.wait_alive('4_workers', list(WORKERS), workers)
            for name in WORKERS:
                bench.warm_up(name)
            print(f'load_average_1min: {os.getloadavg()[0]:.2f}')
            print(f'cpu_cores: {os.cpu_count()}')
            calibration(bench, workers, args.repeats)
            call_overhead(bench)
            loss_detection(bench, workers, args.kills)
            print(f'load_average_1min_end: {os.getloadavg()[0]:.2f}')
        finally:
            if bench is not None:
                bench.close()
            workers.stop()
    print(f'bench_wall_s: {time.monotonic() - started:.1f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
