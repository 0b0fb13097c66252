"""Simulation workers on other hosts: three network namespaces joined by a bridge.

Each namespace is a host of its own with one address on the bridge's subnet:
``w1`` and ``w2`` run a simulation worker each, ``coord`` runs ``graph --workers 0``
(coordinator, gradient evaluator, valve controller, recorder) and ``tune``.  DDS
discovers by unicast between the three addresses only (``ROS_STATIC_PEERS``), over
UDP only (no shared memory between the "hosts"); nothing reaches the machine's own
interfaces.  The namespaces need root (``ip netns``); elsewhere the test skips and
says why.

One session of goals checks what a pool of hosts must do: designs go to both workers;
a worker killed mid-goal is noticed within ``worker_loss_timeout_s`` and the goal ends
with the bits of the goal without the kill; a worker started later is used; a worker
running another model is left out with a warning naming both fingerprints; SIGTERM
stops the coordinator's graph within 5 s under a running goal, its bag complete.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.ros

BIN = Path(sys.prefix) / 'bin'
#: The pools' loss bound, s (config/graph.yaml's default worker_loss_timeout_s).
LOSS_S = 2.0
#: Allowance on top of it for the pool's reaction and a loaded CI machine, s.
SLACK_S = 1.5
#: 8 calibration samples instead of 16: same code path, half the first goal's runs.
SAMPLES = 8


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(['ip', *args], capture_output=True, text=True, check=check)


def _no_netns_reason() -> str:
    if shutil.which('ip') is None:
        return 'no `ip` command (iproute2)'
    if os.geteuid() != 0:
        return 'network namespaces need root (ip netns add); this test runs as root in CI'
    probe = f'stprobe{os.getpid() % 100000}'
    made = _ip('netns', 'add', probe, check=False)
    if made.returncode:
        return f'ip netns add failed: {made.stderr.strip()}'
    _ip('netns', 'del', probe, check=False)
    return ''


class Hosts:
    """Three namespaces (coord, w1, w2) on a bridge in coord; processes started in them."""

    def __init__(self, tmp: Path, domain_id: int) -> None:
        tag = os.getpid() % 1000
        self.prefix = f'st{tag}'
        self.subnet = f'10.213.{tag % 250}'
        self.names = {host: f'{self.prefix}_{host}' for host in ('coord', 'w1', 'w2')}
        self.address = {'coord': f'{self.subnet}.1', 'w1': f'{self.subnet}.2',
                        'w2': f'{self.subnet}.3'}
        self.tmp = tmp
        self.processes: list[subprocess.Popen] = []
        self.env = {
            'PATH': os.environ.get('PATH', ''), 'HOME': os.environ.get('HOME', str(tmp)),
            'ROS_DOMAIN_ID': str(domain_id), 'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp',
            'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
            'ROS_STATIC_PEERS': ';'.join(self.address.values()),
            'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4',  # no shared memory across "hosts"
            'AMENT_PREFIX_PATH': os.environ.get('AMENT_PREFIX_PATH', sys.prefix),
            'ROS_LOG_DIR': str(tmp / 'roslog'), 'PYTHONUNBUFFERED': '1',
            'NUMBA_CACHE_DIR': os.environ.get('NUMBA_CACHE_DIR', ''),
            # The suite's start-up discovery window (test/conftest.py).
            'SUSPENSION_TUNING_DISCOVERY_WINDOW_S': os.environ.get(
                'SUSPENSION_TUNING_DISCOVERY_WINDOW_S', ''),
        }
        self.env = {k: v for k, v in self.env.items() if v}

    def up(self) -> None:
        coord = self.names['coord']
        for name in self.names.values():
            _ip('netns', 'add', name)
        bridge = f'{self.prefix}br'
        _ip('-n', coord, 'link', 'add', bridge, 'type', 'bridge')
        for host in ('w1', 'w2'):
            outer, inner = f'{self.prefix}{host}p', f'{self.prefix}{host}e'
            _ip('link', 'add', outer, 'type', 'veth', 'peer', 'name', inner)
            _ip('link', 'set', outer, 'netns', coord)
            _ip('link', 'set', inner, 'netns', self.names[host])
            _ip('-n', coord, 'link', 'set', outer, 'master', bridge)
            _ip('-n', coord, 'link', 'set', outer, 'up')
            _ip('-n', self.names[host], 'addr', 'add', f'{self.address[host]}/24', 'dev', inner)
            _ip('-n', self.names[host], 'link', 'set', inner, 'up')
        _ip('-n', coord, 'addr', 'add', f'{self.address["coord"]}/24', 'dev', bridge)
        _ip('-n', coord, 'link', 'set', bridge, 'up')
        for name in self.names.values():
            _ip('-n', name, 'link', 'set', 'lo', 'up')
        self._wait_links_up([(coord, bridge), *((self.names[host], f'{self.prefix}{host}e')
                                                 for host in ('w1', 'w2'))])

    @staticmethod
    def _wait_links_up(links: list[tuple[str, str]], timeout_s: float = 10.0) -> None:
        """Wait until every (namespace, device) has carrier (operstate UP).

        The bridge gets carrier only once a port's veth peer is up, a moment after
        ``ip link set up``.  Fast DDS picks its unicast interfaces when a participant
        is created: a process started before that never sends to its static peers
        (the same holds for a node started before a host's network is up: systemd's
        ``After=network-online.target``, docs/distributed.md).
        """
        deadline = time.monotonic() + timeout_s
        for namespace, device in links:
            while True:
                shown = json.loads(_ip('-j', '-n', namespace, 'link', 'show', 'dev',
                                       device).stdout)
                if shown and shown[0].get('operstate') == 'UP':
                    break
                assert time.monotonic() < deadline, (
                    f'{device} in {namespace} not up within {timeout_s} s: {shown}')
                time.sleep(0.05)

    def down(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.kill()
                process.wait(timeout=10)
        for name in self.names.values():
            _ip('netns', 'del', name, check=False)

    def start(self, host: str, label: str, *command: str, **kwargs) -> subprocess.Popen:
        """Start ``command`` in ``host``'s namespace, its output into ``<label>.log``."""
        log = open(self.tmp / f'{label}.log', 'w')  # noqa: SIM115 - closed with the process
        process = subprocess.Popen(['ip', 'netns', 'exec', self.names[host], *command],
                                   env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                   cwd=self.tmp, **kwargs)
        self.processes.append(process)
        return process

    def worker(self, host: str, name: str, *params: str) -> subprocess.Popen:
        return self.start(host, name, str(BIN / 'full_vehicle_sim'), '--ros-args',
                          '-r', f'__node:={name}', '-p', 'telemetry_decimation:=50', *params)

    def log(self, label: str) -> str:
        path = self.tmp / f'{label}.log'
        return path.read_text() if path.exists() else ''

    def logs(self) -> str:
        return '\n'.join(f'--- {p.name}\n{p.read_text()[-2500:]}'
                         for p in sorted(self.tmp.glob('*.log')))

    def tune(self, label: str, on_line=None, timeout_s: float = 300.0) -> list[tuple[float, str]]:
        """Run ``tune`` in coord; its output lines with their arrival time (monotonic)."""
        process = subprocess.Popen(
            ['ip', 'netns', 'exec', self.names['coord'], str(BIN / 'tune'),
             '--scenario', 'ride', '--n-vars', '2', '--gradient', 'simplified'],
            env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            cwd=self.tmp)
        lines = []
        timer = threading.Timer(timeout_s, process.kill)
        timer.start()
        try:
            for line in process.stdout:
                lines.append((time.monotonic(), line.rstrip('\n')))
                if on_line is not None:
                    on_line(line)
            process.wait()
        finally:
            timer.cancel()
        (self.tmp / f'{label}.log').write_text('\n'.join(text for _, text in lines))
        assert process.returncode == 0, self.logs()
        return lines


