"""The FMU's own log messages: the FMI logger callback of one design's instance.

:class:`FmuLog` is the logger FMPy hands the FMU at instantiation (FMI 2.0 through
FMPy's native proxy, which formats the printf-style arguments; FMI 3.0 directly).  It
keeps the design's last messages for its error, and passes each on as an
:class:`FmuMessage` (to the worker's log, or from a child process to its parent).
"""

from __future__ import annotations

import collections
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

#: FMI status names by value (fmi2Status / fmi3Status), for messages.
FMI_STATUS = ('ok', 'warning', 'discard', 'error', 'fatal', 'pending')
#: Messages of one design passed on to ``on_message``: an FMU with debug logging may
#: write one per step; the rest of the design's messages are counted, not passed on.
MESSAGES_PER_DESIGN = 100
#: The FMU's last messages of a failed design quoted in its error.
MESSAGES_IN_ERROR = 5
#: Characters of one message kept (an FMU's traceback can run to pages).
MESSAGE_CHARS = 400


@dataclass(frozen=True)
class FmuMessage:
    """One message the FMU logged through the FMI logger callback.

    Attributes
    ----------
    design : int
        Index of the design in its request.
    time_s : float
        Simulation time of the step during which it came, s.
    status : int
        FMI status (0 ok, 1 warning, 2 discard, 3 error, 4 fatal).
    category : str
        The FMU's log category ('' when it gives none).
    text : str
        The message, on one line.
    """

    design: int
    time_s: float
    status: int
    category: str
    text: str

    def __str__(self) -> str:
        """``[fatal] category: text``."""
        status = FMI_STATUS[self.status] if 0 <= self.status < len(FMI_STATUS) else self.status
        return f'[{status}] ' + (f'{self.category}: ' if self.category else '') + self.text


class FmuLog:
    """The FMI logger callback of one design's instance: keeps and passes on its messages."""

    def __init__(self, design: int, clock: Callable[[], float],
                 sink: Callable[[FmuMessage], None] | None) -> None:
        self.design, self.clock, self.sink = design, clock, sink
        self.count = 0
        self.recent: collections.deque[FmuMessage] = collections.deque(maxlen=MESSAGES_IN_ERROR)
        self.callbacks = None

    def add(self, status: int, category: Any, message: Any) -> None:
        """Keep and pass on one message (bytes or text; ``status`` an FMI status)."""
        try:  # an exception here would be printed by ctypes and lost
            def text(value: Any) -> str:
                if isinstance(value, bytes):
                    value = value.decode('utf-8', 'replace')
                return re.sub(r'\s+', ' ', str(value or '')).strip()
            body = text(message)
            if len(body) > MESSAGE_CHARS:
                body = body[:MESSAGE_CHARS] + ' ...'
            entry = FmuMessage(self.design, float(self.clock()), int(status), text(category),
                               body)
            self.count += 1
            self.recent.append(entry)
            if self.sink is not None and self.count <= MESSAGES_PER_DESIGN:
                self.sink(entry)
            elif self.sink is not None and self.count == MESSAGES_PER_DESIGN + 1:
                self.sink(FmuMessage(self.design, entry.time_s, 0, '',
                                     f'more than {MESSAGES_PER_DESIGN} messages: the rest of '
                                     'this design\'s are not logged'))
        except Exception:  # noqa: BLE001,S110 - logging must never fail the run
            pass

    def fmi2(self, _env, _instance, status, category, message) -> None:
        """fmi2CallbackLogger (after FMPy's proxy has formatted the message)."""
        self.add(status, category, message)

    def fmi3(self, _env, status, category, message) -> None:
        """fmi3LogMessageCallback."""
        self.add(status, category, message)

    def instantiate(self, slave, fmi3: bool) -> None:
        """``slave.instantiate`` with this logger and logging on."""
        if fmi3:
            slave.instantiate(loggingOn=True, logMessage=self.fmi3)
            return
        from ctypes import byref

        from fmpy import calloc, free
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(self.fmi2)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:  # FMPy's native proxy formats the printf-style arguments ctypes cannot pass
            from fmpy.logging import addLoggerProxy
            addLoggerProxy(byref(callbacks))
        except Exception:  # noqa: BLE001,S110 - then the messages come unformatted
            pass
        self.callbacks = callbacks  # FMPy keeps it on the slave too
        slave.instantiate(callbacks=callbacks, loggingOn=True)

    def summary(self) -> str:
        """`` The FMU said: [fatal] ...; [error] ...`` (its last messages), or ''."""
        if not self.recent:
            return ''
        return ' The FMU said: ' + '; '.join(str(m) for m in self.recent)
