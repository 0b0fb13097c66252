"""The node processes' malloc setting (suspension_tuning.nodes._memory)."""

import os
import subprocess
import sys

import pytest

PROBE = ('from suspension_tuning.nodes._memory import share_malloc_arena; '
         'print(share_malloc_arena())')


def _probe(env: dict) -> str:
    return subprocess.run([sys.executable, '-c', PROBE], env=env, capture_output=True,
                          text=True, check=True).stdout.strip()


@pytest.mark.skipif(not os.path.exists('/lib/x86_64-linux-gnu/libc.so.6')
                    and not os.path.exists('/lib/aarch64-linux-gnu/libc.so.6'),
                    reason='glibc only')
def test_one_malloc_arena_is_set_through_mallopt():
    env = {k: v for k, v in os.environ.items() if k != 'MALLOC_ARENA_MAX'}
    # mallopt returns 1 on success (mallopt(3)).
    assert _probe(env) == 'True'


def test_an_arena_count_from_the_environment_is_left_alone():
    assert _probe({**os.environ, 'MALLOC_ARENA_MAX': '4'}) == 'False'
