"""rosbag2 metadata: the directory's ``metadata.yaml`` and the ``offered_qos_profiles`` YAML of a topic.

``metadata.yaml`` (rosbag2 format version 9) lists the MCAP files and the topics with their types,
counts and offered QoS; ``rosbags`` and ``ros2 bag`` need it to open a directory. The offered QoS profiles
are also stored in each MCAP channel's metadata under ``offered_qos_profiles`` (as rosbag2 does) so that a
bare ``.mcap`` keeps them and replay can publish with the original QoS.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

METADATA_FILE = 'metadata.yaml'
ROSBAG2_VERSION = 9

# rosbag2 stored the policies as integers (rmw enum values) before version 9.
_HISTORY = {0: 'system_default', 1: 'keep_last', 2: 'keep_all'}
_RELIABILITY = {0: 'system_default', 1: 'reliable', 2: 'best_effort'}
_DURABILITY = {0: 'system_default', 1: 'transient_local', 2: 'volatile'}


def qos_profile(reliable: bool = True, transient_local: bool = False, depth: int = 10) -> dict[str, Any]:
    """A QoS profile in rosbag2's YAML form (deadline, lifespan, lease left at the rmw default)."""
    unset = {'sec': 0, 'nsec': 0}
    return {
        'history': 'keep_last', 'depth': depth,
        'reliability': 'reliable' if reliable else 'best_effort',
        'durability': 'transient_local' if transient_local else 'volatile',
        'deadline': dict(unset), 'lifespan': dict(unset), 'liveliness': 'automatic',
        'liveliness_lease_duration': dict(unset), 'avoid_ros_namespace_conventions': False,
    }


def dump_qos(profiles: list[dict[str, Any]]) -> str:
    """The ``offered_qos_profiles`` string of a topic."""
    return yaml.safe_dump(profiles, default_flow_style=False, sort_keys=False) if profiles else ''


def parse_qos(text: str) -> list[dict[str, Any]]:
    """Profiles from an ``offered_qos_profiles`` string, policies normalised to lower-case names."""
    profiles = yaml.safe_load(text) if text else None
    if not isinstance(profiles, list):
        return []
    return [_normalise(profile) for profile in profiles if isinstance(profile, dict)]


def _normalise(profile: dict[str, Any]) -> dict[str, Any]:
    """Policies given as rmw enum integers or in any case -> lower-case names (absent ones stay absent)."""
    for key, names in (('history', _HISTORY), ('reliability', _RELIABILITY), ('durability', _DURABILITY)):
        value = profile.get(key)
        if value is not None:
            profile[key] = names.get(value, 'system_default') if isinstance(value, int) else str(value).lower()
    return profile


_QOS_KEYS = {'history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan', 'liveliness',
             'liveliness_lease_duration', 'avoid_ros_namespace_conventions'}


