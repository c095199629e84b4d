"""JointTrajectory to and from its serialized form (CDR, little endian) with numpy, not per-point objects.

Building or deserializing a JointTrajectory through rclpy creates a Python object per point: ~14 µs per
knot each way, which at the ~40 knots per stroke of a continuous 1 kHz burst is half a core. On the
wire, though, a trajectory whose points all carry the same arrays is a run of fixed-size records: XCDR1
aligns each field relative to the payload start (after the 4-byte encapsulation header), and with
positions, velocities and accelerations of n joints, no effort, a point is 24n + 32 bytes and every point
after the first starts 4 bytes past an 8-byte boundary (the first may need 4 bytes of padding before its
doubles). :func:`encode` writes such records; :func:`decode` reads them as a numpy structured array, and
says None for any other layout (the caller then deserializes with rclpy).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Time

from .cdr import ENCAPSULATION, STAMP, put_string, put_uint32


def _record(n: int) -> np.dtype:
    """One point with positions, velocities and accelerations of ``n`` joints, no effort."""
    return np.dtype([('n_pos', '<u4'), ('pos', '<f8', (n,)), ('n_vel', '<u4'), ('pad_vel', '<u4'),
                     ('vel', '<f8', (n,)), ('n_acc', '<u4'), ('pad_acc', '<u4'), ('acc', '<f8', (n,)),
                     ('n_effort', '<u4'), ('sec', '<i4'), ('nanosec', '<u4')])


def point_bytes(n_joints: int) -> int:
    """Serialized size (bytes) of one knot with positions, velocities and accelerations of ``n_joints``."""
    return _record(n_joints).itemsize


def encode(names: Sequence[str], offsets_ns: np.ndarray, positions: np.ndarray, velocities: np.ndarray,
           accelerations: np.ndarray, stamp: Time, command_id: str = '') -> bytes:
    """The serialized JointTrajectory (header stamp, ``command_id`` as the header's frame_id, ``names``) with knots at
    ``offsets_ns`` (whole ns from the stamp) and (points, joints) positions (m), velocities (m/s),
    accelerations (m/s²); a publisher sends it as it is (``publish(bytes)``). At least one joint."""
    n_points, n = np.shape(positions)
    if not n:
        raise ValueError('trajectory_cdr.encode: at least one joint')
    head = bytearray(STAMP.pack(stamp.sec, stamp.nanosec))
    put_string(head, command_id)                                            # frame_id
    put_uint32(head, len(names))
    for name in names:
        put_string(head, name)
    put_uint32(head, n_points)
    record = np.zeros(n_points, dtype=_record(n))
    record['n_pos'] = record['n_vel'] = record['n_acc'] = n
    record['pos'], record['vel'], record['acc'] = positions, velocities, accelerations
    record['sec'], record['nanosec'] = np.divmod(np.asarray(offsets_ns, dtype=np.int64), 1_000_000_000)
    points = record.tobytes()
    if n_points and len(head) % 8 == 0:      # the first point's doubles need 4 bytes of padding
        points = points[:4] + b'\0' * 4 + points[4:]
    return ENCAPSULATION + bytes(head) + points


@dataclass(frozen=True)
class Decoded:
    """A JointTrajectory read from CDR: stamp (s), joint names, point count; ``records`` (read-only structured
    array of :func:`_record`, often a view of the message's bytes) when the points have the fixed layout,
    else None."""

    stamp: float
    names: list[str]
    n_points: int
    records: np.ndarray | None
    frame_id: str = ''


def decode(data: bytes, max_points: int) -> Decoded | None:
    """Read a serialized JointTrajectory; None when it is not little-endian CDR or is cut short. The
    points are read only when there are at most ``max_points`` of them and they have the fixed layout."""
    if len(data) < 16 or data[:2] != ENCAPSULATION[:2]:
        return None
    body = memoryview(data)[4:]
    try:
        sec, nanosec, length = struct.unpack_from('<iII', body, 0)
        frame_id = bytes(body[12:11 + length]).decode() if length else ''
        p = 12 + length
        p += -p % 4
        (count,) = struct.unpack_from('<I', body, p)
        p += 4
        if count > len(body):
            return None
        names = []
        for _ in range(count):
            p += -p % 4
            (length,) = struct.unpack_from('<I', body, p)
            names.append(bytes(body[p + 4:p + 3 + length]).decode())
            p += 4 + length
        p += -p % 4
        (n_points,) = struct.unpack_from('<I', body, p)
        p += 4
    except (struct.error, UnicodeDecodeError):
        return None
    stamp = sec + nanosec * 1e-9
    if n_points == 0 or n_points > max_points or p + 4 > len(body):
        return Decoded(stamp, names, n_points, None, frame_id)
    (n,) = struct.unpack_from('<I', body, p)
    dtype = _record(n)
    pad = 4 if p % 8 == 0 else 0
    end = p + pad + n_points * dtype.itemsize
    if n == 0 or not 0 <= len(body) - end < 8:         # rclpy pads the payload's end
        return Decoded(stamp, names, n_points, None, frame_id)
    if pad:                       # the first point is split by the padding: join it, then the rest as they are
        records = np.empty(n_points, dtype=dtype)
        records[:1] = np.frombuffer(bytes(body[p:p + 4]) + bytes(body[p + 4 + pad:p + pad + dtype.itemsize]),
                                    dtype=dtype)
        records[1:] = np.frombuffer(body[p + pad + dtype.itemsize:end], dtype=dtype)
    else:                         # a view of the message's bytes, not a copy
        records = np.frombuffer(body[p:end], dtype=dtype)
    records.flags.writeable = False   # read-only either way, whatever the names' lengths made the padding
    fixed = (np.all(records['n_pos'] == n) and np.all(records['n_vel'] == n) and np.all(records['n_acc'] == n)
             and not np.any(records['n_effort']))
    return Decoded(stamp, names, n_points, records if fixed else None, frame_id)
