"""One node per name on a ROS domain: the start-up check of the node executables.

Two nodes with the same fully-qualified name (node name and namespace) on one ROS
domain both serve the same services and actions: a second ``graph`` left running
makes both coordinators accept the same goal (``tune`` then fails with rclpy's "Two
goals were accepted with the same ID") and both recorders write a bag of the run.
So each node executable (``nodes._spin.run_node``) and ``graph`` (one check for all
its nodes) first looks for its names on the domain and refuses to start, with one
line naming the node, the domain and how to pick another, and exit code 2.

The check creates, for each name, a bare *probe* node of that name (no services, no
rosout): ROS remapping (``-r __ns:=/other``, ``-r __node:=sim_1``) applies to it as to
the real node, so its fully-qualified name is the real node's.  It then watches
``get_node_names_and_namespaces()`` for another node of that name, up to
:data:`DISCOVERY_WINDOW_S` (leaving as soon as one shows), and destroys the probes.
Nothing of the real node exists before the check has passed: no service, no latched
message, no bag.

Discovery takes time: with Fast DDS's defaults a new participant learns of one already
running at that one's next participant announcement, every 3 s: measured 0 to 3.3 s
after start-up on a 2-core machine (75 starts; over 2 s in half of them), so the
window is 3.5 s, and a shorter one misses duplicates.  ``graph`` imports its node
modules during the window, which hides about 2 s of it.  Environment variable
``SUSPENSION_TUNING_DISCOVERY_WINDOW_S`` sets another window in seconds (longer for a
slow network; 0 skips the check).

A process killed with SIGKILL stays on the graph until its DDS lease runs out (Fast
DDS: 20 s).  So a name found taken is confirmed by asking the other node for its
parameter names (``<name>/list_parameters``, which every rclpy node serves and the
probes do not): one that does not answer within :data:`ANSWER_WAIT_S` is such a
leftover, and the node starts with a note (a worker restarted at once after a crash
serves again).
"""

from __future__ import annotations

import os
import sys
import time
from collections import Counter
from collections.abc import Sequence

from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

#: Longest wait for discovery, s: Fast DDS announces a participant every 3 s by default
#: (measured here: up to 3.3 s from start-up to a running node's discovery).
DISCOVERY_WINDOW_S = 3.5
#: Environment variable that overrides :data:`DISCOVERY_WINDOW_S` (seconds, 0 = no check).
WINDOW_VARIABLE = 'SUSPENSION_TUNING_DISCOVERY_WINDOW_S'
#: Poll period of the node list during the window, s.
POLL_S = 0.05
#: Time a node found with a taken name has to answer ``list_parameters``, s; one that
#: does not is a killed process still listed until its DDS lease runs out.
ANSWER_WAIT_S = 2.0


def discovery_window_s() -> float:
    """The discovery window in seconds: :data:`WINDOW_VARIABLE` if set, else the default.

    Raises
    ------
    ValueError
        The variable is set but is not a number of seconds >= 0.
    """
    text = os.environ.get(WINDOW_VARIABLE, '').strip()
    if not text:
        return DISCOVERY_WINDOW_S
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value >= 0.0:  # also NaN
        raise ValueError(f'{WINDOW_VARIABLE}={text!r}: expected seconds >= 0 (e.g. 3), '
                         '0 skips the check')
    return value


