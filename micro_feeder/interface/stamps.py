"""Sim time on the wire: one pair of converters between seconds (float) and ROS stamps (sec, nanosec).

A stamp is the sim time rounded to the nanosecond; everything that writes or reads one goes through here.
"""

from __future__ import annotations

import struct
from typing import Any

from builtin_interfaces.msg import Duration, Time


def to_ns(t: float) -> int:
    """Sim time ``t`` (s) as integer nanoseconds, rounded as every stamp is."""
    return round(t * 1e9)


def stamp_parts(t: float) -> tuple[int, int]:
    """``t`` (s, >= 0) as (sec, nanosec) of a ROS Time or Duration, rounded to the nanosecond."""
    return divmod(to_ns(t), 1_000_000_000)


def to_time(t: float) -> Time:
    """Sim time ``t`` (s, >= 0) as a ROS Time, rounded to the nanosecond."""
    sec, nanosec = stamp_parts(t)
    return Time(sec=sec, nanosec=nanosec)


def to_duration(t: float) -> Duration:
    """A duration ``t`` (s, >= 0) as a ROS Duration, rounded to the nanosecond."""
    sec, nanosec = stamp_parts(t)
    return Duration(sec=sec, nanosec=nanosec)


def seconds(t: Any) -> float:
    """A ROS Time or Duration (anything with ``sec`` and ``nanosec``) in seconds; inverse of :func:`to_time`."""
    return t.sec + t.nanosec * 1e-9


def stamp_ns(t: Any) -> int:
    """A ROS Time (anything with ``sec`` and ``nanosec``) as integer nanoseconds, exactly."""
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def header_stamp(data: bytes) -> float:
    """``header.stamp`` (s) of a serialized message that starts with a Header (CDR, either byte order), read
    without deserializing the rest; 0 when the bytes are too short."""
    if len(data) < 12:
        return 0.0
    sec, nanosec = struct.unpack_from('<iI' if data[1] == 1 else '>iI', data, 4)
    return sec + nanosec * 1e-9


def header_frame_id(data: bytes) -> str:
    """``header.frame_id`` of a serialized little-endian message that starts with a Header, read without
    deserializing the rest; '' when absent, cut short or not UTF-8."""
    if len(data) < 16 or data[1] != 1:
        return ''
    (length,) = struct.unpack_from('<I', data, 12)
    if length <= 1 or 16 + length > len(data):
        return ''
    try:
        return data[16:15 + length].decode()
    except UnicodeDecodeError:
        return ''


def header_stamp_ns(data: bytes) -> int:
    """``header.stamp`` [ns] of a CDR message whose first field is a ``std_msgs/Header`` (negative as 0)."""
    fmt = '<iI' if data[1] == 1 else '>iI'  # encapsulation: 0x0001 = little-endian CDR
    sec, nanosec = struct.unpack_from(fmt, data, 4)
    return max(0, sec * 1_000_000_000 + nanosec)
