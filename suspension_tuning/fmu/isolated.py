"""FMU runs that cannot take their worker down: each design in a child process.

A user's FMU is code this package did not write: it may crash (a segfault, an
``exit``), hang, or leak until it does.  :class:`IsolatedFmuModel` is an
:class:`~suspension_tuning.fmu.model.FmuModel` whose designs run in a small pool of
child processes (:class:`FmuProcessPool`), each holding the FMU loaded, one design at
a time:

- a child that crashes or exits, or whose design takes longer than the per-design
  timeout, fails that design: the error names the design, the simulation time the run
  had reached, the cause and the FMU's last log messages; the child is killed and
  replaced, and the next design or request runs on the new one;
- a design that fails inside the FMU (an error status, NaN outputs) fails with the
  FMU's own error, and its child is replaced too (an FMU that reported an error may be
  left in any state);
- a healthy child is reused, up to :data:`DESIGNS_PER_PROCESS` designs (FMPy's users
  report FMUs that crash after about a thousand instances, from leaks);
- :meth:`FmuProcessPool.cancel`, :meth:`FmuProcessPool.close` or the caller's
  ``stopping()`` stop a run in progress within :data:`POLL_S`.

The FMU's log messages (FMI logger callback) travel from the child as they come, so
that those written before a crash or a hang are not lost.

The children come from multiprocessing's 'forkserver': a single-threaded server
process, started once, that has imported this module; a replacement is forked from it
in a fraction of a second, and the caller (a ROS node with DDS threads) is never
forked.  Where there is no forkserver (Windows) they are spawned.  No rclpy here.
"""

from __future__ import annotations

import collections
import contextlib
import math
import multiprocessing
import os
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from multiprocessing import connection
from pathlib import Path
from typing import Any

import numpy as np

from suspension_tuning.fmu.fmi_log import MESSAGES_IN_ERROR, FmuMessage
from suspension_tuning.fmu.mapping import FmuMapping, ScenarioMapping
from suspension_tuning.fmu.model import FmuConfigError, FmuModel, FmuRunError, design_label

#: Per-design wall-clock timeout by default, s: a detailed multibody FMU (Adams,
#: CarSim) running a 30 s manoeuvre up to ten times slower than real time, and below
#: the pools' design_timeout_s (360 s, config/graph.yaml), so that a worker answers a
#: hung design before the coordinator gives up on the worker.
DEFAULT_TIMEOUT_S = 300.0
#: Time a new child may take to load the FMU, s: the first child waits for the fork
#: server's imports (3 s on an idle 2-core machine, 15 s seen with both cores busy).
START_TIMEOUT_S = 120.0
#: Designs a child runs before it is replaced (see the module's docstring).
DESIGNS_PER_PROCESS = 500
#: Longest wait between looks at the caller's ``stopping()``, s.
POLL_S = 0.25

try:  # what a child imports to load the FMU, imported once in the fork server (0.2 s)
    import fmpy.fmi2
    import fmpy.fmi3
    import fmpy.logging
    import fmpy.model_description  # noqa: F401
except ImportError:  # pragma: no cover - FmuModel says fmpy is missing
    pass


class FmuRunCancelledError(FmuRunError):
    """A run stopped by a cancel, by closing the model, or because its caller stops."""


def _context() -> Any:
    """The multiprocessing context of the children: forkserver, else spawn."""
    if 'forkserver' not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context('spawn')
    context = multiprocessing.get_context('forkserver')
    # Imported once in the server, so that a child starts in a fraction of a second.
    # The main module too (as multiprocessing does by default), and when it runs as
    # ``python -m package.module`` that module, which every child imports again.
    modules = ['__main__', __name__]
    main_name = getattr(getattr(sys.modules.get('__main__'), '__spec__', None), 'name', None)
    if main_name and not main_name.endswith('__main__'):
        modules.append(main_name)
    context.set_forkserver_preload(modules)  # no effect once the server runs
    return context


