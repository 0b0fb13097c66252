"""Complete ``ros2msg`` message definitions, as rosbag2 stores them in MCAP schemas.

Format (ros2/rosbag2 ``docs/message_definition_encoding.md``; MCAP specification,
appendix "ros2msg"): the top-level definition first, then every type it depends on,
recursively, each preceded by a line of exactly 80 ``=`` characters and a line
``MSG: pkg/kind/Type``.

Where the text comes from:

* ``pkg/msg/T``: the installed ``<share>/pkg/msg/T.msg`` file, verbatim (constants
  and comments kept);
* ``pkg/srv/T_Request`` and ``_Response``: the sections of ``<share>/pkg/srv/T.srv``
  separated by ``---``; ``pkg/action/T_Goal``, ``_Result`` and ``_Feedback``: the
  sections of ``<share>/pkg/action/T.action``;
* types with no interface file of their own (service events ``pkg/srv/T_Event``,
  ``pkg/action/T_FeedbackMessage``, ``T_SendGoal_Request``, ...): generated from the
  generated Python class (``SLOT_TYPES``), which is what the middleware serialises.

Field types use the two-part form of the .msg format (``std_msgs/Header``), also for
the nested types of service events and action messages (``pkg/EvaluateDesign_Request``
in ``pkg/srv/EvaluateDesign_Event``): a .msg field cannot name the ``srv``/``action``
namespace (the parsers of mcap-ros2-support and rosbags reject three-part field
types).  Each dependency's ``MSG:`` header is therefore the name its field reference
resolves to, ``pkg/msg/Name``: rosbags resolves ``pkg/Name`` to exactly that,
mcap-ros2-support matches package and name.  Checked in test/test_bag_writer.py with
both readers.  (rosbag2 itself finds no .msg file for ``T_Event`` types and leaves
their definition empty or falls back to IDL.)
"""

from __future__ import annotations

import importlib
import json
import re
import sys
from functools import cache
from pathlib import Path

#: Separator line between definitions (exactly 80 '=' characters).
SEPARATOR = '=' * 80

#: Primitive field types of the .msg format (no dependency).
PRIMITIVES = frozenset(
    {
        'bool',
        'byte',
        'char',
        'float32',
        'float64',
        'int8',
        'uint8',
        'int16',
        'uint16',
        'int32',
        'uint32',
        'int64',
        'uint64',
        'string',
        'wstring',
    }
)

#: IDL basic type names (rosidl_parser) -> .msg names.
_IDL_TO_MSG = {
    'boolean': 'bool',
    'octet': 'byte',
    'char': 'char',
    'wchar': 'char',
    'float': 'float32',
    'double': 'float64',
    'long double': 'float64',
    'int8': 'int8',
    'uint8': 'uint8',
    'int16': 'int16',
    'uint16': 'uint16',
    'int32': 'int32',
    'uint32': 'uint32',
    'int64': 'int64',
    'uint64': 'uint64',
}

_TYPE_RE = re.compile(r'^(?P<pkg>[A-Za-z][\w]*)/(?:(?P<kind>msg|srv|action)/)?(?P<name>\w+)$')


class DefinitionNotFoundError(LookupError):
    """No definition could be found or built for a type name."""


def normalise_type_name(type_name: str) -> str:
    """Return ``pkg/kind/Name`` for ``pkg/Name`` (kind msg) or ``pkg/kind/Name``.

    Raises
    ------
    ValueError
        If the name is not of the form ``pkg/Name`` or ``pkg/{msg,srv,action}/Name``.
    """
    match = _TYPE_RE.match(type_name)
    if not match:
        raise ValueError(f'type name {type_name!r} is not pkg/Name or pkg/kind/Name')
    return f'{match["pkg"]}/{match["kind"] or "msg"}/{match["name"]}'


@cache
def _share_directory(package: str) -> Path:
    """``<prefix>/share/<package>`` from the ament index, else from this interpreter's prefix.

    The fallback covers a venv used without AMENT_PREFIX_PATH (the ROS wheels install
    their share folders into ``sys.prefix``).
    """
    from ament_index_python.packages import (
        PackageNotFoundError,
        get_package_share_directory,
    )

    try:
        return Path(get_package_share_directory(package))
    except (PackageNotFoundError, OSError):
        fallback = Path(sys.prefix) / 'share' / package
        if fallback.is_dir():
            return fallback
    raise DefinitionNotFoundError(f'package {package!r} is not in the ament index')


