"""Where the package's configuration lives, in a source tree or an installed package."""

from __future__ import annotations

import copy
import functools
import hashlib
from pathlib import Path
from typing import Any

import yaml


def config_dir() -> Path:
    """The ``config/`` folder: the source tree's, else the installed share folder's.

    An editable install (``make setup``) reads the repository's ``config/``; a colcon
    install reads ``share/suspension_tuning/config`` through the ament index.
    """
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
        If the file does not hold a mapping at the top level.
    """
    resolved = Path(path).resolve()
    stat = resolved.stat()
    return copy.deepcopy(_parse_yaml(str(resolved), stat.st_mtime_ns, stat.st_size))


@functools.lru_cache(maxsize=64)
def _parse_yaml(path: str, mtime_ns: int, size: int) -> dict[str, Any]:
    loader = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
    with open(path, encoding='utf-8') as handle:
        data = yaml.load(handle, Loader=loader)  # noqa: S506 - a safe loader
    if not isinstance(data, dict):
        raise ValueError(f'{path}: expected a YAML mapping at the top level')
    return data


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
