"""DDS traffic of our ROS processes goes to loopback only (strace on send calls)."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'scripts'))
from check_loopback import destinations, is_loopback  # noqa: E402

pytestmark = pytest.mark.ros


def test_address_parser_recognises_loopback_and_others():
    log = ('123 sendto(5, "x", 1, 0, {sa_family=AF_INET, sin_port=htons(7400), '
           'sin_addr=inet_addr("127.0.0.1")}, 16) = 1\n'
           '124 sendmsg(6, {msg_name={sa_family=AF_INET, sin_port=htons(7400), '
           'sin_addr=inet_addr("239.255.0.1")}, msg_namelen=16}, 0) = 1\n')
    found = destinations(log)
    assert found == {'127.0.0.1': 1, '239.255.0.1': 1}
    assert is_loopback('127.0.0.1') and is_loopback('127.8.9.10') and is_loopback('::1')
    assert not is_loopback('239.255.0.1')  # the Fast DDS multicast group
    assert not is_loopback('192.168.1.20')


@pytest.mark.skipif(shutil.which('strace') is None, reason='strace (Debian) not installed')
def test_ros_probe_sends_only_to_loopback():
    result = subprocess.run(
        [sys.executable, str(ROOT / 'scripts' / 'check_loopback.py'), '--',
         sys.executable, str(ROOT / 'test' / 'fixtures' / 'loopback_probe.py')],
        capture_output=True, text=True, timeout=120, check=False)
    assert 'non_loopback_destinations: 0' in result.stdout, result.stdout + result.stderr
    count = int(result.stdout.split('send_calls_with_address: ')[1].split()[0])
    assert count > 0, 'no traffic traced: the check would be vacuous'
    assert result.returncode == 0, result.stdout + result.stderr
