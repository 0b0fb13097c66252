"""Thin rclpy adapters over the physics and the optimiser.

Importing this package sets glibc's malloc to one arena that keeps its heap (see
:func:`suspension_tuning.nodes._memory.tune_malloc`): the models run in executor
threads, and otherwise glibc gives their tens of megabytes back to the kernel after
a run, so that the next run page-faults them in again.
"""

from suspension_tuning.nodes._memory import tune_malloc

tune_malloc()
