"""Stopping ``graph`` with SIGINT and SIGTERM: crashes, hangs and incomplete bags.

Starts ``graph`` (one worker, the recorder on, its bags in a temporary directory) again
and again and stops it with a signal in one of four states, in turn:

- ``start``: idle, just after start (the coordinator's action has just appeared);
- ``idle``: idle for ``--idle-s`` seconds (default 30);
- ``goal``: a goal running (``tune`` printed its first iteration);
- ``cancelled``: after a cancelled goal (``tune`` interrupted, its cancel answered).

A stop is a *crash* when ``graph`` ends on a signal (e.g. SIGSEGV, return code -11) or
with a traceback, a *hang* when it has not ended ``--hang-s`` seconds (default 20) after
the signal (it is then killed), and a bag is *incomplete* when its ``.mcap`` lacks the
MCAP footer (the recorder did not close it).  ``graph`` is documented to exit 0 on both
signals.  Prints ``name: value`` lines::

    .venv/bin/python benchmarks/bench_stops.py              # 20 SIGINT, 10 SIGTERM
    .venv/bin/python benchmarks/bench_stops.py --sigint 4 --sigterm 4 --idle-s 10

``--nodes``: the graph as separate node processes (as ``ros2 run`` starts them, each with
its ``config/*.yaml``), and each node in turn gets the signal, idle (``start``) and with a
goal running (``goal``); then the others are stopped by SIGINT.  A node is documented to
exit 0 on both signals; every bag must be complete::

    .venv/bin/python benchmarks/bench_stops.py --nodes

Every process runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and the
``ROS_DOMAIN_ID`` of the environment (default 140).
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

BIN = Path(sys.executable).parent
STATES = ('start', 'idle', 'goal', 'cancelled')
MCAP_MAGIC = b'\x89MCAP0\r\n'
#: A short goal: 2 variables, full-model gradients (no calibration), few iterations.
GOAL = ['--scenario', 'ride', '--n-vars', '2', '--gradient', 'full', '--max-iterations', '3']


class Lines:
    """A process's output lines, read by a thread, that one can wait for."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        self._changed = threading.Condition()
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream) -> None:
        for line in stream:
            with self._changed:
                self.lines.append(line)
                self._changed.notify_all()
        with self._changed:
            self.lines.append(None)  # end of output
            self._changed.notify_all()

    def wait_for(self, text: str, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        with self._changed:
            while True:
                if any(line is not None and text in line for line in self.lines):
                    return True
                if (self.lines and self.lines[-1] is None) or time.monotonic() > deadline:
                    return False
                self._changed.wait(0.2)

    def text(self) -> str:
        return ''.join(line for line in self.lines if line is not None)


def spawn(command: list[str], env: dict[str, str]) -> tuple[subprocess.Popen, Lines]:
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    return process, Lines(process.stdout)


def wait_for_action(env: dict[str, str], timeout_s: float) -> bool:
    """Whether ``/coordinator/optimise`` appears within ``timeout_s`` s (a tiny rclpy client)."""
    probe = ('import rclpy, sys\n'
             'from rclpy.action import ActionClient\n'
             'from suspension_tuning_interfaces.action import Optimise\n'
             'rclpy.init(); node = rclpy.create_node("stop_probe")\n'
             'ok = ActionClient(node, Optimise, "/coordinator/optimise")'
             f'.wait_for_server(timeout_sec={timeout_s})\n'
             'node.destroy_node(); rclpy.try_shutdown(); sys.exit(0 if ok else 1)\n')
    return subprocess.run([sys.executable, '-c', probe], env=env,
                          timeout=timeout_s + 30).returncode == 0


def one_stop(state: str, signum: int, env: dict[str, str], args) -> dict[str, object]:
    """Start ``graph``, bring it into ``state``, send ``signum``; what happened."""
    bags = Path(tempfile.mkdtemp(prefix='stops_'))
    graph, out = spawn([str(BIN / 'graph'), '--ros-args', '-p', f'output_dir:={bags}'], env)
    note = ''
    tune = None
    try:
        if not wait_for_action(env, 60):
            note = 'graph did not come up'
        elif state == 'idle':
            time.sleep(args.idle_s)
        elif state in ('goal', 'cancelled'):
            tune, tune_out = spawn([str(BIN / 'tune'), *GOAL], env)
            if not tune_out.wait_for('iteration', 300):
                note = 'no iteration printed'
            elif state == 'cancelled':
                tune.send_signal(signal.SIGINT)
                try:
                    tune.wait(60)
                except subprocess.TimeoutExpired:
                    note = 'tune did not end after its cancel'
                time.sleep(1.0)
        sent = time.monotonic()
        graph.send_signal(signum)
        try:
            rc = graph.wait(args.hang_s)
            hang = False
        except subprocess.TimeoutExpired:
            hang = True
            graph.kill()
            rc = graph.wait()
        stop_s = time.monotonic() - sent
    finally:
        if tune is not None and tune.poll() is None:
            tune.kill()
            tune.wait()
    out.wait_for('\0', 5)  # the rest of the output
    text = out.text()
    crash = (not hang and rc != 0) or 'Traceback' in text or 'Segmentation' in text
    mcaps = sorted(bags.rglob('*.mcap'))
    incomplete = [str(p) for p in mcaps if not p.read_bytes().endswith(MCAP_MAGIC)]
    return {'state': state, 'signal': signal.Signals(signum).name, 'rc': rc, 'hang': hang,
            'crash': crash, 'bags': len(mcaps), 'incomplete': incomplete,
            'stop_s': stop_s, 'note': note, 'output': text}


#: The nodes of a graph started one process each, with their parameter files.
NODES = {'full_vehicle_sim': 'graph.yaml', 'gradient_evaluator': 'graph.yaml',
         'valve_controller': 'valve_controller.yaml', 'coordinator': 'graph.yaml',
         'recorder': 'recorder.yaml'}


def one_node_stop(target: str, state: str, signum: int, env: dict[str, str],
                  args) -> dict[str, object]:
    """Send ``signum`` to ``target`` alone, in a graph of one process per node in ``state``.

    Returns what happened to ``target``; the other nodes then get SIGINT.
    """
    config = Path(__file__).resolve().parents[1] / 'config'
    bags = Path(tempfile.mkdtemp(prefix='stops_'))
    processes = {}
    for name, params in NODES.items():
        command = [str(BIN / name), '--ros-args', '--params-file', str(config / params)]
        if name == 'recorder':
            command += ['-p', f'output_dir:={bags}']
        processes[name] = spawn(command, env)
    note, tune = '', None
    try:
        if not wait_for_action(env, 60):
            note = 'the graph did not come up'
        elif state == 'goal':
            tune, tune_out = spawn([str(BIN / 'tune'), *GOAL], env)
            if not tune_out.wait_for('iteration', 300):
                note = 'no iteration printed'
        process, out = processes[target]
        sent = time.monotonic()
        process.send_signal(signum)
        try:
            rc = process.wait(args.hang_s)
            hang = False
        except subprocess.TimeoutExpired:
            hang = True
            process.kill()
            rc = process.wait()
        stop_s = time.monotonic() - sent
    finally:
        if tune is not None and tune.poll() is None:
            tune.send_signal(signal.SIGINT)
            try:
                tune.wait(30)
            except subprocess.TimeoutExpired:
                tune.kill()
                tune.wait()
        others_hung = []
        for other, _ in processes.values():
            if other.poll() is None:
                other.send_signal(signal.SIGINT)
        for name, (other, _) in processes.items():
            try:
                other.wait(args.hang_s)
            except subprocess.TimeoutExpired:
                others_hung.append(name)
                other.kill()
                other.wait()
    out.wait_for('\0', 5)
    text = out.text()
    crash = (not hang and rc != 0) or 'Traceback' in text or 'Segmentation' in text
    mcaps = sorted(bags.rglob('*.mcap'))
    incomplete = [str(p) for p in mcaps if not p.read_bytes().endswith(MCAP_MAGIC)]
    if others_hung:
        note += f' (after it, {", ".join(others_hung)} did not end on SIGINT: killed)'
    return {'others_hung': others_hung, 'state': state,
            'signal': signal.Signals(signum).name, 'rc': rc, 'hang': hang, 'crash': crash,
            'bags': len(mcaps), 'incomplete': incomplete,
            'stop_s': stop_s, 'note': note.strip(), 'output': text, 'node': target}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--sigint', type=int, default=20, help='stops by SIGINT')
    parser.add_argument('--sigterm', type=int, default=10, help='stops by SIGTERM')
    parser.add_argument('--idle-s', type=float, default=30.0, help="the 'idle' state's wait, s")
    parser.add_argument('--hang-s', type=float, default=20.0,
                        help='a graph not ended this long after the signal hangs, s')
    parser.add_argument('--nodes', action='store_true',
                        help='each node of a one-process-per-node graph in turn, idle and '
                             'mid-goal, SIGINT and SIGTERM (instead of graph)')
    args = parser.parse_args(argv)
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
           'ROS_DOMAIN_ID': os.environ.get('ROS_DOMAIN_ID', '140'),
           'PYTHONUNBUFFERED': '1'}
    if args.nodes:
        plan = [(node, state, signum) for node in NODES for state in ('start', 'goal')
                for signum in (signal.SIGINT, signal.SIGTERM)]
    else:
        plan = ([('graph', STATES[i % 4], signal.SIGINT) for i in range(args.sigint)]
                + [('graph', STATES[i % 4], signal.SIGTERM) for i in range(args.sigterm)])
    results = []
    for i, (target, state, signum) in enumerate(plan):
        result = (one_stop(state, signum, env, args) if target == 'graph'
                  else one_node_stop(target, state, signum, env, args))
        results.append(result)
        flag = ('CRASH ' if result['crash'] else '') + ('HANG ' if result['hang'] else '') + (
            'INCOMPLETE ' if result['incomplete'] else '')
        print(f'# {i + 1}/{len(plan)} {target} {result["signal"]} {state}: rc {result["rc"]}, '
              f'{result["stop_s"]:.1f} s, {result["bags"]} bag(s) {flag}{result["note"]}',
              flush=True)
        if flag:
            print('#   ' + result['output'][-3000:].replace('\n', '\n#   '), flush=True)
    for name in ('SIGINT', 'SIGTERM'):
        mine = [r for r in results if r['signal'] == name]
        key = name.lower()
        print(f'stops_{key}: {len(mine)}')
        print(f'stops_{key}_crashes: {sum(r["crash"] for r in mine)}')
        print(f'stops_{key}_hangs: {sum(r["hang"] for r in mine)}')
        print(f'stops_{key}_bags: {sum(r["bags"] for r in mine)}')
        print(f'stops_{key}_incomplete_bags: {sum(len(r["incomplete"]) for r in mine)}')
        if mine:
            print(f'stops_{key}_slowest_s: {max(r["stop_s"] for r in mine):.1f}')
    if args.nodes:  # the other nodes, stopped by SIGINT after each target
        print(f'stops_other_nodes_hangs: {sum(len(r["others_hung"]) for r in results)}')
    print(f'stops_not_reached_state: '
          f'{sum(bool(r["note"]) and not r.get("others_hung") for r in results)}')
    bad = sum(r['crash'] or r['hang'] or bool(r['incomplete']) or bool(r.get('others_hung'))
              for r in results)
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
