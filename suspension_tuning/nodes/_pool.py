"""The simulation workers of a graph: found on the graph, shared by pull, watched for loss.

A worker is any node that serves ``<name>/evaluate`` of type EvaluateDesign
(``full_vehicle_sim``, ``sim_0``, a worker on another host).  The pool finds the
workers in its node's namespace (``pattern``) or those an allow-list names, keeps
each one's latched model description (``<name>/model``, with the fingerprint of
:mod:`suspension_tuning.model_identity`) and watches the liveliness of that topic:
DDS reports a worker whose process or host is gone within ``loss_timeout_s``.

A batch of designs is cut into pieces (``pieces_per_worker`` per usable worker) that
go out one at a time to whichever worker is free, the one idle longest first: a slow
host takes fewer pieces, and a one-design request does not always land on the same
worker.  A piece whose worker is lost (liveliness), vanishes or stays silent longer
than ``design_timeout_s`` per design is sent again to another worker; that worker is
used again once it is back: it answers a ping after its liveliness returned, or it
sends a model description from a new process (one restarted under its name, also
within the liveliness lease, when its loss was never reported).  A lost worker whose
``evaluate`` is matched is pinged too: DDS may not report the liveliness of a process
continued after a stop longer than its participant lease; a worker started on its own
joins again as a new participant then (:mod:`suspension_tuning.nodes._pause`), and the
old one's answer "paused" is no answer.  "back" is said once per return.  A design
gives the same bits alone or in a batch, so how the pieces fall does not change a
result.

A worker gets pieces only once it has answered a ping (an ``evaluate`` request with
no scenario and no designs) since it joined, came back or failed.  A worker process
restarted under the same name while the dead one is still listed on the graph (its
DDS lease, 20 s by default) looks ready before its ``evaluate`` is matched: a request
sent then is lost, and the piece would wait ``design_timeout_s`` per design.  Pings
are sent again, ever less often, until one is answered.

Every change of membership (joined, lost, refused for another model, back) is
reported through ``on_event`` and kept in :attr:`SimulationPool.events`.
"""

from __future__ import annotations

import collections
import fnmatch
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml
from rclpy.callback_groups import CallbackGroup
from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from std_srvs.srv import Trigger
from suspension_tuning_interfaces.srv import EvaluateDesign

from suspension_tuning.model_identity import ModelMismatchError, check_same
from suspension_tuning.nodes._pause import PAUSED_ERROR
from suspension_tuning.nodes._services import ServiceCallError

#: The service type that makes a node a simulation worker.
EVALUATE_TYPE = 'suspension_tuning_interfaces/srv/EvaluateDesign'
#: Longest wait between looks at the pieces out, s (a done piece or a lost worker
#: wakes the wait at once; each wake-up takes the GIL from a thread running a model).
POLL_S = 1.0
#: Time to wait for a worker when none is usable, s (one restarting, one joining).
JOIN_WAIT_S = 5.0
#: First and longest wait for a ping's answer before it is sent again, s (doubling:
#: a worker busy with another pool's piece answers after that piece).
PING_RETRY_S = (0.5, 8.0)


def model_qos(lease_s: float) -> QoSProfile:
    """QoS of a worker's ``~/model``: latched, with automatic liveliness of ``lease_s``.

    The worker offers its lease (``liveliness_lease_s``); a pool requests its loss
    bound (``worker_loss_timeout_s``), which must not be shorter (DDS matches an
    offered lease only to an equal or longer requested one) and is the time within
    which DDS reports a worker whose process or host is gone.
    """
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      liveliness=LivelinessPolicy.AUTOMATIC,
                      liveliness_lease_duration=Duration(seconds=lease_s))


def description(text: str) -> dict[str, Any]:
    """A worker's ~/model message as a dict (a text that is no mapping: no fingerprint)."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError:
        data = None
    return data if isinstance(data, dict) else {'unreadable_description': text}


def matches(pattern: str, name: str) -> bool:
    """Whether worker ``name`` fits ``pattern``, one ``fnmatch`` per name segment.

    ``/*`` is every worker at the root namespace and not ``/lab/sim_0``; ``/lab/*``
    the workers in ``/lab``; ``/*/sim_*`` any ``sim_`` one namespace down.
    """
    want, have = pattern.strip('/').split('/'), name.strip('/').split('/')
    return len(want) == len(have) and all(fnmatch.fnmatchcase(h, w)
                                          for w, h in zip(want, have))


class PoolError(ServiceCallError):
    """No simulation worker answers: none found, every one lost, or shut down."""


@dataclass
class PoolEvent:
    """A change of the pool's membership, or a piece sent again."""

    kind: str  #: 'joined', 'lost', 'back', 'refused' or 'resent'
    worker: str
    text: str
    time_s: float = field(default_factory=time.monotonic)  #: time.monotonic() of it