def read_qos_overrides(path: Path | str) -> dict[str, dict[str, Any]]:
    """``{topic: profile}`` from a rosbag2 QoS overrides file (``ros2 bag play --qos-profile-overrides-path``):
    a YAML mapping of topic names to partial profiles (``reliability: best_effort``, ``durability``,
    ``history``, ``depth`` ...), normalised like :func:`parse_qos`. ValueError says what is wrong."""
    try:
        document = yaml.safe_load(Path(path).read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise ValueError(f'QoS overrides file {path}: cannot read it as YAML ({err})') from None
    if not isinstance(document, dict) or not all(isinstance(v, dict) for v in document.values()):
        raise ValueError(f'QoS overrides file {path}: must map topic names to QoS profiles '
                         '(e.g. "/particle/pose: {reliability: best_effort}")')
    for topic, profile in document.items():
        unknown = set(profile) - _QOS_KEYS
        if unknown:
            raise ValueError(f'QoS overrides file {path}: {topic}: unknown polic{"ies" if len(unknown) > 1 else "y"} '
                             f'{", ".join(sorted(unknown))} (known: {", ".join(sorted(_QOS_KEYS))})')
    return {str(topic): _normalise(dict(profile)) for topic, profile in document.items()}


@dataclass
class FileInfo:
    """One MCAP file of a log: name relative to the directory, first log time [ns], span [ns], count."""

    path: str
    start_ns: int = 0
    duration_ns: int = 0
    message_count: int = 0


@dataclass
class TopicInfo:
    """One recorded topic: name, ``pkg/msg/Type``, offered QoS YAML and message count."""

    name: str
    type: str
    offered_qos_profiles: str = ''
    message_count: int = 0


@dataclass
class BagMetadata:
    """The content of ``metadata.yaml``."""

    files: list[FileInfo] = field(default_factory=list)
    topics: list[TopicInfo] = field(default_factory=list)
    custom_data: dict[str, str] = field(default_factory=dict)

    def to_yaml(self) -> str:
        start = min((f.start_ns for f in self.files if f.message_count), default=0)
        end = max((f.start_ns + f.duration_ns for f in self.files if f.message_count), default=0)
        info = {
            'version': ROSBAG2_VERSION,
            'storage_identifier': 'mcap',
            'relative_file_paths': [f.path for f in self.files],
            'duration': {'nanoseconds': end - start},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': sum(f.message_count for f in self.files),
            'topics_with_message_count': [
                {'topic_metadata': {'name': t.name, 'type': t.type, 'serialization_format': 'cdr',
                                    'offered_qos_profiles': t.offered_qos_profiles,
                                    'type_description_hash': ''},
                 'message_count': t.message_count} for t in self.topics],
            'compression_format': '',
            'compression_mode': '',
            'files': [{'path': f.path, 'starting_time': {'nanoseconds_since_epoch': f.start_ns},
                       'duration': {'nanoseconds': f.duration_ns}, 'message_count': f.message_count}
                      for f in self.files],
            'custom_data': dict(self.custom_data),
            'ros_distro': 'kilted',
        }
        return yaml.safe_dump({'rosbag2_bagfile_information': info}, default_flow_style=False, sort_keys=False)

    def write(self, directory: Path) -> None:
        """Write ``metadata.yaml`` atomically (a crash leaves the old one or the new one, never half)."""
        tmp = directory / (METADATA_FILE + '.tmp')
        tmp.write_text(self.to_yaml())
        tmp.replace(directory / METADATA_FILE)


class LogFormatError(ValueError):
    """A file that is not a log (not MCAP, or a ``metadata.yaml`` that is not rosbag2's)."""


def read_file_list(directory: Path) -> list[Path] | None:
    """The MCAP files ``metadata.yaml`` lists, or None when the directory has none (a crashed
    recording); :class:`LogFormatError` when the file is not rosbag2 metadata."""
    path = directory / METADATA_FILE
    if not path.is_file():
        return None
    try:
        document = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise LogFormatError(f'{path} is not rosbag2 metadata (not YAML: {err})') from None
    info = document.get('rosbag2_bagfile_information') if isinstance(document, dict) else None
    files = info.get('relative_file_paths') if isinstance(info, dict) else None
    if not isinstance(files, list) or not all(isinstance(p, str) for p in files):
        raise LogFormatError(f'{path} is not rosbag2 metadata (no rosbag2_bagfile_information with '
                             'relative_file_paths): not a log')
    return [directory / Path(p).name for p in files]


def read_custom_data(directory: Path) -> dict[str, str]:
    """The ``custom_data`` of a directory's ``metadata.yaml`` (the recorder's counters, and why a recording
    stopped early); {} when it has none or cannot be read."""
    try:
        document = yaml.safe_load((directory / METADATA_FILE).read_text())
    except (OSError, yaml.YAMLError, UnicodeDecodeError):
        return {}
    info = document.get('rosbag2_bagfile_information') if isinstance(document, dict) else None
    custom = info.get('custom_data') if isinstance(info, dict) else None
    return {str(k): str(v) for k, v in custom.items()} if isinstance(custom, dict) else {}
