"""Record ``bags/sample`` again: the 4-variable ride run of ``make demo`` (``make sample-bag``).

With ``--mixed`` it records ``bags/sample_mixed`` instead: one closed-loop run of the
mixed scenario (the Belgian paving, then the double lane change, the valves switched by
the valve_controller node step-locked over ROS) at the centre of the 2-variable design
space, as ``tune --scenario mixed --evaluate`` records it, with the telemetry at every
``--telemetry-decimation``-th history sample (default 5: 50 Hz) to keep the bag small.

Runs the demo for the ride scenario only (``python -m suspension_tuning.demo
--scenarios ride``) into a temporary folder, so the recording is exactly what a user's
``make demo`` records, then replaces the files of ``bags/sample`` with that run's
``metadata.yaml`` and ``.mcap`` (the plots stay out: they are made from the bag).
Before replacing anything it checks the new bag: complete, a ride run with its
result, and, where node and the npm packages of ``make setup`` are installed, every
message decoded by Foxglove's own parser and CDR reader.

DDS stays on loopback (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``); the domain is
``ROS_DOMAIN_ID`` from the environment (``make`` sets one).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / 'bags' / 'sample'
SAMPLE_MIXED = ROOT / 'bags' / 'sample_mixed'


def record(work: Path) -> Path:
    """Run the demo's ride optimisation into ``work``; return the run's bag folder."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    command = [sys.executable, '-m', 'suspension_tuning.demo', '--scenarios', 'ride',
               '--bags', str(work)]
    subprocess.run(command, check=True, env=env, cwd=ROOT)
    runs = sorted(p for p in work.iterdir() if p.is_dir() and p.name.endswith('_ride'))
    if len(runs) != 1:
        raise RuntimeError(f'expected one ride bag in {work}, found {[p.name for p in runs]}')
    return runs[0]


def record_mixed(work: Path, decimation: int) -> Path:
    """One recorded closed-loop mixed run through the graph into ``work``; its bag folder."""
    import time

    import rclpy
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.graph import SpinningGraph, build_nodes
    from suspension_tuning.nodes._spin import wait_future

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    rclpy.init()
    nodes = build_nodes(workers=1, record=True, overrides={
        'recorder': [Parameter('output_dir', value=str(work))],
        'full_vehicle_sim': [Parameter('telemetry_decimation', value=decimation)]})
    recorder = nodes[-1]
    client = Node('sample_bag')
    graph = SpinningGraph(nodes, [client])
    try:
        action = ActionClient(client, Optimise, '/coordinator/optimise')
        if not action.wait_for_server(timeout_sec=30):
            raise RuntimeError('the graph did not come up')
        handle = wait_future(action.send_goal_async(Optimise.Goal(
            scenario='mixed', n_vars=2, gradient_source='evaluate')), 60)
        result = wait_future(handle.get_result_async(), 600).result
        if not result.success:
            raise RuntimeError(f'the mixed run failed: {result.message}')
        deadline = time.monotonic() + 60
        while not recorder.session.closed_bags:
            if time.monotonic() > deadline:
                raise RuntimeError('the recorder did not close the run\'s bag')
            time.sleep(0.1)
        return recorder.session.closed_bags[-1]
    finally:
        graph.shutdown()
        rclpy.try_shutdown()


def verify(bag: Path, scenario: str = 'ride') -> str:
    """Check a recorded bag; return a one-line account, or raise RuntimeError."""
    from suspension_tuning.bag import foxglove
    from suspension_tuning.inspect_bag import summary

    info = summary(bag)
    if not info['complete'] or info['run_config'].get('scenario') != scenario:
        raise RuntimeError(f'{bag}: not a complete {scenario} run ({info["stop_reason"]})')
    if not info.get('optimum'):
        raise RuntimeError(f'{bag}: no /optimisation/result in the bag')
    reason = foxglove.unavailable_reason()
    if reason:
        return f'{info["message_count"]} messages; Foxglove decoding not checked: {reason}'
    [result] = foxglove.check([bag])
    failed = {c['topic']: c['error'] for c in result['channels'] if c['error']}
    if not result['ok']:
        raise RuntimeError(f'{bag}: Foxglove cannot decode {failed}')
    decoded = sum(c['decoded'] for c in result['channels'])
    return (f'{info["message_count"]} messages; Foxglove decoded {decoded} on '
            f'{len(result["channels"])} channels')


def replace_sample(bag: Path, target: Path) -> list[Path]:
    """Replace the files of ``target`` with the bag's metadata.yaml and .mcap."""
    files = [bag / 'metadata.yaml', *sorted(bag.glob('*.mcap'))]
    target.mkdir(parents=True, exist_ok=True)
    for old in target.iterdir():
        if old.is_file():
            old.unlink()
    copied = []
    for source in files:
        shutil.copy2(source, target / source.name)
        copied.append(target / source.name)
    return copied


def main(argv: list[str] | None = None) -> int:
    """Record, check and install the sample bag; return the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--target', type=Path, default=None,
                        help='folder to replace (default bags/sample, or bags/sample_mixed)')
    parser.add_argument('--mixed', action='store_true',
                        help='record the closed-loop mixed run into bags/sample_mixed')
    parser.add_argument('--telemetry-decimation', type=int, default=5,
                        help='--mixed: publish every n-th history sample (default 5)')
    args = parser.parse_args(argv)
    args.target = args.target or (SAMPLE_MIXED if args.mixed else SAMPLE)
    with tempfile.TemporaryDirectory(prefix='sample_bag_') as work:
        try:
            if args.mixed:
                bag = record_mixed(Path(work), args.telemetry_decimation)
                account = verify(bag, 'mixed')
            else:
                bag = record(Path(work))
                account = verify(bag)
        except (subprocess.CalledProcessError, RuntimeError, ValueError) as exc:
            print(f'regenerate_sample_bag: {exc}; {args.target} left as it was', file=sys.stderr)
            return 1
        copied = replace_sample(bag, args.target)
    size_kb = sum(p.stat().st_size for p in copied) / 1024
    print(f'{args.target}: {", ".join(p.name for p in copied)} ({size_kb:.0f} KiB); {account}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