@dataclass
class Worker:
    """What the pool knows of one worker."""

    name: str
    client: Any
    cancel: Any
    model: dict[str, Any] | None = None
    alive: bool = False  #: its ~/model writer is alive (DDS liveliness) or just spoke
    gone: bool = False  #: its liveliness was lost and has not come back
    failed: str = ''  #: why it is not used until it is back ('' = not failed)
    refused: str = ''  #: why its model is not the pool's ('' = not refused)
    ready: bool = False  #: answered a ping since it joined, came back or failed
    model_stamp: int | None = None  #: source time stamp of its model description, ns
    back_reported: bool = False  #: 'back' said since its process's model description
    ping: Any = None  #: the future of the ping in flight
    ping_sent_s: float = 0.0
    ping_wait_s: float = PING_RETRY_S[0]
    last_sent_s: float = 0.0
    designs: int = 0  #: designs it answered
    busy_s: float = 0.0  #: time its pieces took, s

    @property
    def fingerprint(self) -> str:
        return str((self.model or {}).get('fingerprint', 'none'))


class SimulationPool:
    """The simulation workers of a node's graph, and batches shared among them.

    Parameters
    ----------
    node : rclpy.node.Node
        The calling node, spun by a multi-threaded executor.
    group : CallbackGroup
        Callback group of the clients, subscriptions and the refresh timer (not one
        the caller of :meth:`evaluate` holds).
    allow : sequence of str
        Workers to use and no others (``sim_workers``); empty: every worker that fits
        ``pattern``.  A listed worker whose model differs from the others' refuses the
        goal instead of being left out.
    pattern : str
        Worker names to use (:func:`matches`); '' = the node's namespace (``/*``, or
        ``/ns/*`` for a node in ``/ns``).
    design_timeout_s : float
        Time one design may take on a worker before the worker is declared hung, s.
    loss_timeout_s : float
        Liveliness lease requested from the workers: a lost worker is reported within
        it, s.
    pieces_per_worker : int
        Pieces a batch is cut into per usable worker.
    stopping : callable
        True when the caller's node shuts down or its goal is cancelled.
    on_event : callable, optional
        Called with each :class:`PoolEvent` (from an executor thread).
    refresh_s : float
        Period of the look for new workers on the graph, s.
    """

    def __init__(self, node: Node, group: CallbackGroup, allow: Sequence[str] = (),
                 pattern: str = '', design_timeout_s: float = 360.0,
                 loss_timeout_s: float = 2.0, pieces_per_worker: int = 3,
                 stopping: Callable[[], bool] = lambda: False,
                 on_event: Callable[[PoolEvent], None] | None = None,
                 refresh_s: float = 1.0) -> None:
        self.node = node
        self.group = group
        self.allow = ['/' + str(name).strip('/') for name in allow or ()]
        namespace = node.get_namespace().rstrip('/')
        self.pattern = pattern or f'{namespace}/*'
        self.design_timeout_s = float(design_timeout_s)
        self.loss_timeout_s = float(loss_timeout_s)
        self.pieces_per_worker = max(1, int(pieces_per_worker))
        self.stopping = stopping
        self.on_event = on_event
        self.workers: dict[str, Worker] = {}
        self.events: collections.deque[PoolEvent] = collections.deque(maxlen=500)
        self.fingerprint = ''
        self._lock = threading.RLock()
        self._news = threading.Condition(self._lock)
        self.refresh()
        self._timer = node.create_timer(refresh_s, self.refresh, callback_group=group)

    # ------------------------------------------------------------ membership
    def wanted(self, name: str) -> bool:
        """Whether the pool uses worker ``name`` (allow-list, else the pattern)."""
        return name in self.allow if self.allow else matches(self.pattern, name)

    def looked_for(self) -> str:
        """How the pool finds its workers, for messages."""
        return (f'sim_workers {", ".join(self.allow)}' if self.allow else
                f'workers serving <name>/evaluate that fit {self.pattern!r}')

    def refresh(self) -> None:
        """Add the workers that appeared on the graph (and the listed ones) to the pool."""
        try:
            services = self.node.get_service_names_and_types()
        except RuntimeError:  # rclpy's InvalidHandle: the node is being destroyed
            return
        found = [name[:-len('/evaluate')] for name, types in services
                 if name.endswith('/evaluate') and EVALUATE_TYPE in types]
        with self._lock:
            for name in [*self.allow, *found]:
                if name not in self.workers and self.wanted(name):
                    self._add(name)
            for worker in self.workers.values():
                self._ping(worker)

    def _ping(self, worker: Worker) -> None:
        """Ping a worker that is not ready (again, once the last ping is overdue).

        A worker that is up gets pinged before its first piece; one that was lost (its
        liveliness) but whose ``evaluate`` is matched gets pinged too: an answer shows
        that it runs again (a process continued after a stop, or restarted under its
        name, whose liveliness DDS may not report again), and takes it back.  A worker
        that failed otherwise (hung, a failed call) is used again at the next goal
        (:meth:`revive`).
        """
        if worker.ready or worker.model is None:
            return
        if not (self._up(worker) or (worker.gone and worker.client.service_is_ready())):
            return
        now = time.monotonic()
        if worker.ping is not None:
            if now - worker.ping_sent_s < worker.ping_wait_s:
                return
            worker.client.remove_pending_request(worker.ping)
            worker.ping_wait_s = min(2.0 * worker.ping_wait_s, PING_RETRY_S[1])
        future = worker.client.call_async(EvaluateDesign.Request())
        worker.ping, worker.ping_sent_s = future, now
        future.add_done_callback(lambda done: self._on_pong(worker, done))

    def _on_pong(self, worker: Worker, future: Any) -> None:
        """A ping's answer makes the worker ready (and back, when it was out).

        An answer from a worker on its way to a new participant after a pause
        (:data:`~suspension_tuning.nodes._pause.PAUSED_ERROR`) is not one: the ping is
        sent again, and the new participant answers it.
        """
        event = None
        with self._news:
            if (future is worker.ping and future.exception() is None
                    and not future.result().error.startswith(PAUSED_ERROR)):
                worker.ready, worker.ping = True, None
                worker.ping_wait_s = PING_RETRY_S[0]
                event = self._back(worker, ' (it answers again)')
                self._news.notify_all()
        if event is not None:
            self._event(*event, worker.name)

    def _back(self, worker: Worker, how: str) -> tuple[str, str] | None:
        """Take a lost or failed worker back: the 'back' event, once per return."""
        out = worker.gone or bool(worker.failed)
        worker.gone, worker.failed, worker.alive = False, '', True
        if not out:
            return None
        worker.back_reported = True
        return ('back', f'worker {worker.name} is back{how}')

    def _not_ready(self, worker: Worker) -> None:
        """The worker must answer a ping before it gets a piece again."""
        if worker.ping is not None:
            worker.client.remove_pending_request(worker.ping)
        worker.ready, worker.ping, worker.ping_wait_s = False, None, PING_RETRY_S[0]

    def _add(self, name: str) -> None:
        client = self.node.create_client(EvaluateDesign, f'{name}/evaluate',
                                         callback_group=self.group)
        cancel = self.node.create_client(Trigger, f'{name}/cancel', callback_group=self.group)
        self.workers[name] = Worker(name, client, cancel)
        self.node.create_subscription(
            String, f'{name}/model', lambda msg, info: self._on_model(name, msg, info),
            model_qos(self.loss_timeout_s), callback_group=self.group,
            event_callbacks=SubscriptionEventCallbacks(
                liveliness=lambda info: self._on_liveliness(name, info),
                incompatible_qos=lambda _info: self._on_incompatible(name)))

    def _event(self, kind: str, text: str, worker: str, time_s: float | None = None) -> None:
        event = PoolEvent(kind, worker, text, time.monotonic() if time_s is None else time_s)
        self.events.append(event)
        if kind in ('joined', 'back'):  # one call site per severity (rclpy's rule)
            self.node.get_logger().info(text)
        else:
            self.node.get_logger().warning(text)
        if self.on_event is not None:
            self.on_event(event)

    def _on_model(self, name: str, msg: String, info: Any = None) -> None:
        """A worker's model description: it joined, or a process restarted under its name.

        A description with a new source time stamp comes from a new process (each one
        publishes it once, latched); the same one again is the old sample delivered
        anew (e.g. after the graph forgot a stopped process).  A new process is back
        even when its loss went unnoticed (restarted within the liveliness lease), and
        must answer a ping before it gets a piece: the old one's calls are lost.
        """
        events = []
        stamp = info.get('source_timestamp') if isinstance(info, dict) else None
        with self._news:
            arrived = time.monotonic()  # taken under the lock: before check_models sees it
            worker = self.workers[name]
            first = worker.model is None
            restarted = not first and stamp is not None and stamp != worker.model_stamp
            worker.model, worker.alive = description(msg.data), True
            if restarted:
                worker.model_stamp = stamp
                self._not_ready(worker)
                if not worker.back_reported:  # a loss and return said it already
                    worker.failed = worker.failed or 'restarted'
                worker.back_reported = False
            elif first:
                worker.model_stamp = stamp
            back = self._back(worker, f' (model {worker.fingerprint})')
            if back is not None:
                events.append(back)
                worker.back_reported = not restarted
            elif first:
                events.append(('joined', f'worker {name} joined (model {worker.fingerprint})'))
            worker.refused = ''
            if self.fingerprint and worker.fingerprint != self.fingerprint:
                worker.refused = self._refusal(worker)
                events.append(('refused', worker.refused))
            self._ping(worker)
            self._news.notify_all()
        for kind, text in events:
            self._event(kind, text, name, arrived)

    def _refusal(self, worker: Worker) -> str:
        return (f'worker {worker.name} runs model {worker.fingerprint}, the pool runs model '
                f'{self.fingerprint}: not used (another vehicle, FMU, mapping or '
                'configuration on that host)')

    def _on_liveliness(self, name: str, info: Any) -> None:
        event = None
        with self._news:
            worker = self.workers[name]
            if info.alive_count > 0:  # back once it answers a ping (_on_pong)
                worker.alive = True
                self._ping(worker)
            elif worker.alive and not self._in_this_process(name):
                was_out, worker.alive, worker.gone = worker.gone, False, True
                self._not_ready(worker)
                if not was_out:  # not when alive again for a moment, unanswered
                    event = ('lost', f'worker {name} lost: no sign of life within '
                             f'{self.loss_timeout_s:g} s (its process ended or its host '
                             'is unreachable)')
            self._news.notify_all()
        if event is not None:
            self._event(*event, name)

    def _in_this_process(self, name: str) -> bool:
        """Whether worker ``name``'s ``~/model`` writer shares this node's DDS participant.

        Fast DDS asserts automatic liveliness to the readers of other participants
        only, so a worker in this node's own context (``graph``, a test) seems lost
        after one lease; being in this process, it cannot be lost without this node.
        A participant's endpoints share the first 12 bytes of their GUID.
        """
        topic = f'{name}/model'
        own = {bytes(info.endpoint_gid[:12])
               for info in self.node.get_subscriptions_info_by_topic(topic)
               if (info.node_name, info.node_namespace) == (self.node.get_name(),
                                                           self.node.get_namespace())}
        return any(bytes(info.endpoint_gid[:12]) in own
                   for info in self.node.get_publishers_info_by_topic(topic))

    def _on_incompatible(self, name: str) -> None:
        self.node.get_logger().error(
            f'worker {name} offers a liveliness lease longer than this node\'s '
            f'worker_loss_timeout_s ({self.loss_timeout_s:g} s): set the worker\'s '
            'liveliness_lease_s below it; until then the pool does not hear from it')

    def _up(self, worker: Worker) -> bool:
        """Described, alive, not failed, and its evaluate service matched."""
        return (worker.model is not None and worker.alive and not worker.failed
                and worker.client.service_is_ready())

    def _usable(self, worker: Worker) -> bool:
        return self._up(worker) and not worker.refused and worker.ready

    @property
    def alive(self) -> list[str]:
        """The workers the pool uses now."""
        with self._lock:
            return sorted(w.name for w in self.workers.values() if self._usable(w))

    @property
    def models(self) -> dict[str, dict[str, Any]]:
        """Each worker's model description, as far as received."""
        with self._lock:
            return {w.name: w.model for w in self.workers.values() if w.model is not None}

    def designs_by_worker(self) -> dict[str, int]:
        """Designs each worker has answered since the pool started."""
        with self._lock:
            return {w.name: w.designs for w in self.workers.values()}

    def revive(self) -> None:
        """Use again the failed workers that are alive and serve now."""
        with self._lock:
            for worker in self.workers.values():
                if worker.failed and worker.alive and worker.client.service_is_ready():
                    worker.failed = ''
                    self._ping(worker)

    def cancel_runs(self) -> None:
        """Ask every worker to stop its FMU run in progress (``~/cancel``; no wait)."""
        with self._lock:
            clients = [w.cancel for w in self.workers.values()]
        for client in clients:
            if client.service_is_ready():
                client.call_async(Trigger.Request())

    def check_models(self, wait_s: float = 5.0) -> str:
        """The one model of the pool's workers, pinned for the answers that follow.

        Waits up to ``wait_s`` for a worker, and for the model description of each
        worker that serves.  Workers with another model than the pool's are left
        out with a warning (an event naming both fingerprints); the pool's model is
        the one most workers run, or the listed workers' one with ``allow``.

        Raises
        ------
        ModelMismatchError
            Listed workers run different models, or no model is run by more workers
            than any other (the message names each worker and its fingerprint).
        PoolError
            No worker found, or a listed worker serves but has not described its model.
        """
        self.fingerprint = ''
        self.revive()
        deadline = time.monotonic() + wait_s
        while not self.stopping():
            self.refresh()
            with self._lock:
                workers = list(self.workers.values())
                silent = [w for w in workers if w.model is None and w.client.service_is_ready()]
                described = [w for w in workers if w.model is not None and w.alive]
            if (described and not silent) or time.monotonic() > deadline:
                break
            time.sleep(0.05)  # the subscriptions are served by the node's executor
        listed_silent = [w.name for w in silent if w.name in self.allow]
        if listed_silent:
            raise PoolError(f'worker {", ".join(listed_silent)} serves evaluate but has '
                            f'published no model description (~/model) within {wait_s} s')
        for worker in silent:
            self.node.get_logger().warning(f'worker {worker.name} serves evaluate but has '
                                           'described no model: not used')
        for name in self.allow:
            if name not in [w.name for w in described]:
                self.node.get_logger().warning(f'worker {name} is not running (no model '
                                               'description): not used')
        if not described:
            raise PoolError(f'no simulation worker is running ({self.looked_for()})')
        models = {w.name: w.fingerprint for w in described}
        if self.allow:
            fingerprint = check_same(models)
        else:
            counts = collections.Counter(models.values()).most_common()
            if len(counts) > 1 and counts[0][1] == counts[1][1]:
                raise ModelMismatchError(
                    'the simulation workers run different models and none is run by most '
                    'of them (' + ', '.join(f'{name}: {fp}' for name, fp in models.items())
                    + '): stop the wrong ones, or list the workers to use in sim_workers')
            fingerprint = counts[0][0]
        refused = []
        with self._lock:
            self.fingerprint = fingerprint
            for worker in self.workers.values():  # said again for every goal
                worker.refused = (self._refusal(worker) if worker.model is not None
                                  and worker.fingerprint != fingerprint else '')
                if worker.refused and worker.alive:
                    refused.append(worker)
        for worker in refused:
            self._event('refused', worker.refused, worker.name)
        return fingerprint

    # ------------------------------------------------------------ batches
    def evaluate(self, scenario: str, n_vars: int, designs: np.ndarray,
                 return_inputs: bool = False, publish_telemetry: bool = False,
                 integrator: str = '', road: str = '',
                 on_piece: Callable[[int], None] | None = None,
                 conditions: Sequence[str] | None = None,
                 ) -> list[EvaluateDesign.Response]:
        """Evaluate designs (m, n_vars) on the workers; the responses in design order.

        ``integrator``: the full-model integrator ('' = each worker's parameter);
        ``road``: the ride road ('' = each worker's configured one); ``on_piece``:
        called with the number of designs answered so far after each piece;
        ``conditions``: the operating condition of each design (JSON text,
        EvaluateDesign.condition), so that one design in several conditions goes out
        as one batch (a piece holds designs of one condition; list each condition's
        designs together, condition after condition, for the responses to come in
        design order).
        Telemetry (``publish_telemetry``) is that of the first design.

        Raises
        ------
        ValueError
            A worker rejected the request or its run failed (its error text).
        ModelMismatchError
            A worker answered from another model than the pinned one, or a listed
            worker joined with another model.
        PoolError
            No worker is left, or the node shuts down (or the goal is cancelled).
        """
        designs = np.atleast_2d(np.asarray(designs, dtype=float))
        with self._lock:
            usable = sum(self._usable(w) for w in self.workers.values())
        # Sizes differing by one design at most: 16 designs for 2 workers are 6 pieces
        # of 3, 3, 3, 3, 2 and 2, which fall 8 and 8 on two equal workers.
        # The mixed scenario closes its valve loop over ROS: one design per request.
        count = (len(designs) if scenario == 'mixed'
                 else min(len(designs), max(1, usable) * self.pieces_per_worker))
        if conditions is None:
            pieces = np.array_split(np.arange(len(designs)), count)
            piece_condition = [''] * len(pieces)
        else:
            if len(conditions) != len(designs):
                raise ValueError(f'{len(conditions)} conditions for {len(designs)} designs')
            groups: dict[str, list[int]] = {}
            for index, condition in enumerate(conditions):
                groups.setdefault(str(condition), []).append(index)
            pieces, piece_condition = [], []
            for condition, indices in groups.items():
                share = max(1, round(count * len(indices) / len(designs)))
                for piece in np.array_split(np.asarray(indices), min(share, len(indices))):
                    pieces.append(piece)
                    piece_condition.append(condition)
        queue = collections.deque(range(len(pieces)))
        running: dict[str, tuple[int, Any, float]] = {}  # worker -> (piece, future, sent)
        responses: dict[int, EvaluateDesign.Response] = {}
        waiting_since = None

        def request(index: int) -> EvaluateDesign.Request:
            return EvaluateDesign.Request(
                scenario=scenario, n_vars=n_vars, designs=designs[pieces[index]].ravel().tolist(),
                publish_telemetry=publish_telemetry and index == 0,
                return_inputs=return_inputs, integrator=integrator, road=road,
                condition=piece_condition[index])

        def abandon() -> None:
            for name, (_, future, _) in running.items():
                if not future.done():
                    self.workers[name].client.remove_pending_request(future)

        try:
            while queue or running:
                if self.stopping() or not self.node.context.ok():
                    raise PoolError('shut down while waiting for the simulation workers')
                with self._news:
                    self._check_listed()
                    free = sorted((w for w in self.workers.values()
                                   if w.name not in running and self._usable(w)),
                                  key=lambda w: w.last_sent_s)
                    for worker in free[:len(queue)]:
                        index = queue.popleft()
                        future = worker.client.call_async(request(index))
                        future.add_done_callback(self._notify)
                        worker.last_sent_s = time.monotonic()
                        running[worker.name] = (index, future, worker.last_sent_s)
                    if not running:
                        waiting_since = waiting_since or time.monotonic()
                        pinged = [w.name for w in self.workers.values() if w.ping is not None
                                  and not w.failed and not w.refused and w.alive]
                        waited = time.monotonic() - waiting_since
                        if waited > (self.design_timeout_s if pinged else JOIN_WAIT_S):
                            raise PoolError(
                                'no simulation worker left: every worker failed or is gone '
                                f'({self.looked_for()})' + (
                                    f'; {", ".join(pinged)} did not answer a ping within '
                                    f'{waited:.0f} s' if pinged else ''))
                    else:
                        waiting_since = None
                    self._news.wait(0.1 if not running else POLL_S)
                self._collect(running, queue, pieces, responses, on_piece)
        finally:
            abandon()
        if conditions is None:
            return [responses[i] for i in sorted(responses)]
        return [responses[i] for i in sorted(responses, key=lambda i: int(pieces[i][0]))]

    def _notify(self, _future: Any) -> None:
        with self._news:
            self._news.notify_all()

    def _check_listed(self) -> None:
        """Refuse the run when a listed worker runs another model (allow-list)."""
        for name in self.allow:
            worker = self.workers.get(name)
            if worker is not None and worker.refused:
                raise ModelMismatchError(worker.refused.replace(': not used', '') +
                                         f'; {name} is listed in sim_workers, so the run stops')

    def _collect(self, running: dict, queue: collections.deque, pieces: list,
                 responses: dict, on_piece: Callable[[int], None] | None) -> None:
        """Take the answered pieces; send the pieces of lost or hung workers again."""
        now = time.monotonic()
        for name, (index, future, sent) in list(running.items()):
            worker = self.workers[name]
            n = len(pieces[index])
            if future.done():
                del running[name]
                worker.busy_s += now - sent
                error = future.exception()
                if error is not None:
                    self._fail(worker, f'its call failed ({error})', index, n, queue)
                    continue
                response = future.result()
                if response.error.startswith(PAUSED_ERROR):  # not an answer: send again
                    self._fail(worker, 'was paused and joins the graph again', index, n,
                               queue)
                    continue
                if not response.success:
                    raise ValueError(response.error)
                if self.fingerprint and response.model_fingerprint != self.fingerprint:
                    raise ModelMismatchError(
                        f'worker {name} answered from model {response.model_fingerprint}, '
                        f'but this run uses model {self.fingerprint}: a worker restarted '
                        'with another model, FMU, mapping or configuration')
                worker.designs += n
                responses[index] = response
                if on_piece is not None:
                    on_piece(sum(len(pieces[i]) for i in responses))
                continue
            if not worker.alive:
                reason = f'lost (no sign of life within {self.loss_timeout_s:g} s)'
            elif now - sent > self.design_timeout_s * n:
                reason = (f'no answer within {self.design_timeout_s * n:g} s for {n} '
                          f'design(s) (design_timeout_s {self.design_timeout_s:g}): hung')
            elif not worker.client.service_is_ready():
                reason = 'its evaluate service vanished'
            else:
                continue
            worker.client.remove_pending_request(future)
            del running[name]
            self._fail(worker, reason, index, n, queue)

    def _fail(self, worker: Worker, reason: str, index: int, n: int,
              queue: collections.deque) -> None:
        worker.failed = reason
        self._not_ready(worker)
        queue.appendleft(index)
        self._event('resent', f'worker {worker.name} {reason}; its {n} design(s) are sent '
                    'to another worker', worker.name)


