"""glibc malloc settings of the node processes: one arena, no give-back of the heap.

The full model allocates about 1.3 MB of channel arrays per design and run (40 MB for
a 30-design calibration batch), and its metrics several megabytes of temporaries.
Memory that glibc hands back to the kernel is page-faulted and zeroed again by the
next run.  Two glibc habits did that here:

- **Per-thread arenas.**  The nodes run the models in executor threads, and glibc
  gives each thread an arena of its own, whose heaps are unmapped when they empty.
  Measured on a 30-design ride batch in an executor thread: 2,500-3,700 page faults
  and 0.1-0.2 s of system time per run (about 20 % of the run), against none on the
  main thread.  ``M_ARENA_MAX = 1`` keeps one arena for all threads.
- **A moving mmap threshold and heap trimming.**  Blocks above the mmap threshold
  (dynamic, 128 kB to 32 MB) get pages of their own that go back on free, and the
  heap top is trimmed above twice that threshold.  Which run paid for it depended on
  the order of earlier runs and threads: with one arena, alternate graph and
  in-process runs still faulted about 1,430 times (5.6 MB, 30 ms of system time and
  60-70 ms of wall time) per 30-design batch, one or the other
  (``benchmarks/bench_graph.py``).  A fixed ``M_MMAP_THRESHOLD`` of 32 MB and
  ``M_TRIM_THRESHOLD`` of 1 GB keep the model's blocks in the heap, which then stays
  at its high-water mark (a few hundred megabytes for the largest batches): after the
  first run, 0-3 faults per batch.

The arena limit only takes effect before a second thread has allocated (glibc fixes
the arena count at the first extra arena), so the nodes package applies the settings
on import, before rclpy starts DDS threads.  They are a no-op outside glibc; a
setting the environment already makes (``MALLOC_ARENA_MAX``,
``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_``) stands.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

#: ``mallopt`` parameters of glibc's <malloc.h>.
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD, M_ARENA_MAX = -1, -3, -8

#: (parameter, value, environment variable that overrides it).  32 MB is the largest
#: mmap threshold glibc accepts on 64-bit (HEAP_MAX_SIZE / 2).
SETTINGS = ((M_ARENA_MAX, 1, 'MALLOC_ARENA_MAX'),
            (M_MMAP_THRESHOLD, 32 << 20, 'MALLOC_MMAP_THRESHOLD_'),
            (M_TRIM_THRESHOLD, 1 << 30, 'MALLOC_TRIM_THRESHOLD_'))


def tune_malloc() -> dict[str, bool]:
    """Apply :data:`SETTINGS` through ``mallopt``.

    Returns
    -------
    dict
        Environment variable name -> True when this call set that parameter (False:
        left to the environment, or not glibc).
    """
    try:
        libc = ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6')
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return {env: False for _, _, env in SETTINGS}
    return {env: env not in os.environ and bool(mallopt(param, value))
            for param, value, env in SETTINGS}