def wait_for(predicate, timeout_s: float, what: str, hosts: Hosts) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, f'{what} within {timeout_s} s\n{hosts.logs()}'
        time.sleep(0.2)


def bag_summary(bags: Path, count: int) -> dict:
    """``inspect_bag --json`` of the ``count``-th bag (1-based) under ``bags``."""
    paths = sorted(p for p in bags.iterdir() if p.is_dir())
    assert len(paths) >= count, paths
    run = subprocess.run([str(BIN / 'inspect_bag'), '--json', str(paths[count - 1])],
                         capture_output=True, text=True, check=True)
    return json.loads(run.stdout)


def designs_by_worker(summary: dict) -> dict[str, int]:
    """Designs each worker received in one run, from its evaluate service events."""
    return {name[:-len('/evaluate')]: counts['designs']
            for name, counts in summary['evaluations']['services'].items()
            if name.endswith('/evaluate')}


@pytest.fixture
def hosts(tmp_path, ros_domain_id):
    reason = _no_netns_reason()
    if reason:
        pytest.skip(f'no test across hosts: {reason}')
    made = Hosts(tmp_path, ros_domain_id)
    try:
        made.up()
        yield made
    finally:
        made.down()


def test_hosts_share_designs_survive_a_kill_take_a_late_worker_and_refuse_another_model(
        hosts, tmp_path):
    bags = tmp_path / 'bags'
    params = tmp_path / 'graph.yaml'
    params.write_text(yaml.safe_dump({
        '/**/coordinator': {'ros__parameters': {'calibration_samples': SAMPLES}},
        '/**/recorder': {'ros__parameters': {'output_dir': str(bags)}},
        '/**/gradient_evaluator': {'ros__parameters': {
            'calibration_dir': str(tmp_path / 'calibration')}}}))
    hosts.worker('w1', 'sim_1')
    hosts.worker('w2', 'sim_2')
    graph = hosts.start('coord', 'graph', str(BIN / 'graph'), '--workers', '0', '--ros-args',
                        '--params-file', str(params))
    wait_for(lambda: all(f'worker /{w} joined' in hosts.log('graph')
                         for w in ('sim_1', 'sim_2')), 120.0,
             'the coordinator-side graph did not see both remote workers', hosts)

    # 1. A goal over both hosts: designs on both workers.
    plain = hosts.tune('tune_plain')
    first = bag_summary(bags, 1)
    assert first['optimum']['success'], first['optimum']['message']
    used = designs_by_worker(first)
    assert used.get('/sim_1', 0) > 0 and used.get('/sim_2', 0) > 0, used
    assert not any('workers:' in text for _, text in plain)  # nothing joined or lost

    # 2. sim_2 killed after the first iteration: noticed within the bound, same result.
    killed_at: list[float] = []

    def kill_after_first_iteration(line: str) -> None:
        if line.startswith('iteration') and not killed_at:
            killed_at.append(time.monotonic())
            os.kill(hosts.processes[1].pid, signal.SIGKILL)

    kill = hosts.tune('tune_kill', kill_after_first_iteration)
    assert killed_at, 'no iteration to kill the worker after'
    lost = [(t, text) for t, text in kill if 'worker /sim_2 lost' in text]
    assert lost, hosts.logs()
    # The feedback line reaches tune after the coordinator noticed the loss.
    assert lost[0][0] - killed_at[0] <= LOSS_S + SLACK_S, (lost[0][0] - killed_at[0], lost)
    second = bag_summary(bags, 2)
    assert second['optimum']['x'] == first['optimum']['x']  # bit for bit
    assert second['optimum']['f'] == first['optimum']['f']

    # 3. A worker started later, on the host that lost its own, is used.
    hosts.worker('w2', 'sim_3')
    wait_for(lambda: 'worker /sim_3 joined' in hosts.log('graph'), 120.0,
             'the late worker sim_3 was not seen', hosts)
    hosts.tune('tune_late')
    assert designs_by_worker(bag_summary(bags, 3)).get('/sim_3', 0) > 0

    # 4. A worker with another model (another integrator: another fingerprint) is left
    # out with a warning naming both fingerprints, and the goal runs on the others.
    hosts.worker('w1', 'sim_4', '-p', 'integrator:=variable_step')
    wait_for(lambda: 'worker /sim_4 joined' in hosts.log('graph'), 120.0,
             'the other-model worker sim_4 was not seen', hosts)
    other = hosts.tune('tune_other_model')
    refused = [text for _, text in other if 'worker /sim_4 runs model' in text]
    fingerprint = first['run_config']['model_fingerprint']
    assert refused and fingerprint in refused[0] and 'not used' in refused[0], other
    fourth = bag_summary(bags, 4)
    assert '/sim_4' not in designs_by_worker(fourth)
    assert fourth['optimum']['f'] == first['optimum']['f']

    # 5. SIGTERM to the coordinator's graph under a running goal: out within 5 s, and
    # the cut run's bag complete.
    stopped: list[float] = []

    def terminate_after_first_iteration(line: str) -> None:
        if line.startswith('iteration') and not stopped:
            stopped.append(time.monotonic())
            graph.send_signal(signal.SIGTERM)

    process = subprocess.Popen(
        ['ip', 'netns', 'exec', hosts.names['coord'], str(BIN / 'tune'), '--scenario', 'ride',
         '--n-vars', '2', '--gradient', 'full'],
        env=hosts.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in process.stdout:
        terminate_after_first_iteration(line)
        if stopped:
            break
    assert stopped, hosts.logs()
    graph.wait(timeout=5.0 + SLACK_S)
    assert time.monotonic() - stopped[0] <= 5.0 + SLACK_S
    process.kill()
    process.wait(timeout=10)
    last = sorted(p for p in bags.iterdir() if p.is_dir())[-1]
    assert (last / 'metadata.yaml').is_file(), sorted(last.iterdir())
    assert bag_summary(bags, 5)['complete']