#: The pool's parameters on the coordinator and the gradient evaluator (start-up only).
POOL_PARAMETERS = ['sim_workers', 'sim_worker_pattern', 'design_timeout_s',
                   'worker_loss_timeout_s', 'pieces_per_worker']


def pool_from_parameters(node: Node, group: CallbackGroup,
                         stopping: Callable[[], bool] = lambda: False,
                         on_event: Callable[[PoolEvent], None] | None = None) -> SimulationPool:
    """Declare the pool's ROS parameters on ``node`` and make its pool from them.

    ``sim_workers`` (string array, optional allow-list; empty: none), ``sim_worker_pattern``
    ('' = the node's namespace), ``design_timeout_s`` (s), ``worker_loss_timeout_s``
    (s) and ``pieces_per_worker``: config/graph.yaml has their meaning and defaults.
    """
    from suspension_tuning.nodes._parameters import (
        declare_numbers,
        declare_string_array,
        read_only,
    )

    allow = declare_string_array(node, 'sim_workers')  # [] (the default): every worker
    node.declare_parameter('sim_worker_pattern', '')
    declare_numbers(node, {'design_timeout_s': 360.0, 'worker_loss_timeout_s': 2.0,
                           'pieces_per_worker': 3})
    read_only(node, POOL_PARAMETERS)  # the pool below is made from them once
    value = node.get_parameter
    return SimulationPool(node, group, allow=list(allow or ()),
                          pattern=str(value('sim_worker_pattern').value),
                          design_timeout_s=value('design_timeout_s').value,
                          loss_timeout_s=value('worker_loss_timeout_s').value,
                          pieces_per_worker=value('pieces_per_worker').value,
                          stopping=stopping, on_event=on_event)
