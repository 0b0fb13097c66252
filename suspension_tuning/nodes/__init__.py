"""Thin rclpy adapters over the physics and the optimiser.

Importing this package limits glibc's malloc to one arena (see
:func:`suspension_tuning.nodes._memory.share_malloc_arena`): the models run in
executor threads, and per-thread arenas give their tens of megabytes back to the
kernel after every run, so that every run page-faults them in again.
"""

from suspension_tuning.nodes._memory import share_malloc_arena

share_malloc_arena()
