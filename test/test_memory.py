"""The node processes' malloc settings (suspension_tuning.nodes._memory)."""

import json
import os
import subprocess
import sys

import pytest

PROBE = ('import json; from suspension_tuning.nodes._memory import tune_malloc; '
         'print(json.dumps(tune_malloc()))')
GLIBC = (os.path.exists('/lib/x86_64-linux-gnu/libc.so.6')
         or os.path.exists('/lib/aarch64-linux-gnu/libc.so.6'))
MALLOC_VARS = ('MALLOC_ARENA_MAX', 'MALLOC_MMAP_THRESHOLD_', 'MALLOC_TRIM_THRESHOLD_')


def _probe(**extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in MALLOC_VARS}
    out = subprocess.run([sys.executable, '-c', PROBE], env={**env, **extra},
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out)


@pytest.mark.skipif(not GLIBC, reason='glibc only')
def test_one_arena_and_fixed_thresholds_are_set_through_mallopt():
    # mallopt returns 1 on success (mallopt(3)); 32 MB is glibc's largest mmap
    # threshold on 64-bit, so it is accepted.
    assert _probe() == {name: True for name in MALLOC_VARS}


@pytest.mark.skipif(not GLIBC, reason='glibc only')
def test_a_setting_from_the_environment_is_left_alone():
    settings = _probe(MALLOC_ARENA_MAX='4', MALLOC_TRIM_THRESHOLD_='65536')
    assert settings == {'MALLOC_ARENA_MAX': False, 'MALLOC_MMAP_THRESHOLD_': True,
                        'MALLOC_TRIM_THRESHOLD_': False}
