"""FMU runs in child processes (suspension_tuning.fmu.isolated): faults fail one design.

FaultyRide (conftest ``fmus``) raises, returns NaN, hangs, segfaults or exits its
process for designs with a damper scale above 2.5, one step after it logged a warning
at t = 0.200 s: each fault fails its design with an error naming the design, the
simulation time reached, the cause and the FMU's own words, and the next design runs.
"""

import os
import re
import threading
import time

import numpy as np
import pytest
import yaml
from test_fmu import failing_mapping, ride_inputs_mapping

from suspension_tuning.fmu import FmuModel, FmuRunError, parse_mapping
from suspension_tuning.fmu.isolated import FmuRunCancelledError, IsolatedFmuModel

TIMEOUT_S = 2.0  # per-design timeout of these tests: a healthy design here takes ~0.05 s
STOP_S = 1.0  # short runs (the fault comes at 0.2 s); W_b settles in 0.56 s (comfort.py)
GOOD = np.array([[0.3, 0.4]])  # dpsf 0.97 (eq. 4): no fault
BAD = np.array([[0.3, 0.4], [0.9, 0.4]])  # design 1: dpsf 2.71 > 2.5, faults after 0.2 s
WARNING = 'damper force table exceeded at t = 0.200 s'  # FaultyRide's message, logged first


def faulty_mapping(fault: int, **ride):
    mapping = failing_mapping()
    mapping['scenarios']['ride'].update(stop_time_s=STOP_S, settle_s=0.5,
                                        parameters={'fault': fault}, **ride)
    return parse_mapping(yaml.safe_dump(mapping))


#: fault number of FaultyRide -> what the error must say about the cause.
FAULTS = {
    'raise': (1, r"the FMU failed at t = 0\.202 s: fmi2DoStep failed with status 4 \(fatal\)\. "
                 r".*RuntimeError\('solver failure: damper force table exceeded'\)"),
    'nan': (2, r"the FMU failed at t = 0\.2 s: output 'seatDriverAz' = nan at t = 0\.202 s "
               r'\(diverged\)'),
    'hang': (3, r'no result within 2 s \(fmu_timeout_s\): the FMU hung at t = 0\.202 s'),
    'segfault': (4, r'the FMU crashed at t = 0\.202 s .*killed by SIGSEGV'),
    'exit': (5, r'the FMU crashed at t = 0\.202 s .*exited with code 3'),
}


@pytest.mark.parametrize('fault', FAULTS)
def test_fmu_fault_fails_its_design_with_its_cause_and_the_next_design_runs(fmus, fault):
    number, cause = FAULTS[fault]
    messages = []
    with IsolatedFmuModel(fmus['faulty'], faulty_mapping(number), timeout_s=TIMEOUT_S,
                          on_message=messages.append) as fmu:
        before = fmu.evaluate('ride', GOOD)
        child = fmu.pool._children[0].process
        start = time.monotonic()
        with pytest.raises(FmuRunError, match=r'^design 1 \(x = \[0\.9, 0\.4\]\): ' + cause
                           ) as failed:
            fmu.evaluate('ride', BAD)
        took = time.monotonic() - start
        after = fmu.evaluate('ride', GOOD)
        dirs = [c.unzipdir for c in fmu.pool._children]
    assert took < TIMEOUT_S + 5.0  # the bound: within the timeout + 5 s
    # The FMU's own words: in the error, and passed on as they came.
    assert f'The FMU said: [warning] logStatusWarning: {WARNING}' in str(failed.value)
    assert any(m.design == 1 and m.status == 1 and WARNING in m.text for m in messages)
    # The failed design's process was replaced; the next design gives the same bits.
    assert not child.is_alive()
    np.testing.assert_array_equal(after.f, before.f)
    np.testing.assert_array_equal(after.g, before.g)
    # Closing stops the children and removes what they extracted.
    assert not any(os.path.exists(d) for d in dirs)


def test_fmu_runs_in_two_processes_give_the_in_process_bits(fmus):
    """Designs spread over two children, each replaced after every design: the same
    bits as the in-process model (each design runs on a fresh instance either way)."""
    x = np.array([[0.3, 0.4], [0.8, 0.9], [0.5, 0.1]])
    mapping = parse_mapping(yaml.safe_dump(ride_inputs_mapping(stop_time_s=STOP_S,
                                                               settle_s=0.5)))
    with FmuModel(fmus['ride_inputs'], mapping) as fmu:
        local = fmu.evaluate('ride', x)
    with IsolatedFmuModel(fmus['ride_inputs'], mapping, processes=2,
                          designs_per_process=1) as fmu:
        isolated = fmu.evaluate('ride', x)
        replaced = fmu.pool.replaced
    np.testing.assert_array_equal(isolated.f, local.f)
    np.testing.assert_array_equal(isolated.g, local.g)
    np.testing.assert_array_equal(isolated.metrics, local.metrics)
    assert replaced == 0  # recycled after their design, not replaced after a failure


def test_fmu_run_in_progress_is_stopped_by_a_cancel_and_by_its_caller(fmus):
    """A design hung in the FMU (timeout far away) stops at a cancel, and when the
    caller's ``stopping()`` turns true (a worker shutting down), within a second."""
    stop = threading.Event()
    hung = threading.Event()

    def on_message(message):
        if WARNING in message.text:  # the step after this one hangs
            hung.set()

    with IsolatedFmuModel(fmus['faulty'], faulty_mapping(3), timeout_s=60.0,
                          on_message=on_message, stopping=stop.is_set) as fmu:
        for how in ('cancel', 'stopping'):
            hung.clear()
            outcome = []
            run = threading.Thread(target=_attempt, args=(fmu, outcome))
            run.start()
            assert hung.wait(30.0), 'the FMU never reached its hang'
            start = time.monotonic()
            if how == 'cancel':
                assert fmu.cancel()
            else:
                stop.set()
            run.join(10.0)
            assert time.monotonic() - start < 1.0  # POLL_S = 0.25 s and a kill
            assert isinstance(outcome[0], FmuRunCancelledError), outcome
            reason = 'cancel requested' if how == 'cancel' else 'the worker is stopping'
            # The warning comes at the end of the step from 0.200 s, the hang in the step
            # from 0.202 s: a cancel right after the warning finds the run at either.
            assert re.search(rf'FMU run stopped \({reason}\): design 1 \(x = \[0\.9, 0\.4\]\) '
                             r'at t = 0\.2(02)? s', str(outcome[0])), outcome
        stop.clear()
        assert not fmu.cancel()  # nothing runs: nothing to stop
        assert np.isfinite(fmu.evaluate('ride', GOOD).f).all()


def _attempt(fmu, outcome):
    try:
        outcome.append(fmu.evaluate('ride', BAD))
    except FmuRunError as error:
        outcome.append(error)
