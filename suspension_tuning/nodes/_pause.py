"""A node's watch for pauses of its process, and its return to the graph after one.

A process that was stopped (SIGSTOP, a debugger's break, its host or VM suspended) for
longer than Fast DDS's participant lease (20 s by default) has been forgotten by its
peers, and Fast DDS does not always match it again when it continues: the continued
participant reads the announcements queued while it was stopped and never learns that
its peers dropped it (eProsima/Fast-DDS#155; measured 2-3 of 12 tries on a loaded
two-core machine where a resumed worker was never matched again).  A new participant is
matched like a process restarted under its name, which the pools take back every time.

:class:`PauseWatch` looks at the monotonic clock once a second.  A gap longer than
:data:`PAUSE_S` is a pause: it logs one line and, when its node runs under
:func:`suspension_tuning.nodes._spin.run_node` with ``renew_after_pause`` (a
simulation worker started on its own), asks for the node to be made again in a new
rclpy context, so a new DDS participant (:attr:`PauseWatch.renewal_due`).  Until
then the old participant may be matched again for a moment: a request that reaches it
is answered with :data:`PAUSED_ERROR` (:meth:`PauseWatch.paused`, called before a
request is served), which a pool takes as "not back yet", not as an answer.
"""

from __future__ import annotations

import threading
import time

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

#: A gap between two looks at the clock longer than this is a pause of the process, s:
#: half Fast DDS's default participant lease (20 s), after which peers may forget it
#: (an announcement every 3 s; a gap of 10 s leaves margin for a loaded machine).
PAUSE_S = 10.0
#: Time between two looks at the clock, s.
LOOK_PERIOD_S = 1.0
#: How a request's error starts when it reached a worker on its way to a new
#: participant (:meth:`PauseWatch.paused`): send it again, elsewhere or later.
PAUSED_ERROR = 'paused: '


class PauseWatch:
    """Watch ``node``'s process for pauses (a timer in a callback group of its own).

    Parameters
    ----------
    node : rclpy.node.Node
        The node whose log says so; a timer of period :data:`LOOK_PERIOD_S` is added.
    renew : bool
        Ask for a new participant after a pause (``renewal_due``); False: only say so.
        ``run_node(..., renew_after_pause=True)`` sets it.

    Attributes
    ----------
    renewal_due : threading.Event
        Set after a pause when ``renew`` is on: the node's ``run_node`` loop then
        destroys the node and its context and makes both again.
    """

    def __init__(self, node: Node, renew: bool = False) -> None:
        self.node = node
        self.renew = renew
        self.renewal_due = threading.Event()
        self.last_look = time.monotonic()
        self._lock = threading.Lock()
        node.create_timer(LOOK_PERIOD_S, self._look,
                          callback_group=MutuallyExclusiveCallbackGroup())

    def paused(self) -> bool:
        """Look at the clock now: True once a pause asked for a new participant.

        Called by a request's callback before it serves: the first callback after a
        pause may run before the timer's next look, while peers already match the old
        participant again.  Its answer is then :data:`PAUSED_ERROR`, not a result.
        """
        self._look()
        return self.renewal_due.is_set()

    def paused_error(self) -> str:
        """The error of a request served by :meth:`paused` (starts with PAUSED_ERROR)."""
        return (f'{PAUSED_ERROR}{self.node.get_fully_qualified_name()} was paused (its '
                'process stopped, or its host suspended) and joins the graph again as a '
                'new DDS participant: send the request again')

    def _look(self) -> None:
        with self._lock:
            now = time.monotonic()
            gap, self.last_look = now - self.last_look, now
            if gap <= PAUSE_S or self.renewal_due.is_set():
                return
            if self.renew:
                self.renewal_due.set()
        name = self.node.get_fully_qualified_name()
        said = (f'this process was paused for {gap:.0f} s (stopped, or its host suspended): '
                'its peers may have forgotten it (DDS participant lease, 20 s)')
        if self.renew:
            self.node.get_logger().warning(
                said + f': {name} joins the graph again as a new DDS participant; the '
                f'pools that use it take it back ("worker {name} is back" in the '
                "coordinator's log)")
        else:
            self.node.get_logger().warning(
                said + ': the pools in other processes take it back once DDS finds it '
                'again, which Fast DDS may never do after a pause past that lease '
                f'(eProsima/Fast-DDS#155): if no "worker {name} is back" follows in the '
                "coordinator's log within seconds, restart the process")
