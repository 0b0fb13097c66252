"""Decode bags with Foxglove's own libraries, as Foxglove opens them (needs node).

``tools/foxglove/check_bag.mjs`` reads each MCAP file with ``@mcap/core``, parses each
``ros2msg`` schema with ``@foxglove/rosmsg`` (``ros2: true``: dependency sections are
found by exact name) and each ``ros2idl`` one (a service's event) with
``@foxglove/ros2idl-parser``, and decodes every message with
``@foxglove/rosmsg2-serialization``.  ``make setup`` installs those packages (pinned in
``tools/foxglove/package-lock.json``) into ``tools/foxglove/node_modules``.

Usage::

    python -m suspension_tuning.bag.foxglove BAG [BAG ...]

prints one line per channel (topic, schema, messages decoded of recorded, first
error) and exits 0 when every message of every bag decoded, 1 otherwise, 2 when the
check cannot run (no node, packages not installed, unreadable file).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from suspension_tuning.bag.reader import mcap_file

#: Folder of the node script and its package.json / package-lock.json.
TOOL_DIR = Path(__file__).resolve().parents[2] / 'tools' / 'foxglove'
SCRIPT = TOOL_DIR / 'check_bag.mjs'
#: Oldest node major version the packages support (their package.json "engines").
NODE_MAJOR = 20
#: Packages the script imports (installed by ``make setup``).
PACKAGES = (
    '@mcap/core',
    '@foxglove/rosmsg',
    '@foxglove/ros2idl-parser',
    '@foxglove/rosmsg2-serialization',
    '@foxglove/wasm-zstd',
    '@foxglove/wasm-lz4',
)


def unavailable_reason() -> str:
    """Why the check cannot run here ('' when it can)."""
    node = shutil.which('node')
    if node is None:
        return f'node is not installed (the Foxglove decoding check needs node >= {NODE_MAJOR})'
    try:
        version = subprocess.run([node, '--version'], capture_output=True, text=True,
                                 timeout=30, check=True).stdout.strip()
        major = int(version.lstrip('v').split('.')[0])
    except (OSError, subprocess.SubprocessError, ValueError):
        return f'{node} --version does not answer'
    if major < NODE_MAJOR:
        return f'node {version} is too old (@foxglove/rosmsg2-serialization needs >= {NODE_MAJOR})'
    if not SCRIPT.is_file():
        return f'{SCRIPT} is missing'
    missing = [p for p in PACKAGES if not (TOOL_DIR / 'node_modules' / p).is_dir()]
    if missing:
        return (
            f'npm packages {", ".join(missing)} are not installed in {TOOL_DIR}/node_modules '
            '(run make setup)'
        )
    return ''


def check(
    bags: Sequence[str | os.PathLike[str]],
    messages: bool = False,
    timeout_s: float = 600.0,
) -> list[dict[str, Any]]:
    """Decode every message of the bags with Foxglove's parser and CDR reader.

    Parameters
    ----------
    bags : sequence of str or Path
        Bag folders or ``.mcap`` files.
    messages : bool
        Also return the decoded messages (``channels[k]['decoded_messages']``: log time,
        ns, and the message as plain JSON values).
    timeout_s : float
        Longest time the node process may take, s.

    Returns
    -------
    list of dict
        Per file: ``path``, ``complete`` (footer reached), ``ok`` (every schema parsed
        and every message decoded) and ``channels`` (topic, schema_name, messages,
        decoded, trailing_bytes, error).

    Raises
    ------
    RuntimeError
        If the check cannot run (see :func:`unavailable_reason`) or a file cannot be read.
    """
    reason = unavailable_reason()
    if reason:
        raise RuntimeError(reason)
    files = [str(mcap_file(b)) for b in bags]
    args = ['node', str(SCRIPT), *(['--messages'] if messages else []), *files]
    done = subprocess.run(args, capture_output=True, text=True, timeout=timeout_s, check=False)
    if done.returncode not in (0, 1):
        raise RuntimeError(
            f'Foxglove check failed (exit {done.returncode}): {done.stderr.strip()}'
        )
    return list(json.loads(done.stdout)['files'])


def main(argv: list[str] | None = None) -> int:
    """Command line: print the check of each bag; return the exit status."""
    parser = argparse.ArgumentParser(
        prog='python -m suspension_tuning.bag.foxglove', description=__doc__.split('\n')[0]
    )
    parser.add_argument('bags', nargs='+', help='bag folders or .mcap files')
    args = parser.parse_args(argv)
    try:
        results = check(args.bags)
    except (RuntimeError, ValueError, OSError, subprocess.TimeoutExpired) as exc:
        print(f'foxglove check: {exc}', file=sys.stderr)
        return 2
    for result in results:
        decoded = sum(c['decoded'] for c in result['channels'])
        total = sum(c['messages'] for c in result['channels'])
        print(f'{result["path"]}: {decoded} of {total} messages decoded on '
              f'{len(result["channels"])} channels{"" if result["complete"] else " (incomplete)"}')
        for channel in result['channels']:
            status = channel['error'] or 'ok'
            print(f'  {channel["topic"]} [{channel["schema_name"]}] '
                  f'{channel["decoded"]}/{channel["messages"]}: {status}')
    return 0 if all(r['ok'] for r in results) else 1


if __name__ == '__main__':
    sys.exit(main())
