"""Where the package's configuration lives, in a source tree or an installed package."""

from __future__ import annotations

import contextvars
import copy
import functools
import hashlib
import os
from pathlib import Path
from typing import Any

import yaml

#: Environment variable naming a configuration folder in place of the package's.
CONFIG_DIR_VARIABLE = 'SUSPENSION_TUNING_CONFIG_DIR'


def config_dir() -> Path:
    """The ``config/`` folder: the source tree's, else the installed share folder's.

    An editable install (``make setup``) reads the repository's ``config/``; a colcon
    install reads ``share/suspension_tuning/config`` through the ament index.  The
    environment variable ``SUSPENSION_TUNING_CONFIG_DIR`` names another folder of the
    same files (e.g. a copy with one number changed), read by every node and command
    started with it.
    """
    chosen = os.environ.get(CONFIG_DIR_VARIABLE)
    if chosen:
        return Path(chosen).expanduser().resolve()
    source = Path(__file__).resolve().parents[1] / 'config'
    if source.is_dir():
        return source
    from ament_index_python.packages import get_package_share_directory

    return Path(get_package_share_directory('suspension_tuning')) / 'config'


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Parse a configuration file once; later calls get a fresh copy of the mapping.

    Every full-model run reads its parameters (vehicle, strut, tyre, scenarios, road):
    parsed anew each time they cost ~10 ms of a 20-45 ms run.  The parse is cached per
    file, path and modification time, so an edited file is read again, and each caller
    gets its own deep copy to change freely.  libyaml's C parser is used when PyYAML
    has it.

    Raises
    ------
    ValueError
        If the file is not valid YAML (the message gives the line and column) or does
        not hold a mapping at the top level.
    """
    resolved = Path(path).resolve()
    stat = resolved.stat()
    data = copy.deepcopy(_parse_yaml(str(resolved), stat.st_mtime_ns, stat.st_size))
    tracker = KEY_TRACKER.get()
    return data if tracker is None else tracker.wrap(data, str(path))


@functools.lru_cache(maxsize=64)
def _parse_yaml(path: str, mtime_ns: int, size: int) -> dict[str, Any]:
    loader = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
    with open(path, encoding='utf-8') as handle:
        try:
            data = yaml.load(handle, Loader=loader)  # noqa: S506 - a safe loader
        except yaml.YAMLError as error:
            raise ValueError(f'{path}: {yaml_error_text(error)}') from None
    if not isinstance(data, dict):
        raise ValueError(f'{path}: expected a YAML mapping at the top level')
    return data


def yaml_error_text(error: yaml.YAMLError) -> str:
    """One line for a YAML syntax error: where (1-based line, column) and what."""
    mark = getattr(error, 'problem_mark', None)
    problem = getattr(error, 'problem', None) or str(error).split('\n')[0]
    where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark is not None else ''
    return f'not valid YAML{where}: {problem}'


class KeyTracker:
    """Records the last key read from the mappings :func:`read_yaml` returns.

    Used by :mod:`suspension_tuning.config_check`: a loader that fails on a missing key
    or on a value it cannot convert says which key of which file it was.
    """

    def __init__(self) -> None:
        self.last: tuple[str, str] | None = None  # (file, dotted key)

    def wrap(self, data: dict[str, Any], source: str, prefix: str = '') -> dict[str, Any]:
        """``data`` as a mapping that reports each key read to this tracker."""
        return _TrackedDict(data, self, source, prefix)


class _TrackedDict(dict):
    def __init__(self, data: dict[str, Any], tracker: KeyTracker, source: str,
                 prefix: str) -> None:
        super().__init__(data)
        self._tracker, self._source, self._prefix = tracker, source, prefix

    def _child(self, key: Any, value: Any) -> Any:
        name = f'{self._prefix}{key}'
        self._tracker.last = (self._source, name)
        if isinstance(value, dict) and not isinstance(value, _TrackedDict):
            return _TrackedDict(value, self._tracker, self._source, name + '.')
        return value

    def __getitem__(self, key: Any) -> Any:
        try:
            value = super().__getitem__(key)
        except KeyError:
            self._tracker.last = (self._source, f'{self._prefix}{key}')
            raise
        return self._child(key, value)

    def get(self, key: Any, default: Any = None) -> Any:
        return self._child(key, super().get(key, default)) if key in self else default


#: The tracker :func:`read_yaml` reports to, while a configuration check runs.
KEY_TRACKER: contextvars.ContextVar[KeyTracker | None] = contextvars.ContextVar(
    'KEY_TRACKER', default=None)


def dump_yaml(data: Any) -> str:
    """YAML text of plain data, keys in insertion order (libyaml's emitter when present).

    PyYAML's pure-Python emitter takes about 1.5 ms for a run's configuration, paid
    at the start of every optimisation through the graph; libyaml's takes a tenth.
    """
    dumper = getattr(yaml, 'CSafeDumper', yaml.SafeDumper)
    return yaml.dump(data, Dumper=dumper, sort_keys=False)


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes, read in 1 MiB blocks (FMUs, road files)."""
    h = hashlib.sha256()
    with open(path, 'rb') as f:
        for block in iter(lambda: f.read(1 << 20), b''):
            h.update(block)
    return h.hexdigest()
