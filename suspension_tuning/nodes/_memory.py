"""One malloc arena for the node processes (glibc ``mallopt(M_ARENA_MAX, 1)``).

The full model allocates about 1.3 MB of channel arrays per design and run (40 MB for
a 30-design calibration batch).  On the main thread glibc keeps such memory in its
heap and the next run reuses it.  The nodes run the models in executor threads, and
glibc gives each thread an arena of its own, whose heaps are unmapped when they empty:
every run then page-faults and zeroes its memory again.  Measured on a 30-design ride
batch in an executor thread: 2,500-3,700 page faults and 0.1-0.2 s of system time per
run (about 20 % of the run), against none on the main thread; with one arena, none in
either (``benchmarks/bench_graph.py``).  One arena costs some lock contention between
threads that allocate at the same time, which the nodes rarely do.

The limit only takes effect before a second thread has allocated (glibc fixes the
arena count at the first extra arena), so the nodes package applies it on import,
before rclpy starts DDS threads.  It is a no-op outside glibc, and when the
environment already sets ``MALLOC_ARENA_MAX`` (whose value then stands).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

#: ``M_ARENA_MAX`` of glibc's <malloc.h>.
M_ARENA_MAX = -8


def share_malloc_arena() -> bool:
    """Limit glibc malloc to one arena; True when the limit was set here."""
    if 'MALLOC_ARENA_MAX' in os.environ:
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6')
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(M_ARENA_MAX, 1))