def _detach() -> None:
    """In a child: leave Ctrl-C to the parent, and die with the fork server.

    Ctrl-C in a terminal reaches every process of its group: the parent decides what
    happens to a run.  A child holds the fork server's "alive" pipe, which keeps the
    server running while any child does; without it, the server exits with the
    parent, and on Linux the kernel then kills a child that is still in a hung FMU.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        from multiprocessing import forkserver
        server = forkserver._forkserver  # noqa: SLF001 - no public way to drop the pipe
        if server._forkserver_alive_fd is not None:  # noqa: SLF001
            os.close(server._forkserver_alive_fd)  # noqa: SLF001
            server._forkserver_alive_fd = None  # noqa: SLF001
    except (AttributeError, ImportError, OSError):
        pass
    if sys.platform.startswith('linux'):
        import ctypes
        pr_set_pdeathsig = 1
        ctypes.CDLL(None).prctl(pr_set_pdeathsig, int(signal.SIGKILL))


def _serve(conn: Any, fmu_path: str, mapping: FmuMapping, progress: Any) -> None:
    """A child's life: load the FMU, then run the designs sent until told to stop.

    Messages to the parent: ('ready', unzip folder) or ('failed', text) once, then per
    design ('log', FmuMessage)... and ('done', samples) or ('run_failed', text).
    """
    _detach()
    try:
        model = FmuModel(fmu_path, mapping)
    except BaseException as error:  # noqa: BLE001 - told to the parent, which decides
        conn.send(('failed', f'{type(error).__name__}: {error}'))
        return
    model.on_message = lambda message: conn.send(('log', message))
    inputs: dict[str, np.ndarray | None] = {}
    try:
        conn.send(('ready', model._unzipdir))  # noqa: SLF001 - removed by the parent
        while True:
            try:
                task = conn.recv()
            except EOFError:  # the parent has gone
                return
            if task is None:
                return
            scenario, index, x, values, fresh, road = task
            if fresh:
                inputs[scenario] = road
            sm = model.mapping.scenarios[scenario]
            try:
                samples = model._run_one(sm, index, x, values, inputs[scenario],  # noqa: SLF001
                                         progress)
            except FmuRunError as error:
                conn.send(('run_failed', str(error)))
            else:
                conn.send(('done', samples))
    finally:
        model.close()


def _ended(exitcode: int | None) -> str:
    """How a child's process ended, from its exit code."""
    if exitcode is None:
        return 'its process stopped answering'
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
            what = signal.strsignal(-exitcode) or name
        except ValueError:
            name, what = f'signal {-exitcode}', 'unknown signal'
        return f'its process was killed by {name} ({what.lower()})'
    return f'its process exited with code {exitcode}'


def _when(t: float) -> str:
    """``at t = 0.202 s (in the step from there)``, from a child's progress."""
    if math.isnan(t):
        return 'before its run started'
    return f'at t = {t:.6g} s (in the step from there)'


def _said(messages: collections.abc.Iterable[FmuMessage]) -> str:
    """`` The FMU said: ...`` of its last messages, or ''."""
    messages = list(messages)
    return ' The FMU said: ' + '; '.join(map(str, messages)) if messages else ''


@dataclass(eq=False)
class _Child:
    """One child process and what the parent knows of it."""

    process: Any
    conn: Any
    progress: Any  # simulation time at the start of the step being run, s
    started: float
    state: str = 'starting'  # 'starting', 'idle' or 'busy'
    unzipdir: str = ''
    designs: int = 0
    scenarios: set[str] = field(default_factory=set)  # whose road inputs it holds
    index: int = -1
    x: np.ndarray | None = None
    sent: float = 0.0
    recent: collections.deque = field(
        default_factory=lambda: collections.deque(maxlen=MESSAGES_IN_ERROR))

    @property
    def t(self) -> float:
        return float(self.progress.value)


