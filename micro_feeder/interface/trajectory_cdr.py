"""JointTrajectory to and from its serialized form (CDR, little endian) with numpy, not per-point objects.

Building or deserializing a JointTrajectory through rclpy creates a Python object per point: ~14 µs per
knot each way, which at the ~40 knots per stroke of a continuous 1 kHz burst is half a core. On the
wire, though, a trajectory whose points all carry the same arrays is a run of fixed-size records: XCDR1
aligns each field relative to the payload start (after the 4-byte encapsulation header), and with
positions, velocities and accelerations of n joints, no effort, a point is 24n + 32 bytes and every point
after the first starts 4 bytes past an 8-byte boundary (the first may need 4 bytes of padding before its
doubles). :func:`encode` writes such records; :func:`decode` reads them, and those of points that carry
positions with or without velocities and accelerations (what other senders write: positions and
velocities, or positions alone), as numpy arrays, and says None for any other layout (the caller then
deserializes with rclpy).
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Time

from .cdr import ENCAPSULATION, STAMP, put_string, put_uint32


def point_bytes(n_joints: int) -> int:
    """Serialized size (bytes) of one knot with positions, velocities and accelerations of ``n_joints``."""
    return _full_point(n_joints).itemsize


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
    record = np.zeros(n_points, dtype=_full_point(n))
    record['n_pos'] = record['n_vel'] = record['n_acc'] = n
    record['pos'], record['vel'], record['acc'] = positions, velocities, accelerations
    record['sec'], record['nanosec'] = np.divmod(np.asarray(offsets_ns, dtype=np.int64), 1_000_000_000)
    points = record.tobytes()
    if n_points and len(head) % 8 == 0:      # the first point's doubles need 4 bytes of padding
        points = points[:4] + b'\0' * 4 + points[4:]
    return ENCAPSULATION + bytes(head) + points


@dataclass(frozen=True)
class Decoded:
    """A JointTrajectory read from CDR: stamp (s), joint names, point count; ``records`` (the points' columns,
    read-only, often views of the message's bytes: ``sec``, ``nanosec``, and those of ``pos``, ``vel``, ``acc``
    the points carry) when they have a layout :func:`decode` reads, else None."""

    stamp: float
    names: list[str]
    n_points: int
    records: np.ndarray | None
    frame_id: str = ''


def decode(data: bytes, max_points: int) -> Decoded | None:
    """Read a serialized JointTrajectory; None when it is not little-endian CDR or is cut short. The
    points are read only when there are at most ``max_points`` of them and they carry the same fields
    (:func:`_read_points`)."""
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
    if n_points == 0 or n_points > max_points:
        return Decoded(stamp, names, n_points, None, frame_id)
    try:
        records = _read_points(body, p, n_points, len(names))
    except struct.error:
        records = None
    return Decoded(stamp, names, n_points, records, frame_id)


KNOT_FIELDS = ('pos', 'vel', 'acc')     # a point's positions, velocities, accelerations, in CDR order


@functools.lru_cache(maxsize=256)
def _point_layout(start: int, n: int, present: tuple[bool, ...]) -> np.dtype:
    """The dtype of one point that starts at payload offset ``start`` modulo 8 (0 or 4) with ``n``-joint
    arrays of the :data:`KNOT_FIELDS` ``present`` (the others empty), no effort: doubles are aligned to 8
    bytes relative to the payload, so the padding depends on where the point starts."""
    names, formats, offsets, p = [], [], [], start
    for field, has in zip(KNOT_FIELDS, present, strict=True):
        names.append('n_' + field), formats.append('<u4'), offsets.append(p - start)
        p += 4
        if has:
            p += -p % 8
            names.append(field), formats.append(('<f8', (n,))), offsets.append(p - start)
            p += 8 * n
    for field, fmt in (('n_effort', '<u4'), ('sec', '<i4'), ('nanosec', '<u4')):
        names.append(field), formats.append(fmt), offsets.append(p - start)
        p += 4
    return np.dtype({'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': p - start})


def _full_point(n: int) -> np.dtype:
    """A point with positions, velocities and accelerations of ``n`` joints that starts 4 bytes past an
    8-byte boundary (every point after the first, as :func:`encode` writes them)."""
    return _point_layout(4, n, (True, True, True))


def _read_points(body: memoryview, p: int, n_points: int, n_joints: int) -> dict[str, np.ndarray] | None:
    """The points at ``p`` as columns (``sec``, ``nanosec``, and ``pos``, ``vel``, ``acc`` (points × joints)
    for the fields they carry), when every point has positions of the message's ``n_joints`` > 0 joints,
    each other field either that many values on every point or none, and no effort; else None (the caller
    deserializes such a message, and its checks say what is wrong). Read from the bytes with numpy: the
    first one or two points on their own (their padding depends on where they start), the rest as one
    run of identical records."""
    n = struct.unpack_from('<I', body, p)[0]
    if n != n_joints:
        return None
    q, present = p, []
    for _field in KNOT_FIELDS:                      # the first point says which fields the points carry
        (count,) = struct.unpack_from('<I', body, q)
        q += 4
        if count not in (0, n):
            return None
        present.append(count == n)
        if count:
            q += -q % 8 + 8 * count
    if n == 0 or not present[0]:
        return None
    chunks, left = [], n_points
    while left:
        dtype = _point_layout(p % 8, n, tuple(present))
        run = left if dtype.itemsize % 8 == 0 else 1    # from here on every point starts alike
        end = p + run * dtype.itemsize
        if end > len(body):     # bytes after the points are left alone: rclpy's serialize_message leaves
            return None         # spare bytes at the end (tens), every point's counts are checked instead
        chunks.append(np.frombuffer(body[p:end], dtype=dtype))
        p, left = end, left - run

    def column(name: str) -> np.ndarray:
        return np.concatenate([c[name] for c in chunks]) if len(chunks) > 1 else chunks[0][name]

    for field, has in zip(KNOT_FIELDS, present, strict=True):
        if np.any(column('n_' + field) != (n if has else 0)):
            return None
    if np.any(column('n_effort')):
        return None
    return {name: column(name) for name in ('sec', 'nanosec', *(f for f, has in zip(KNOT_FIELDS, present,
                                                                                    strict=True) if has))}
