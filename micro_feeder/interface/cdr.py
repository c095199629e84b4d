"""The few XCDR1 (little endian) rules the hand-serialized messages share, writing and reading.

Fields are aligned to their size relative to the payload start, which is right after the 4-byte
encapsulation header; a string is a uint32 length that counts its terminating NUL, then its UTF-8 bytes
and the NUL. The readers serve the log tools, which read millions of recorded messages: they return None
for anything but the plain layout (big endian, cut short, unexpected trailing bytes), and the caller then
decodes the message in full.
"""

from __future__ import annotations

import struct

import numpy as np

ENCAPSULATION = b'\x00\x01\x00\x00'       # CDR, little endian
STAMP = struct.Struct('<iI')               # a builtin_interfaces Time or Duration: int32 sec, uint32 nanosec


def align(buf: bytearray) -> None:
    """Pad the payload ``buf`` (without the encapsulation header) to a multiple of 4 bytes."""
    buf += b'\0' * (-len(buf) % 4)


def put_uint32(buf: bytearray, value: int) -> None:
    """Append ``value`` as an aligned uint32 (a sequence length, a count) to the payload ``buf``."""
    align(buf)
    buf += struct.pack('<I', value)


def put_string(buf: bytearray, text: str) -> None:
    """Append ``text`` as a CDR string (aligned length, bytes, NUL) to the payload ``buf``."""
    data = text.encode() + b'\0'
    put_uint32(buf, len(data))
    buf += data


POSITION = struct.Struct('<3d')            # a geometry_msgs Point


def get_string(body: bytes | memoryview, p: int) -> tuple[str, int]:
    """The CDR string at ``p`` of a payload (aligned first) and the offset after it; raises ValueError
    (struct.error, UnicodeDecodeError) when the bytes do not hold one."""
    p += -p % 4
    (length,) = struct.unpack_from('<I', body, p)
    end = p + 4 + length
    if not length or end > len(body) or body[end - 1] != 0:
        raise ValueError('not a CDR string')
    return bytes(body[p + 4:end - 1]).decode(), end


def plain_end(body: bytes | memoryview, p: int) -> bool:
    """True when a payload's fields end at ``p``: at most the 7 bytes of padding a serializer may add."""
    return 0 <= len(body) - p < 8


def read_pose_xz(data: bytes) -> tuple[float, float] | None:
    """``pose.position`` x and z [m] of a serialized ``geometry_msgs/PoseStamped`` (little-endian CDR), or
    None when the bytes do not have its plain layout."""
    if len(data) < 16 or data[:2] != ENCAPSULATION[:2]:
        return None
    body = memoryview(data)[4:]
    try:
        _, p = get_string(body, STAMP.size)     # header: stamp, frame_id
        p += -p % 8
        x, _, z = POSITION.unpack_from(body, p)
    except (ValueError, struct.error):
        return None
    return (x, z) if plain_end(body, p + 7 * 8) else None


MULTI_ARRAY_DIMENSION_MIN_BYTES = 16       # a MultiArrayDimension: label (length, NUL, padding), size, stride


def read_float64_array(data: bytes) -> np.ndarray | None:
    """``data`` of a serialized ``std_msgs/Float64MultiArray`` (little-endian CDR), whatever its layout's
    dimensions, or None when the bytes do not have its plain layout. What the simulator reads an
    ``actuator/command`` with: rclpy's deserialization cost ~12 µs a message, a flood of set-points 5000
    a second."""
    if len(data) < 16 or data[:2] != ENCAPSULATION[:2]:
        return None
    body = memoryview(data)[4:]
    try:
        (n_dims,) = struct.unpack_from('<I', body, 0)
        if n_dims * MULTI_ARRAY_DIMENSION_MIN_BYTES > len(body):
            return None
        p = 4
        for _ in range(n_dims):
            _, p = get_string(body, p)              # label
            p += -p % 4 + 8                          # size, stride (uint32)
        p += -p % 4 + 4                              # data_offset (uint32)
        (count,) = struct.unpack_from('<I', body, p)
        p += 4
        p += -p % 8
    except (ValueError, struct.error):
        return None
    if not plain_end(body, p + 8 * count):
        return None
    return np.frombuffer(body, dtype='<f8', count=count, offset=p).astype(float)