def _interface_file(package: str, kind: str, stem: str) -> Path | None:
    try:
        path = _share_directory(package) / kind / f'{stem}.{kind}'
    except DefinitionNotFoundError:
        return None
    return path if path.is_file() else None


def _sections(path: Path) -> list[str]:
    """Split a .srv/.action file at its ``---`` lines."""
    parts: list[list[str]] = [[]]
    for line in path.read_text().splitlines():
        if line.strip() == '---':
            parts.append([])
        else:
            parts[-1].append(line)
    return ['\n'.join(p).strip('\n') + '\n' if any(s.strip() for s in p) else '' for p in parts]


def message_class(type_name: str) -> type:
    """The generated Python class of ``pkg/kind/Name`` (also ``T_Event``, ``T_FeedbackMessage``).

    Raises
    ------
    DefinitionNotFoundError
        If the module or the class cannot be imported.
    """
    full_name = normalise_type_name(type_name)
    package, kind, name = full_name.split('/')
    try:
        module = importlib.import_module(f'{package}.{kind}')
    except ImportError as exc:
        raise DefinitionNotFoundError(f'no Python module {package}.{kind}') from exc
    if isinstance(getattr(module, name, None), type):
        return getattr(module, name)
    # Composed types (T_Event, T_FeedbackMessage, ...) live in the submodule of T.
    for value in vars(module).values():
        if isinstance(value, type):
            submodule = importlib.import_module(value.__module__)
            candidate = getattr(submodule, name, None)
            if isinstance(candidate, type) and hasattr(candidate, 'SLOT_TYPES'):
                return candidate
    raise DefinitionNotFoundError(f'no Python class for {full_name}')


def _idl_to_msg(slot_type: object) -> str:
    """Write one rosidl_parser type as a .msg field type."""
    cls = type(slot_type).__name__
    if cls == 'BasicType':
        return _IDL_TO_MSG[slot_type.typename]
    if cls == 'UnboundedString':
        return 'string'
    if cls == 'UnboundedWString':
        return 'wstring'
    if cls == 'BoundedString':
        return f'string<={slot_type.maximum_size}'
    if cls == 'BoundedWString':
        return f'wstring<={slot_type.maximum_size}'
    if cls == 'NamespacedType':
        return f'{slot_type.namespaces[0]}/{slot_type.name}'
    if cls == 'Array':
        return f'{_idl_to_msg(slot_type.value_type)}[{slot_type.size}]'
    if cls == 'UnboundedSequence':
        return f'{_idl_to_msg(slot_type.value_type)}[]'
    if cls == 'BoundedSequence':
        return f'{_idl_to_msg(slot_type.value_type)}[<={slot_type.maximum_size}]'
    raise DefinitionNotFoundError(f'unsupported IDL type {cls}')


def _nested_names(slot_type: object) -> list[str]:
    """Full names (pkg/kind/Name) of the message types inside one rosidl_parser type."""
    if type(slot_type).__name__ == 'NamespacedType':
        return ['/'.join([*slot_type.namespaces, slot_type.name])]
    inner = getattr(slot_type, 'value_type', None)
    return _nested_names(inner) if inner is not None else []


def _generated(full_name: str) -> tuple[str, list[str]]:
    """A .msg text generated from the Python class (no constants, no comments).

    Returns the text and the full names of its dependencies (the short ``pkg/Name`` in
    the text loses the ``srv``/``action`` namespace, the class still knows it).
    """
    msg_class = message_class(full_name)
    names = list(msg_class.get_fields_and_field_types())
    lines = [f'{_idl_to_msg(t)} {n}' for t, n in zip(msg_class.SLOT_TYPES, names)]
    deps: list[str] = []
    for slot_type in msg_class.SLOT_TYPES:
        deps += [d for d in _nested_names(slot_type) if d not in deps]
    return '\n'.join(lines) + '\n', deps


def own_text(type_name: str) -> str:
    """The .msg text of one type alone (without its dependencies).

    Parameters
    ----------
    type_name : str
        ``pkg/Name`` or ``pkg/{msg,srv,action}/Name``.

    Raises
    ------
    DefinitionNotFoundError
        If neither an interface file nor a generated Python class is found.
    """
    return _own(normalise_type_name(type_name))[0]


