"""Run a command under strace and list every address it sent network packets to.

Usage: ``python scripts/check_loopback.py -- <command> [args...]``

Traces ``sendto``, ``sendmsg``, ``sendmmsg`` and ``connect`` of the command and all
its children (``strace -f``), then prints the count of calls per destination address
and ``non_loopback_destinations: N``.  Exit status 1 if any IPv4 destination lies
outside 127.0.0.0/8 or any IPv6 destination is not ::1, 2 if strace is missing.
DDS discovery must stay on loopback here (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).
"""

from __future__ import annotations

import collections
import ipaddress
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ADDRESS = re.compile(r'inet_pton\(AF_INET6, "([^"]+)"|inet_addr\("([^"]+)"\)')


def destinations(trace_text: str) -> collections.Counter:
    """Count destination IP addresses in an strace log of send/connect calls."""
    found: collections.Counter = collections.Counter()
    for line in trace_text.splitlines():
        for v6, v4 in ADDRESS.findall(line):
            found[v6 or v4] += 1
    return found


def is_loopback(address: str) -> bool:
    """Tell whether an address is in 127.0.0.0/8 or is ::1 (IPv4-mapped included)."""
    ip = ipaddress.ip_address(address)
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    return ip.is_loopback


def trace(command: list[str]) -> tuple[int, collections.Counter]:
    """Run ``command`` under strace; return its exit code and the destinations."""
    if shutil.which('strace') is None:
        print('strace not found (Debian package strace)', file=sys.stderr)
        sys.exit(2)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / 'trace.txt'
        result = subprocess.run(['strace', '-f', '-qq', '--seccomp-bpf', '-e',
                                 'trace=sendto,sendmsg,sendmmsg,connect',
                                 '-o', str(log), *command], check=False)
        return result.returncode, destinations(log.read_text())


def main(argv: list[str]) -> int:
    """Trace the command after ``--`` and report its network destinations."""
    if '--' in argv:
        argv = argv[argv.index('--') + 1:]
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    returncode, found = trace(argv)
    bad = {address: n for address, n in found.items() if not is_loopback(address)}
    for address, n in sorted(found.items()):
        print(f'destination {address}: {n} calls')
    print(f'command_exit_code: {returncode}')
    print(f'send_calls_with_address: {sum(found.values())}')
    print(f'non_loopback_destinations: {len(bad)}')
    return 1 if bad or returncode else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