class NameCheck:
    """Look for other nodes with the given names on the domain of ``context``.

    The probes are created at once, so that the discovery window runs while the caller
    does other start-up work (e.g. imports); :meth:`taken` waits for the rest of it.

    Parameters
    ----------
    names : sequence of str
        Node names as the executable creates them (before remapping).
    context : rclpy.context.Context, optional
        The initialised context the real nodes will use (its ``--ros-args`` apply);
        default rclpy's.

    Raises
    ------
    ValueError
        :data:`WINDOW_VARIABLE` is not a number of seconds >= 0.
    """

    def __init__(self, names: Sequence[str], context: Context | None = None) -> None:
        self.window_s = discovery_window_s()
        self.started = time.monotonic()
        self.probes = [Node(name, context=context, enable_rosout=False,
                            start_parameter_services=False,
                            parameter_overrides=[Parameter('start_type_description_service',
                                                           value=False)])
                       for name in names]
        self.own = Counter((p.get_name(), p.get_namespace()) for p in self.probes)

    def _taken_now(self) -> list[str]:
        seen = Counter(self.probes[0].get_node_names_and_namespaces())
        return [(ns.rstrip('/') + '/' + name) for (name, ns), count in self.own.items()
                if seen[(name, ns)] > count]

    def taken(self, window_s: float | None = None) -> list[str]:
        """Fully-qualified names another node on the domain has; the probes are destroyed.

        Parameters
        ----------
        window_s : float, optional
            Longest wait for discovery from the check's creation, s (default
            :func:`discovery_window_s` at creation).  Returns early once a name is taken, and at
            once (empty) when the context shuts down (Ctrl-C, SIGTERM).
        """
        window_s = self.window_s if window_s is None else window_s
        try:
            if not self.probes or window_s <= 0.0:
                return []
            while True:
                if not self.probes[0].context.ok():
                    return []
                taken = self._taken_now()
                if taken or time.monotonic() - self.started >= window_s:
                    return [name for name in taken if self._answers(name)]
                time.sleep(POLL_S)
        finally:
            for probe in self.probes:
                probe.destroy_node()
            self.probes = []


    def _answers(self, name: str) -> bool:
        """Whether the node ``name`` answers ``list_parameters`` (else: a leftover)."""
        from rcl_interfaces.srv import ListParameters
        from rclpy.executors import SingleThreadedExecutor

        probe = self.probes[0]
        client = probe.create_client(ListParameters, f'{name}/list_parameters')
        executor = SingleThreadedExecutor(context=probe.context)
        executor.add_node(probe)
        try:
            if client.wait_for_service(timeout_sec=ANSWER_WAIT_S):
                future = client.call_async(ListParameters.Request())
                executor.spin_until_future_complete(future, timeout_sec=ANSWER_WAIT_S)
                if future.done():
                    return True
        finally:
            executor.shutdown(timeout_sec=0.0)
            probe.destroy_client(client)
        print(f'note: a node {name} is listed on the domain but does not answer: a process '
              'killed within its DDS lease (20 s); starting', file=sys.stderr)
        return False


def refusal(program: str, taken: Sequence[str], domain_id: int,
            rename: bool = False) -> str:
    """The one-line start-up refusal for names another node on the domain has.

    Parameters
    ----------
    program : str
        What does not start (a node's name, or 'graph').
    taken : sequence of str
        The fully-qualified names found on the domain.
    domain_id : int
        The ROS domain id (``ROS_DOMAIN_ID``).
    rename : bool
        Also suggest another node name (a simulation worker: ``__node:=sim_1``).
    """
    which = (f'a node {taken[0]} already runs' if len(taken) == 1
             else f'nodes {", ".join(taken)} already run')
    ways = ['another ROS_DOMAIN_ID', 'in another namespace (--ros-args -r __ns:=/other)']
    if rename:
        ways.append('under another node name (--ros-args -r __node:=sim_1)')
    return (f'{program}: not started: {which} on ROS domain {domain_id} (ROS_DOMAIN_ID) '
            'and would answer the same requests; start it on ' + ', '.join(ways[:-1])
            + ' or ' + ways[-1])


def start_check(program: str, names: Sequence[str]) -> NameCheck:
    """A :class:`NameCheck` of ``names`` in rclpy's default context, begun now.

    A bad :data:`WINDOW_VARIABLE` ends the process: one line on stderr, exit code 2.
    """
    import rclpy

    try:
        return NameCheck(names)
    except ValueError as error:
        rclpy.try_shutdown()
        print(f'{program}: not started: {error}', file=sys.stderr)
        sys.exit(2)


def require_unique(program: str, check: NameCheck, rename: bool = False) -> bool:
    """Finish ``check``; end the process if another node has one of its names.

    Returns
    -------
    bool
        True: start the nodes.  False: Ctrl-C or SIGTERM came during the check, rclpy
        is shut down and nothing was started (the caller returns quietly).

    A name taken on the domain ends the process with :func:`refusal`'s line on stderr
    and exit code 2.
    """
    import rclpy

    try:
        taken = check.taken()
    except KeyboardInterrupt:
        taken = []
    if not rclpy.ok():
        rclpy.try_shutdown()
        return False
    if taken:
        domain_id = rclpy.get_default_context().get_domain_id()
        rclpy.try_shutdown()
        print(refusal(program, taken, domain_id, rename), file=sys.stderr)
        sys.exit(2)
    return True