class FmuProcessPool:
    """Child processes each holding the FMU loaded; runs designs one per child at a time.

    Parameters
    ----------
    fmu_path : str or Path
        The FMU (each child loads it from here).
    mapping : FmuMapping
        Its checked mapping.
    processes : int
        Children, i.e. designs run at the same time (each holds an instance's worth of
        memory, and of licence where the FMU checks one out).
    timeout_s : float
        Wall-clock time one design may take, s.
    on_message : callable, optional
        Receives each :class:`~suspension_tuning.fmu.fmi_log.FmuMessage` of the FMU, in the
        thread that runs :meth:`run`.
    designs_per_process : int
        Designs a child runs before it is replaced.

    The children start in the background (the first one of a process waits for the
    fork server's imports, seconds); :meth:`run` waits for them (at most
    :data:`START_TIMEOUT_S`), :meth:`wait_ready` too.
    """

    def __init__(self, fmu_path: str | Path, mapping: FmuMapping, processes: int = 1,
                 timeout_s: float = DEFAULT_TIMEOUT_S,
                 on_message: Callable[[FmuMessage], None] | None = None,
                 designs_per_process: int = DESIGNS_PER_PROCESS) -> None:
        self.path = str(fmu_path)
        self.mapping = mapping
        self.timeout_s = float(timeout_s)
        #: What sets ``timeout_s``, named in the error of a run that exceeds it.
        self.timeout_name = 'fmu_timeout_s'
        self.on_message = on_message
        self.designs_per_process = int(designs_per_process)
        self._context = _context()
        self._wake_r, self._wake_w = self._context.Pipe(duplex=False)
        self._run_lock = threading.Lock()  # one run at a time
        self._state_lock = threading.Lock()
        self._running = self._cancelled = self._closed = False
        self.replaced = 0  # children replaced after a failure, a timeout or a stop
        self._children: list[_Child] = []
        self._start_error: BaseException | None = None
        self._starter = threading.Thread(target=self._start_all, args=(int(processes),),
                                         name='fmu_start', daemon=True)
        self._starter.start()

    def _start_all(self, processes: int) -> None:
        try:
            for _ in range(processes):
                child = self._start()
                with self._state_lock:
                    if not self._closed:
                        self._children.append(child)
                        continue
                self._stop(child)  # closed while it started
                return
        except BaseException as error:  # noqa: BLE001 - raised by the first run
            self._start_error = error

    def _started(self, stopping: Callable[[], bool] | None = None) -> None:
        """Wait for the background start of the children (FmuRunError if it failed).

        The first start of a process waits for the fork server's imports (seconds, more
        on a busy machine): a cancel, closing or ``stopping()`` ends the wait.
        """
        while self._starter.is_alive():
            reason = self._stop_reason(stopping)
            if reason:
                raise FmuRunCancelledError(f'FMU run stopped ({reason}) before its child '
                                           'process had started')
            self._starter.join(POLL_S)
        if self._start_error is not None:
            raise FmuRunError(f'the child processes of the FMU could not be started: '
                              f'{type(self._start_error).__name__}: {self._start_error}')

    # ---------------------------------------------------------------- children
    def _start(self) -> _Child:
        parent_conn, child_conn = self._context.Pipe()
        progress = self._context.RawValue('d', math.nan)
        process = self._context.Process(target=_serve, name='fmu_run', daemon=True,
                                        args=(child_conn, self.path, self.mapping, progress))
        process.start()
        child_conn.close()  # the child's end lives in the child only: its death is EOF here
        return _Child(process, parent_conn, progress, time.monotonic())

    @staticmethod
    def _stop(child: _Child) -> None:
        if child.process.is_alive():
            child.process.kill()
        child.process.join(5.0)
        child.conn.close()
        if child.unzipdir:
            shutil.rmtree(child.unzipdir, ignore_errors=True)

    def _replace(self, child: _Child, failed: bool = True) -> None:
        """Kill ``child`` and start another in its place."""
        self._stop(child)
        self.replaced += failed
        self._children[self._children.index(child)] = self._start()

    def _pass_on(self, child: _Child, message: FmuMessage) -> None:
        child.recent.append(message)
        if self.on_message is not None:
            try:
                self.on_message(message)
            except Exception:  # noqa: BLE001,S110 - a failing log sink must not fail the run
                pass

    def _collect(self, child: _Child, out: list, failures: dict[int, str]) -> str | None:
        """Take in what ``child`` sent; a start-up problem's text, or None."""
        alive = True
        try:
            while child.conn.poll():
                kind, payload = child.conn.recv()
                if kind == 'log':
                    self._pass_on(child, payload)
                elif kind == 'ready':
                    child.state, child.unzipdir = 'idle', payload
                elif kind == 'failed':
                    self._replace(child)
                    return payload
                elif kind == 'done':
                    out[child.index] = payload
                    child.state, child.designs = 'idle', child.designs + 1
                    if child.designs >= self.designs_per_process:
                        self._replace(child, failed=False)
                        return None
                elif kind == 'run_failed':
                    failures[child.index] = payload
                    self._replace(child)
                    return None
        except (EOFError, OSError):
            alive = False
        if alive and child.process.is_alive():
            return None
        child.process.join(1.0)  # the exit code follows the closed pipe closely
        cause = _ended(child.process.exitcode)
        state = child.state
        if state == 'busy':
            failures[child.index] = (f'{design_label(child.index, child.x)}: the FMU crashed '
                                     f'{_when(child.t)}: {cause}.{_said(child.recent)}')
        self._replace(child)
        return f'{cause} while loading the FMU' if state == 'starting' else None

    def wait_ready(self, timeout_s: float = START_TIMEOUT_S) -> None:
        """Block until every child has loaded the FMU.

        Raises
        ------
        FmuRunError
            A child could not load it, or not within ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        with self._run_lock:
            self._started()
            while any(c.state == 'starting' for c in self._children):
                if self._closed:
                    raise FmuRunCancelledError('the FMU model is closed')
                starting = [c for c in self._children if c.state == 'starting']
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise FmuRunError(f'the FMU was not loaded within {timeout_s:g} s')
                connection.wait([c.conn for c in starting], min(remaining, POLL_S))
                for child in starting:
                    problem = self._collect(child, [], {})
                    if problem:
                        raise FmuRunError(f'the FMU could not be loaded in a child process: '
                                          f'{problem}')

    # ---------------------------------------------------------------- running
    def run(self, sm: ScenarioMapping, x: np.ndarray, values: list[dict],
            inputs: np.ndarray | None,
            stopping: Callable[[], bool] | None = None) -> list[np.ndarray]:
        """Run each design (row of ``x``, FMU parameter values ``values``) on a child.

        ``sm``: the scenario's mapping; ``inputs``: its road inputs (n_steps + 1, 4) in
        FMU units, or None.
        Returns each design's outputs (n_outputs, n_steps + 1) in FMU units, in order.
        After the first failure no further design is started; the designs running
        finish (or time out).

        Raises
        ------
        FmuRunCancelledError
            :meth:`cancel`, :meth:`close` or ``stopping()`` stopped the run (the designs
            running are killed).
        FmuRunError
            A design failed (the lowest-numbered failure is reported), or the FMU could
            not be loaded in a child process.
        """
        with self._run_lock:
            with self._state_lock:
                if self._closed:
                    raise FmuRunCancelledError('the FMU model is closed')
                self._running, self._cancelled = True, False
            try:
                self._started(stopping)
                return self._run(sm, x, values, inputs, stopping)
            finally:
                with self._state_lock:
                    self._running = False

    def _stop_reason(self, stopping: Callable[[], bool] | None) -> str:
        if self._closed:
            return 'the model was closed'
        if self._cancelled:
            return 'cancel requested'
        if stopping is not None and stopping():
            return 'the worker is stopping'
        return ''

    def _run(self, sm: ScenarioMapping, x: np.ndarray, values: list[dict],
             inputs: np.ndarray | None, stopping: Callable[[], bool] | None) -> list:
        queue = collections.deque(range(len(x)))
        out: list[np.ndarray | None] = [None] * len(x)
        failures: dict[int, str] = {}
        start_problem = None
        while True:
            reason = self._stop_reason(stopping)
            if reason:
                busy = [c for c in self._children if c.state == 'busy']
                for child in busy:
                    self._replace(child)
                stopped = ', '.join(f'{design_label(c.index, c.x)} '
                                    + (f'at t = {c.t:.6g} s' if not math.isnan(c.t)
                                       else 'before its run started') for c in busy)
                raise FmuRunCancelledError(f'FMU run stopped ({reason})' +
                                      (f': {stopped}' if stopped else ''))
            if not failures and start_problem is None:
                for child in list(self._children):
                    if child.state == 'idle' and queue:
                        index = queue.popleft()
                        if not self._send(child, sm.name, index, x, values, inputs):
                            queue.appendleft(index)  # its child had died idle: replaced
            busy = [c for c in self._children if c.state == 'busy']
            if not busy and (failures or start_problem or not queue):
                break
            waiting = busy + [c for c in self._children if c.state == 'starting']
            now = time.monotonic()
            deadlines = ([c.sent + self.timeout_s for c in busy]
                         + [c.started + START_TIMEOUT_S for c in waiting if c not in busy])
            wait_s = min(POLL_S, max(0.0, min(deadlines) - now))
            connection.wait([c.conn for c in waiting] + [c.process.sentinel for c in waiting]
                            + [self._wake_r], wait_s)
            while self._wake_r.poll():
                self._wake_r.recv_bytes()
            for child in waiting:
                problem = self._collect(child, out, failures)
                start_problem = start_problem or problem
            now = time.monotonic()
            for child in list(self._children):
                if child.state == 'busy' and now - child.sent > self.timeout_s:
                    failures[child.index] = (
                        f'{design_label(child.index, child.x)}: no result within '
                        f'{self.timeout_s:g} s ({self.timeout_name}): the FMU hung '
                        f'{_when(child.t)}; its process was stopped.{_said(child.recent)}')
                    self._replace(child)
                elif child.state == 'starting' and now - child.started > START_TIMEOUT_S:
                    start_problem = f'it did not load within {START_TIMEOUT_S:g} s'
                    self._replace(child)
        if failures:
            raise FmuRunError(failures[min(failures)])
        if start_problem:
            raise FmuRunError(f'the FMU could not be loaded in a child process: '
                              f'{start_problem}')
        return out

    def _send(self, child: _Child, scenario: str, index: int, x: np.ndarray,
              values: list[dict], inputs: np.ndarray | None) -> bool:
        """Send design ``index`` to an idle child; False if the child had died."""
        fresh = scenario not in child.scenarios
        child.progress.value = math.nan
        child.recent.clear()
        try:
            child.conn.send((scenario, index, x[index], values[index], fresh,
                             inputs if fresh else None))
        except OSError:
            self._replace(child)
            return False
        child.index, child.x, child.sent, child.state = index, x[index], time.monotonic(), 'busy'
        child.scenarios.add(scenario)
        return True

    def cancel(self) -> bool:
        """Stop the run in progress (its designs fail as cancelled); False if none runs."""
        with self._state_lock:
            if not self._running:
                return False
            self._cancelled = True
        self._wake()
        return True

    def _wake(self) -> None:
        try:
            self._wake_w.send_bytes(b'!')
        except OSError:
            pass

    def close(self) -> None:
        """Stop a run in progress and every child (idempotent)."""
        with self._state_lock:
            if self._closed:
                return
            self._closed = True
        self._wake()
        locked = self._run_lock.acquire(timeout=5.0)  # a run ends within POLL_S
        try:
            # Not waiting for a start under way: the starter stops what it started.
            with self._state_lock:
                children = list(self._children)
            for child in children:
                self._stop(child)
            self._wake_r.close()
            self._wake_w.close()
        finally:
            if locked:
                self._run_lock.release()


class IsolatedFmuModel(FmuModel):
    """An :class:`~suspension_tuning.fmu.model.FmuModel` whose designs run in child processes.

    The FMU and mapping are checked here, as by FmuModel; each design then runs in a
    child of a :class:`FmuProcessPool`.

    Parameters
    ----------
    fmu_path, mapping
        As for FmuModel.
    timeout_s : float
        Wall-clock time one design may take, s.
    processes : int
        Child processes, i.e. designs of one request run at the same time.
    on_message : callable, optional
        Receives the FMU's log messages (:class:`~suspension_tuning.fmu.fmi_log.FmuMessage`).
    stopping : callable, optional
        Checked every :data:`POLL_S` while designs run; True stops the run
        (:class:`FmuRunCancelledError`), e.g. when the worker shuts down.

    Raises
    ------
    FmuConfigError
        As FmuModel, or a timeout or a number of processes that is not positive.
    """

    def __init__(self, fmu_path: str | Path, mapping: FmuMapping | str | Path,
                 timeout_s: float = DEFAULT_TIMEOUT_S, processes: int = 1,
                 on_message: Callable[[FmuMessage], None] | None = None,
                 stopping: Callable[[], bool] | None = None,
                 designs_per_process: int = DESIGNS_PER_PROCESS) -> None:
        if not (isinstance(timeout_s, (int, float)) and math.isfinite(timeout_s)
                and timeout_s > 0):
            raise FmuConfigError(f'fmu_timeout_s must be a positive number of seconds, got '
                                 f'{timeout_s!r}')
        if isinstance(processes, bool) or not isinstance(processes, int) or processes < 1:
            raise FmuConfigError(f'fmu_processes must be a whole number of at least 1, got '
                                 f'{processes!r}')
        super().__init__(fmu_path, mapping)
        self.on_message = on_message
        self.stopping = stopping
        try:
            self.pool = FmuProcessPool(self.path, self.mapping, processes, timeout_s,
                                       on_message, designs_per_process)
        except BaseException:
            super().close()
            raise

    def _run_designs(self, sm: ScenarioMapping, x: np.ndarray, values: list[dict],
                     inputs: np.ndarray | None) -> np.ndarray:
        return np.stack(self.pool.run(sm, x, values, inputs, self.stopping))

    def cancel(self) -> bool:
        """Stop the designs running now (their request fails as cancelled); False if none."""
        return self.pool.cancel()

    @contextlib.contextmanager
    def run_timeout(self, timeout_s: float, name: str) -> Iterator[None]:
        """Within the block, a design may take ``timeout_s`` at most.

        Not more than ``fmu_timeout_s``; the error of a design stopped names ``name``.
        """
        saved = self.pool.timeout_s, self.pool.timeout_name
        if timeout_s < saved[0]:
            self.pool.timeout_s, self.pool.timeout_name = float(timeout_s), name
        try:
            yield
        finally:
            self.pool.timeout_s, self.pool.timeout_name = saved

    def close(self) -> None:
        """Stop the child processes, then close as FmuModel."""
        pool = getattr(self, 'pool', None)
        if pool is not None:
            pool.close()
        super().close()
