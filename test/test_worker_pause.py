"""A simulation worker says so after a pause of its process, and what to do about it.

The pause is made by moving the worker's last look at the clock back past
``PAUSE_WARNING_S`` (what a SIGSTOP that long leaves behind; test_pool_restarts.py
stops a real process).
"""

from __future__ import annotations

import time

import pytest

pytestmark = pytest.mark.ros


def test_a_pause_longer_than_half_the_dds_lease_is_logged_with_the_remedy(
        ros_context, executor, capfd):
    from suspension_tuning.nodes.full_vehicle_sim import PAUSE_WARNING_S, FullVehicleSimNode
    from suspension_tuning.testing import wait_until

    sim = FullVehicleSimNode(name='paused_sim', context=ros_context)
    executor.add(sim)
    time.sleep(2.5)  # two looks at the clock without a pause: nothing said
    assert 'was paused' not in capfd.readouterr().err
    sim._last_look -= PAUSE_WARNING_S + 5.0  # the process did not run meanwhile
    said = []  # stderr as it comes

    def paused_said() -> bool:
        said.append(capfd.readouterr().err)
        return 'was paused' in ''.join(said)

    assert wait_until(paused_said, 5.0, period_s=0.2)
    err = ''.join(said)
    assert 'this process was paused for 1' in err  # 15-16 s: the moved look, a tick
    assert 'if no "worker /paused_sim is back" follows' in err
    assert 'restart this worker' in err
