"""Option dataclasses built from mappings (config sections), shared by the optimisers."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields, replace
from typing import Any, TypeVar

T = TypeVar('T')


def options_from_mapping(cls: type[T], options: T | Mapping[str, Any] | None, label: str,
                         convert: Mapping[str, Any] | None = None) -> T:
    """An options dataclass from itself, a mapping of its fields, or None (defaults).

    Parameters
    ----------
    cls : type
        The frozen options dataclass.
    options : cls, mapping or None
        Field values; a key that is not a field raises ValueError naming ``label``.
    label : str
        What the options belong to, for the message ('Dynamic-Q', 'LFOP', ...).
    convert : mapping, optional
        Field name -> callable applied to that field's value first (e.g. ``float`` for
        a YAML ``.inf``).
    """
    if options is None:
        return cls()
    if isinstance(options, cls):
        return options
    known = {f.name for f in fields(cls)}
    unknown = set(options) - known
    if unknown:
        raise ValueError(f'unknown {label} option(s) {sorted(unknown)}; known: {sorted(known)}')
    values = dict(options)
    for name, function in (convert or {}).items():
        if name in values:
            values[name] = function(values[name])
    return replace(cls(), **values)
