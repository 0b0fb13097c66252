"""The full model's pool of recording arrays (suspension_tuning.vehicle._buffers)."""

import numpy as np

from suspension_tuning.vehicle._buffers import MIN_POOLED_BYTES, ArrayPool

BIG = (4, 36, 1000)  # 1.15 MB of float64, above MIN_POOLED_BYTES (1 MiB)


def test_an_array_nobody_holds_is_handed_out_again():
    pool = ArrayPool()
    first = pool.empty(BIG)
    address = first.__array_interface__['data'][0]
    del first
    again = pool.empty(BIG)
    assert again.__array_interface__['data'][0] == address
    assert (pool.allocated, pool.reused) == (1, 1)


def test_an_array_with_a_live_view_is_not_handed_out():
    pool = ArrayPool()
    first = pool.empty(BIG)
    view = first[:, 0]  # a history kept by a result refers to its recording array
    del first
    second = pool.empty(BIG)
    assert not np.shares_memory(second, view)
    assert (pool.allocated, pool.reused) == (2, 0)


def test_small_arrays_come_from_numpy_and_are_not_kept():
    pool = ArrayPool()
    small = pool.empty((10, 10))
    assert small.nbytes < MIN_POOLED_BYTES
    assert pool.nbytes == 0


def test_the_pool_forgets_the_oldest_arrays_beyond_its_size():
    one = 8 * int(np.prod(BIG))
    pool = ArrayPool(max_bytes=2 * one)
    held = [pool.empty(BIG) for _ in range(3)]  # all in use: three allocations
    assert pool.allocated == 3
    assert pool.nbytes == 2 * one  # the oldest one is no longer tracked
    assert held[0].shape == BIG


def test_successive_full_model_runs_reuse_their_recording_arrays():
    from suspension_tuning import evaluation
    from suspension_tuning.vehicle._buffers import RECORDING

    designs = np.full((3, 2), 0.5)  # 3 designs: 1.4 MB full-rate, 3.2 MB decimated
    evaluation.evaluate('ride', designs)
    reused = RECORDING.reused
    evaluation.evaluate('ride', designs)
    # The first run's model and result are gone, so both its arrays are free again.
    assert RECORDING.reused - reused == 2
