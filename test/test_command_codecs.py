"""The simulator's hand-written CDR on its command path (interface/cdr.py, interface/messages.py) against
rclpy's serialization, over drawn messages: an ``actuator/command`` read without deserializing is the
message's ``data``, and a ``simulator/command_status`` answer written by hand is the DiagnosticArray rclpy
would serialize (the same length, the same message read back). Both exist because a flood of refused
set-points (5 kHz) is read and answered one by one."""

from __future__ import annotations

import math

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension, MultiArrayLayout

from micro_feeder.interface.cdr import read_float64_array
from micro_feeder.interface.messages import command_status
from micro_feeder.interface.stamps import to_time

labels = st.text(st.characters(codec='utf-8', exclude_characters='\0'), max_size=9)
dimensions = st.builds(MultiArrayDimension, label=labels, size=st.integers(0, 2**32 - 1),
                       stride=st.integers(0, 2**32 - 1))
multi_arrays = st.builds(
    lambda dims, offset, data: Float64MultiArray(layout=MultiArrayLayout(dim=dims, data_offset=offset), data=data),
    st.lists(dimensions, max_size=3), st.integers(0, 2**32 - 1), st.lists(st.floats(width=64), max_size=70))


@settings(max_examples=300, deadline=None)
@given(multi_arrays)
def test_set_points_read_from_bytes_are_the_message_data(msg: Float64MultiArray) -> None:
    values = read_float64_array(serialize_message(msg))
    assert values is not None and values.dtype == np.float64
    np.testing.assert_array_equal(values, np.asarray(msg.data, dtype=float))     # NaN equal to NaN


def test_bytes_that_are_not_a_plain_float64_array_are_left_to_rclpy() -> None:
    data = serialize_message(Float64MultiArray(layout=MultiArrayLayout(dim=[MultiArrayDimension(label='x')]),
                                               data=[1.0, 2.0]))
    assert read_float64_array(data[:-1]) is None                        # cut short
    assert read_float64_array(data + b'\0' * 8) is None                 # trailing bytes
    assert read_float64_array(b'\x00\x00' + data[2:]) is None           # big endian
    assert read_float64_array(b'') is None
    huge_dims = data[:4] + (10**9).to_bytes(4, 'little') + data[8:]
    assert read_float64_array(huge_dims) is None


texts = st.text(st.characters(codec='utf-8', exclude_characters='\0'), max_size=40)


@settings(max_examples=300, deadline=None)
@given(st.floats(0.0, 1e6), texts, texts, texts, texts, texts)
def test_command_status_bytes_are_what_rclpy_serializes(t: float, frame_id: str, name: str, topic: str,
                                                       command_id: str, reason: str) -> None:
    expected = DiagnosticArray(header=Header(stamp=to_time(t), frame_id=frame_id), status=[DiagnosticStatus(
        level=DiagnosticStatus.ERROR, name=name, message=reason, hardware_id='micro_feeder',
        values=[KeyValue(key='topic', value=topic), KeyValue(key='command_id', value=command_id),
                KeyValue(key='t_s', value=repr(t))])])
    data = command_status(t, frame_id, name, topic, command_id, reason)
    assert len(data) == len(serialize_message(expected))    # rclpy leaves its padding bytes unset: not compared
    assert deserialize_message(data, DiagnosticArray) == expected
    assert math.isclose(float(expected.status[0].values[2].value), t)
