"""The few XCDR1 (little endian) writing rules the hand-serialized messages share.

Fields are aligned to their size relative to the payload start, which is right after the 4-byte
encapsulation header; a string is a uint32 length that counts its terminating NUL, then its UTF-8 bytes
and the NUL.
"""

from __future__ import annotations

import struct

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
