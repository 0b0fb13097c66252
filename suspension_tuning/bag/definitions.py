"""Complete ``ros2msg`` message definitions, written the way rosbag2 writes them.

Format (MCAP specification, appendix "ros2msg"; ros2/rosbag2
``docs/message_definition_encoding.md``): the top-level definition first, then every
type it depends on, each preceded by a line of exactly 80 ``=`` characters and a line
``MSG: <name>``.

Which names, in which order: what rosbag2's recorder does (``rosbag2_cpp``
``LocalMessageDefinitionSource::get_full_text``, Jazzy, and its test
``test_local_message_definition_source.cpp``, which expects ``MSG:
rosbag2_test_msgdefs/BasicMsg`` after a field ``rosbag2_test_msgdefs/BasicMsg b``):

* a dependency is headed with the type name as the field spells it
  (``std_msgs/Header``), a same-package relative name with the package prefixed
  (``<package>/<Type>``); the example in rosbag2's encoding document shows
  ``MSG: my_msgs/msg/BasicMsg``, but neither rosbag2's code nor Foxglove's parser
  (``@foxglove/rosmsg``, which matches dependency names exactly) follows it;
* the complex field types of one text are taken in sorted order (rosbag2 keeps them
  in a ``std::set``), each followed at once by its own dependencies (depth first),
  every name written once;
* each text is appended as it is, after a newline: a file that ends in a newline
  leaves an empty line before the next separator.

Where the text of one type comes from:

* ``pkg/msg/T``: the installed ``<share>/pkg/msg/T.msg`` file, verbatim (constants
  and comments kept);
* ``pkg/srv/T_Request`` and ``_Response``: the sections of ``<share>/pkg/srv/T.srv``
  separated by ``---``; ``pkg/action/T_Goal``, ``_Result`` and ``_Feedback``: the
  sections of ``<share>/pkg/action/T.action`` (same-package names written out as
  ``pkg/Name``, see :func:`_qualify`);
* types with no interface file of their own (service events ``pkg/srv/T_Event``,
  ``pkg/action/T_FeedbackMessage``, ``T_SendGoal_Request``, ...): generated from the
  generated Python class (``SLOT_TYPES``), which is what the middleware serialises.

Field types use the two-part form of the .msg format (``std_msgs/Header``), also for
the nested types of service events and action messages (``pkg/EvaluateDesign_Request``
in ``pkg/srv/EvaluateDesign_Event``, headed ``MSG: pkg/EvaluateDesign_Request``): a .msg
field cannot name the ``srv``/``action`` namespace (the parsers of mcap-ros2-support,
rosbags and Foxglove reject or misread three-part field types).  rosbag2 itself stores
a service-event topic with the ``.srv`` text under ``SRV: pkg/srv/T`` (not the layout
of the ``T_Event`` message on the wire) and finds no definition for action messages;
the definitions here describe the bytes recorded.

Bags written before this layout headed every dependency ``MSG: pkg/msg/Name``;
:func:`rosbag2_form` rewrites such a definition text (used by ``reindex``).
"""

from __future__ import annotations

import importlib
import json
import re
import sys
from collections.abc import Callable
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
        if slot_type.namespaces[-1] == 'action':  # its full name: it enters the hash
            return '/'.join([*slot_type.namespaces, slot_type.name])
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


def _generated(full_name: str) -> tuple[str, dict[str, str]]:
    """A .msg text generated from the Python class (no constants, no comments).

    Returns the text and, sorted, the referenced name -> full name of each type it
    uses: a message and a service's part as ``pkg/Name``, an action's part by its full
    name (``pkg/action/T_Feedback``: the name that enters the type hash; rosbags and
    Foxglove keep it, mcap-ros2-support's parser does not, see bag/reader.py).  A
    service's event is written as ``ros2idl`` in bags (:func:`schema_of`).
    """
    msg_class = message_class(full_name)
    names = list(msg_class.get_fields_and_field_types())
    lines = [f'{_idl_to_msg(t)} {n}' for t, n in zip(msg_class.SLOT_TYPES, names)]
    full: dict[str, str] = {}
    for slot_type in msg_class.SLOT_TYPES:
        for nested in _nested_names(slot_type):
            package, kind, name = nested.split('/')
            full[nested if kind == 'action' else f'{package}/{name}'] = nested
    text = '\n'.join(lines) + '\n'
    return text, {ref: full[ref] for ref in referenced_names(text, full_name.split('/')[0])}


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
def _own(full: str) -> tuple[str, dict[str, str]]:
    """Text of one type and, sorted, referenced name -> full name of the types it uses."""
    package, kind, name = full.split('/')
    if kind == 'msg':
        path = _interface_file(package, 'msg', name)
        if path is not None:
            text = path.read_text()
            return text, _file_dependencies(text, package)
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
                return text, _file_dependencies(text, package)
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


