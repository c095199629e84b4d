"""The fence around rclpy's own serialization: the one place outside the nodes that reaches it.

The hot paths publish and read CDR bytes written by this package's own codecs (:mod:`.cdr`,
:mod:`.trajectory_cdr`, :mod:`.transitions`, the templates of :mod:`.messages`); the tests compare every
one of them against these two functions. Everything else (a template's first serialization, a layout the
fast decoder does not read, the live view's decoding) goes through here, and rclpy is imported only when
one is called, so that importing the simulation core, the logs or the exploration tools never loads it
(the import-linter contract in pyproject.toml allows this module, and only this one, to do so).
"""

from __future__ import annotations

from typing import Any


def serialize(msg: Any) -> bytes:
    """CDR bytes of a ROS message object, by rclpy (``rclpy.serialization.serialize_message``)."""
    from rclpy.serialization import serialize_message

    return serialize_message(msg)


def deserialize(data: bytes, msg_type: type) -> Any:
    """The ``msg_type`` message in CDR ``data``, by rclpy; raises what rclpy raises for bytes that are not one."""
    from rclpy.serialization import deserialize_message

    return deserialize_message(data, msg_type)
