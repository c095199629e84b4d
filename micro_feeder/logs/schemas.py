"""ROS 2 message definitions as MCAP ``ros2msg`` schemas, read from the installed ``.msg`` files.

A ``ros2msg`` schema is the type's own ``.msg`` text followed by the text of every message type it
depends on, each after a line of 80 ``=`` and ``MSG: pkg/Type`` (rosbag2's format), so that a reader
(Foxglove, rosbags, mcap-ros2-support) can decode the CDR bytes without the ROS packages installed.
The ``.msg`` files are looked up under ``<prefix>/share/<pkg>/msg/`` for each prefix in
``AMENT_PREFIX_PATH`` and then ``sys.prefix`` (where the ROS 2 wheels put them); rclpy is not needed.
"""

from __future__ import annotations

import os
import re
import sys
from functools import cache
from pathlib import Path

SEPARATOR = '=' * 80
CONSTANT = re.compile(r'^\w+\s*=')

PRIMITIVE_TYPES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32',
    'int64', 'uint64', 'string', 'wstring'})


class SchemaError(LookupError):
    """A message type whose ``.msg`` definition (or one of its dependencies') cannot be found."""


def normalize_type(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type`` (the name used for schemas and channels)."""
    parts = type_name.split('/')
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3 and parts[1] == 'msg':
        return type_name
    raise SchemaError(f'not a ROS 2 message type name: {type_name!r} (expected pkg/msg/Type)')


def message_prefixes() -> list[Path]:
    """Install prefixes searched for ``share/<pkg>/msg/*.msg``, in search order."""
    prefixes = [Path(p) for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    prefixes.append(Path(sys.prefix))
    return list(dict.fromkeys(prefixes))


@cache
def msg_text(type_name: str) -> str:
    """The ``.msg`` file text of ``pkg/msg/Type``."""
    pkg, _, name = normalize_type(type_name).split('/')
    for prefix in message_prefixes():
        path = prefix / 'share' / pkg / 'msg' / f'{name}.msg'
        if path.is_file():
            return path.read_text()
    searched = ', '.join(str(p) for p in message_prefixes())
    raise SchemaError(f'no definition of {type_name} (looked for share/{pkg}/msg/{name}.msg under {searched})')


def field_types(type_name: str) -> list[tuple[str, str]]:
    """``[(field name, base type)]`` of a message, constants left out; base types of nested messages are
    full ``pkg/msg/Type`` names, arrays and string bounds are stripped (``float64[36]`` -> ``float64``)."""
    pkg = normalize_type(type_name).split('/')[0]
    fields = []
    for raw_line in msg_text(type_name).splitlines():
        line = raw_line.split('#', 1)[0].strip()
        if not line:
            continue
        type_token, _, rest = line.partition(' ')
        rest = rest.strip()
        if CONSTANT.match(rest):
            continue  # a constant: NAME=value
        name = rest.split(' ', 1)[0]
        base = type_token.split('[', 1)[0].split('<=', 1)[0]
        if base not in PRIMITIVE_TYPES:
            base = normalize_type(base if '/' in base else f'{pkg}/{base}')
        fields.append((name, base))
    return fields


def dependencies(type_name: str) -> list[str]:
    """Every message type ``type_name`` depends on, depth first, each once."""
    seen: dict[str, None] = {}

    def visit(name: str) -> None:
        for _, base in field_types(name):
            if base not in PRIMITIVE_TYPES and base not in seen:
                seen[base] = None
                visit(base)

    visit(normalize_type(type_name))
    return list(seen)


@cache
def schema_text(type_name: str) -> str:
    """The ``ros2msg`` schema of a type: its ``.msg`` text, then each dependency's after a separator."""
    parts = [msg_text(type_name).rstrip('\n')]
    for dep in dependencies(type_name):
        pkg, _, name = dep.split('/')
        parts.append(f'{SEPARATOR}\nMSG: {pkg}/{name}\n{msg_text(dep).rstrip(chr(10))}')
    return '\n'.join(parts) + '\n'


@cache
def has_header(type_name: str) -> bool:
    """True when the first field is a ``std_msgs/Header`` (its stamp becomes the publish time)."""
    fields = field_types(type_name)
    return bool(fields) and fields[0][1] == 'std_msgs/msg/Header'
