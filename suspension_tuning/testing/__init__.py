"""Testing kit: integration tests of the tuning graph on rclpy executors.

With the package installed, pytest loads the kit as a plugin (entry point
``pytest11``), so any test can ask for its fixtures:

- ``ros_domain_id``: the session's ROS_DOMAIN_ID, reserved on the machine for the
  session so that parallel sessions never share it (``--ros-domain-id`` asks for one);
- ``ros_context``: an isolated, initialised rclpy context, shut down after the test;
- ``ros_executor``: a :class:`SpinningExecutor` on that context (``.add(node)``);
- ``start_tuning_graph``: ``start_tuning_graph(record=True, replace={...},
  parameters={...})`` starts the graph (:class:`TuningGraph`) on that context,
  recording into the test's ``tmp_path / 'bags'``; shut down after the test.

The plugin also keeps DDS discovery on loopback for the whole session
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) with a domain of the session's own.
The same pieces work without pytest as context managers (:func:`isolated_context`,
:func:`spinning_executor`, :func:`tuning_graph`, :func:`reserved_domain`), with
helpers that wait with a timeout and raise :class:`RosTimeoutError` naming what did
not answer (:func:`wait_for_future`, :func:`call_service`, :func:`send_goal`,
:meth:`TuningGraph.optimise`) and that open the bag of the run just recorded
(:meth:`TuningGraph.recorded_bag`, :func:`wait_for_bag`, :func:`open_bag`,
:func:`decode`).  See docs/testing.md.
"""

from suspension_tuning.bag.reader import BagContents, decode
from suspension_tuning.testing._environment import (
    DomainInUseError,
    apply_loopback_environment,
    default_domain_id,
    loopback_environment,
    reservation_port,
    reserved_domain,
)
from suspension_tuning.testing._graph import (
    OPTIMISE_ACTION,
    TuningGraph,
    open_bag,
    tuning_graph,
    wait_for_bag,
)
from suspension_tuning.testing._ros import (
    DEFAULT_TIMEOUT_S,
    CallbackError,
    GoalOutcome,
    GoalRejectedError,
    RosTimeoutError,
    SpinningExecutor,
    call_service,
    isolated_context,
    raise_callback_errors,
    send_goal,
    spinning_executor,
    wait_for_future,
    wait_until,
)

__all__ = [
    'DEFAULT_TIMEOUT_S', 'OPTIMISE_ACTION', 'BagContents', 'CallbackError',
    'DomainInUseError', 'GoalOutcome', 'GoalRejectedError', 'RosTimeoutError',
    'SpinningExecutor', 'TuningGraph', 'apply_loopback_environment', 'call_service',
    'decode', 'default_domain_id', 'isolated_context', 'loopback_environment', 'open_bag',
    'raise_callback_errors', 'reservation_port', 'reserved_domain', 'send_goal',
    'spinning_executor', 'tuning_graph', 'wait_for_bag', 'wait_for_future', 'wait_until',
]