#: Field types of a .msg text as rosbag2 finds them (rosbag2_cpp
#: local_message_definition_source.cpp, ``MSG_FIELD_TYPE_REGEX``): the first word of a
#: line, before any array brackets.  Bounded strings (``string<=5``) do not match.
_FIELD_TYPE_RE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')

#: Deepest nesting followed before giving up (rosbag2_cpp's
#: ROSBAG2_CPP_LOCAL_MESSAGE_DEFINITION_SOURCE_MAX_RECURSION_DEPTH).
MAX_DEPTH = 50


def referenced_names(text: str, package: str) -> list[str]:
    """The complex field types of a .msg text, named as rosbag2 heads them, sorted.

    ``pkg/Type`` as the field spells it, ``<package>/Type`` for a relative name, and
    ``std_msgs/Header`` for a bare ``Header`` (the .msg format's one special name);
    sorted and each once, the order in which rosbag2 appends them.

    Parameters
    ----------
    text : str
        A .msg text (one type, no dependency sections).
    package : str
        The package the text belongs to (context of relative names).
    """
    names: set[str] = set()
    for match in _FIELD_TYPE_RE.finditer(text):
        base = match[1]
        if base in PRIMITIVES:
            continue
        if base == 'Header':
            names.add('std_msgs/Header')
        elif '/' in base:
            names.add(base)
        else:
            names.add(f'{package}/{base}')
    return sorted(names)


def _file_dependencies(text: str, package: str) -> dict[str, str]:
    """Referenced name -> full name (``pkg/msg/T``) of each complex field of a file text."""
    return {name: normalise_type_name(name) for name in referenced_names(text, package)}


def _compose(root: str, own: Callable[[str], tuple[str, dict[str, str]]]) -> str:
    """Concatenate a root text and its dependencies the way rosbag2 does.

    ``own(key)`` returns the text of one type and, sorted by referenced name, the
    referenced name -> key of each type it uses.
    """
    seen: set[str] = set()

    def append(key: str, depth: int) -> str:
        if depth <= 0:
            raise DefinitionNotFoundError(f'{root}: dependencies nest deeper than {MAX_DEPTH}')
        text, deps = own(key)
        for name, dep_key in deps.items():
            if name not in seen:
                seen.add(name)
                text += f'\n{SEPARATOR}\nMSG: {name}\n' + append(dep_key, depth - 1)
        return text

    return append(root, MAX_DEPTH)


@cache
def definition_text(type_name: str) -> str:
    """Complete ``ros2msg`` definition of a type, as rosbag2 writes it into an MCAP schema.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/T``, ``pkg/srv/T_Event`` (service introspection), ``pkg/srv/T_Request``,
        ``pkg/action/T_FeedbackMessage``, ``action_msgs/msg/GoalStatusArray``, ...

    Returns
    -------
    str
        The top-level text, then each dependency once (depth first, the fields of each
        text in sorted order), each after an 80-character ``=`` line and a line
        ``MSG: <name as the field references it>`` (see the module docstring).

    Raises
    ------
    DefinitionNotFoundError
        If the type or one of its dependencies cannot be found.
    ValueError
        If the name is malformed.
    """
    return _compose(normalise_type_name(type_name), _own)


def rosbag2_form(type_name: str, definition: str) -> str:
    """A stored definition whose headers read ``MSG: pkg/msg/Name``, rewritten as rosbag2's.

    Bags written before the rosbag2 layout headed each dependency with its full name
    and listed the dependencies in order of appearance.  The texts stored in the bag
    are kept (they describe the recorded bytes, whatever is installed today); only
    the headers and the order change.  A definition already in rosbag2's form, or one
    with other section kinds (``IDL:``, ``SRV:``), is returned unchanged.

    Parameters
    ----------
    type_name : str
        The schema's type name (``pkg/msg/T``, ``pkg/srv/T_Event``, ...).
    definition : str
        The schema text as stored.

    Raises
    ------
    DefinitionNotFoundError
        If a field's type has no section in the stored text.
    ValueError
        If a name is malformed.
    """
    lines = definition.split('\n')
    starts = [
        k for k in range(len(lines) - 1)
        if lines[k] == SEPARATOR and lines[k + 1].startswith(('MSG: ', 'IDL: ', 'SRV: '))
    ]
    headers = [lines[k + 1] for k in starts]
    if not any(h.startswith('MSG: ') and h.count('/') == 2 for h in headers) or any(
        not h.startswith('MSG: ') for h in headers
    ):
        return definition
    ends = [*starts, len(lines)]
    root_key = normalise_type_name(type_name)
    texts = {root_key: '\n'.join(lines[: ends[0]]).rstrip('\n') + '\n'}
    for start, end in zip(starts, ends[1:]):
        name = normalise_type_name(lines[start + 1][len('MSG: '):].strip())
        texts.setdefault(name, '\n'.join(lines[start + 2 : end]).rstrip('\n') + '\n')

    def own(key: str) -> tuple[str, dict[str, str]]:
        if key not in texts:
            raise DefinitionNotFoundError(f'{type_name}: the stored definition has no {key}')
        return texts[key], _file_dependencies(texts[key], key.split('/')[0])

    return _compose(root_key, own)


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


