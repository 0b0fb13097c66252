"""Record ``bags/sample`` again: the 4-variable ride run of ``make demo`` (``make sample-bag``).

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


def verify(bag: Path) -> str:
    """Check a recorded bag; return a one-line account, or raise RuntimeError."""
    from suspension_tuning.bag import foxglove
    from suspension_tuning.inspect_bag import summary

    info = summary(bag)
    if not info['complete'] or info['run_config'].get('scenario') != 'ride':
        raise RuntimeError(f'{bag}: not a complete ride run ({info["stop_reason"]})')
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
    parser.add_argument('--target', type=Path, default=SAMPLE, help='folder to replace')
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix='sample_bag_') as work:
        try:
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