@cache
def _own(full: str) -> tuple[str, list[str]]:
    """Text of one type and the full names of the types its fields use."""
    package, kind, name = full.split('/')
    if kind == 'msg':
        path = _interface_file(package, 'msg', name)
        if path is not None:
            text = path.read_text()
            return text, _dependencies(text, package)
        return _generated(full)
    stem, _, part = name.rpartition('_')
    suffixes = {'srv': ('Request', 'Response'), 'action': ('Goal', 'Result', 'Feedback')}
    if stem and part in suffixes[kind] and '_' not in stem:
        path = _interface_file(package, kind, stem)
        if path is not None:
            sections = _sections(path)
            index = suffixes[kind].index(part)
            if len(sections) == len(suffixes[kind]):
                text = _qualify(sections[index], package)
                return text, _dependencies(text, package)
    return _generated(full)


def _qualify(text: str, package: str) -> str:
    """Prefix unqualified field types with the package (``X`` -> ``pkg/X``).

    In a .srv/.action file a bare name means a message of the same package; once the
    section is stored as the definition of ``pkg/action/T_Result`` a reader would look
    for it in the ``action`` namespace (rosbags does), so the package is written out.
    """
    lines = []
    for line in text.splitlines():
        match = re.match(r'^(\s*)([A-Za-z]\w*)(\[[^\]]*\])?(\s+\w+.*)$', line)
        if match and match[2] not in PRIMITIVES and not line.lstrip().startswith('#'):
            line = f'{match[1]}{package}/{match[2]}{match[3] or ""}{match[4]}'
        lines.append(line)
    return '\n'.join(lines) + ('\n' if text.endswith('\n') else '')


def _dependencies(text: str, package: str) -> list[str]:
    """Full names of the complex field types in a .msg text, in order of appearance."""
    found: list[str] = []
    for raw in text.splitlines():
        line = raw.split('#', 1)[0].strip()
        if not line:
            continue
        field_type, _, rest = line.partition(' ')
        if '=' in rest.split(' ', 1)[0] or re.match(r'^\w+\s*=', rest.strip()):
            continue  # a constant: primitive type only
        base = re.sub(r'\[.*\]$', '', field_type)
        base = re.sub(r'<=\d+$', '', base)
        if base in PRIMITIVES:
            continue
        if base == 'Header':
            full = 'std_msgs/msg/Header'
        elif '/' in base:
            full = normalise_type_name(base)
        else:
            full = f'{package}/msg/{base}'
        if full not in found:
            found.append(full)
    return found


@cache
def definition_text(type_name: str) -> str:
    """Complete ``ros2msg`` definition of a type: its text and all dependencies.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/T``, ``pkg/srv/T_Event`` (service introspection), ``pkg/srv/T_Request``,
        ``pkg/action/T_FeedbackMessage``, ``action_msgs/msg/GoalStatusArray``, ...

    Returns
    -------
    str
        The top-level text, then each dependency (depth-first, each once) after an
        80-character ``=`` line and a ``MSG: pkg/kind/Type`` line.

    Raises
    ------
    DefinitionNotFoundError
        If the type or one of its dependencies cannot be found.
    ValueError
        If the name is malformed.
    """
    top = normalise_type_name(type_name)
    order: list[str] = []

    def visit(full: str) -> None:
        for dep in _own(full)[1]:
            if dep != top and dep not in order:
                order.append(dep)
                visit(dep)

    visit(top)
    parts = [_own(top)[0].rstrip('\n')]
    for dep in order:
        package, _, name = dep.split('/')
        parts += [SEPARATOR, f'MSG: {package}/msg/{name}', _own(dep)[0].rstrip('\n')]
    return '\n'.join(parts) + '\n'


@cache
def type_hash(type_name: str) -> str:
    """RIHS01 type-description hash of a type, from the installed ``.json``, or ''.

    The rosidl generators write ``<share>/pkg/kind/T.json`` with the hashes of the
    type and of its composed types (``T_Event``, ``T_FeedbackMessage``, ...).
    """
    full = normalise_type_name(type_name)
    package, kind, name = full.split('/')
    candidates = [name]
    if '_' in name:
        candidates.append(name.split('_', 1)[0])
    for stem in candidates:
        try:
            path = _share_directory(package) / kind / f'{stem}.json'
        except DefinitionNotFoundError:
            return ''
        if path.is_file():
            for entry in json.loads(path.read_text()).get('type_hashes', []):
                if entry.get('type_name') == full:
                    return str(entry.get('hash_string', ''))
    return ''