#: Schema encoding of the types whose full name rosbags' and Foxglove's ``ros2msg``
#: readers cannot keep: services' parts and events (``pkg/srv/T_Event``).
IDL_KINDS = ('srv',)


def _idl_type(slot_type: object) -> str:
    """One rosidl_parser type as an IDL type (arrays are written at the field)."""
    cls = type(slot_type).__name__
    if cls == 'BasicType':
        return str(slot_type.typename)
    if cls in ('UnboundedString', 'UnboundedWString'):
        return 'string' if cls == 'UnboundedString' else 'wstring'
    if cls in ('BoundedString', 'BoundedWString'):
        kind = 'string' if cls == 'BoundedString' else 'wstring'
        return f'{kind}<{slot_type.maximum_size}>'
    if cls == 'NamespacedType':
        return '::'.join([*slot_type.namespaces, slot_type.name])
    if cls == 'UnboundedSequence':
        return f'sequence<{_idl_type(slot_type.value_type)}>'
    if cls == 'BoundedSequence':
        return f'sequence<{_idl_type(slot_type.value_type)}, {slot_type.maximum_size}>'
    raise DefinitionNotFoundError(f'unsupported IDL type {cls}')


def _idl_struct(full_name: str) -> tuple[str, list[str]]:
    """The IDL text of one type (its modules and struct) and the types it uses."""
    msg_class = message_class(full_name)
    package, kind, name = full_name.split('/')
    fields, uses = [], []
    for slot_type, field_name in zip(msg_class.SLOT_TYPES,
                                     msg_class.get_fields_and_field_types()):
        if type(slot_type).__name__ == 'Array':
            fields.append(f'      {_idl_type(slot_type.value_type)} {field_name}'
                          f'[{slot_type.size}];')
        else:
            fields.append(f'      {_idl_type(slot_type)} {field_name};')
        uses += [n for n in _nested_names(slot_type) if n not in uses]
    body = '\n'.join(fields) or '      uint8 structure_needs_at_least_one_member;'
    text = (f'module {package} {{\n  module {kind} {{\n    struct {name} {{\n{body}\n'
            f'    }};\n  }};\n}};\n')
    return text, uses


@cache
def idl_definition_text(type_name: str) -> str:
    """Complete ``ros2idl`` definition of a type, in rosbag2's layout for IDL schemas.

    The type's IDL first, then each type it uses once (depth first), each after an
    80-character ``=`` line and a line ``IDL: <pkg/kind/Name>``; fields only (the
    constants of a message do not enter its type hash nor its bytes).  Every name is
    the full one (``pkg::srv::T_Request``), so a reader that hashes the text (rosbags'
    AnyReader) gets the type's RIHS01 hash: ``ros2msg`` has no name for a service's
    parts that rosbags keeps (it reads ``pkg/srv/T`` as ``pkg/srv/msg/T``).

    Raises
    ------
    DefinitionNotFoundError
        If a type's generated Python class cannot be imported.
    """
    root = normalise_type_name(type_name)
    sections, seen = [], {root}

    def append(full: str) -> None:
        text, uses = _idl_struct(full)
        sections.append(f'{SEPARATOR}\nIDL: {full}\n{text}')
        for used in uses:
            if used not in seen:
                seen.add(used)
                append(used)

    append(root)
    return ''.join(sections)


def schema_of(type_name: str) -> tuple[str, str]:
    """(MCAP schema encoding, definition text) the recorder writes for a type.

    ``ros2idl`` (:func:`idl_definition_text`) for services' parts and events, whose
    full names ``ros2msg`` readers do not keep; ``ros2msg`` (:func:`definition_text`)
    for every other type.
    """
    if normalise_type_name(type_name).split('/')[1] in IDL_KINDS:
        return 'ros2idl', idl_definition_text(type_name)
    return 'ros2msg', definition_text(type_name)
