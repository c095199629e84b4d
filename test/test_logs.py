"""The logs library: what our writer writes, rosbags (an implementation we did not write) reads back
intact; schemas carry their full dependency text; truncated files read to the last whole chunk and
recover into valid logs; summaries, CSV export and plots."""

from __future__ import annotations

import csv
import io
import shutil
import warnings
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from log_fixtures import T0, one_of_each, pose, type_name, write_motion_log, write_run_log
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from micro_feeder.logs.export import export_csv
from micro_feeder.logs.mcap_fast import FastWriter
from micro_feeder.logs.reader import LogReader, TruncatedLogWarning
from micro_feeder.logs.recover import recover
from micro_feeder.logs.schemas import SEPARATOR, schema_text
from micro_feeder.logs.summary import format_summary, summarize
from micro_feeder.logs.writer import LogWriter
from micro_feeder.plots.log import plot_log


def rosbags_messages(path: Path) -> list[tuple[str, int, bytes, object]]:
    with AnyReader([path]) as reader:
        return [(c.topic, t, raw, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]


def test_schema_has_every_dependency_in_rosbag2_format():
    text = schema_text('geometry_msgs/msg/PoseStamped')
    names = [block.split('\n', 1)[0] for block in text.split(SEPARATOR + '\n')[1:]]
    assert names == ['MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time', 'MSG: geometry_msgs/Pose',
                     'MSG: geometry_msgs/Point', 'MSG: geometry_msgs/Quaternion']


def test_every_recorded_type_reads_back_intact_with_rosbags(tmp_path):
    messages = one_of_each()
    # Serialized once: rclpy leaves alignment padding uninitialised, so two serializations may differ.
    sent = {topic: serialize_message(msg) for topic, msg in messages.items()}
    writer = LogWriter(tmp_path / 'log')
    for i, (topic, msg) in enumerate(messages.items()):
        writer.add_topic(topic, type_name(msg))
        writer.write(topic, sent[topic], T0 + i)
    writer.close()
    read = rosbags_messages(tmp_path / 'log')
    assert [topic for topic, *_ in read] == list(messages)
    for i, (topic, t, raw, _) in enumerate(read):
        assert raw == sent[topic], topic
        assert t == T0 + i
    by_topic = {topic: decoded for topic, _, _, decoded in read}
    assert by_topic['/actuator/trajectory'].points[0].positions.tolist() == [1e-6, 2e-6]
    assert by_topic['/particle/contact_wrench'].wrench.force.z == -3e-6
    assert by_topic['/surface/markers'].markers[0].id == 3
    assert by_topic['/diagnostics'].status[0].values[0].value == '1.0'


def test_our_reader_decodes_trajectory_points_with_empty_sequences(tmp_path):
    traj = JointTrajectory(joint_names=['piezo_0'], points=[JointTrajectoryPoint(positions=[3e-6])])
    traj.points[0].time_from_start.sec = 2
    writer = LogWriter(tmp_path / 'traj.mcap')
    writer.add_topic('/actuator/trajectory', 'trajectory_msgs/msg/JointTrajectory')
    writer.write('/actuator/trajectory', serialize_message(traj), T0)
    writer.close()
    point = next(LogReader(tmp_path / 'traj.mcap').messages(['actuator/trajectory'])).message.points[0]
    assert list(point.positions) == [3e-6] and list(point.effort) == [] and point.time_from_start.sec == 2


def test_many_messages_intact_and_publish_time_is_header_stamp(tmp_path):
    poses = write_motion_log(tmp_path / 'log', n=2000)
    read = [r for r in rosbags_messages(tmp_path / 'log') if r[0] == '/particle/pose']
    assert [raw for _, _, raw, _ in read] == poses
    log = LogReader(tmp_path / 'log')
    stamps = [m.publish_time_ns for m in log.messages(['particle/pose'])]
    assert stamps == [i * 1_000_000 for i in range(2000)]
    state = next(log.messages(['particle/contact_state']))
    assert state.publish_time_ns == state.log_time_ns and state.message.data == 'stuck'


def test_a_chunk_costs_the_writer_under_a_kilobyte_whatever_the_log_length(tmp_path):
    """A recording flushes a chunk every second for hours: what the writer keeps per chunk for the summary
    (its index, span, counts) stays small, and the file still reads whole, every message in its chunk."""
    import tracemalloc

    topics = [f'/t{k}' for k in range(16)]
    writer = LogWriter(tmp_path / 'log', flush_period=float('inf'))
    for topic in topics:
        writer.add_topic(topic, 'geometry_msgs/msg/PoseStamped')

    def chunks(first: int, n: int) -> None:
        for c in range(first, first + n):
            for k, topic in enumerate(topics):
                writer.write(topic, serialize_message(pose(c)), T0 + c * 100 + k)
            writer.flush()

    chunks(0, 50)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        chunks(50, 1000)
        per_chunk = (tracemalloc.get_traced_memory()[0] - before) / 1000
    finally:
        tracemalloc.stop()
    writer.close()
    # measured 0.57 kB; mcap's Writer keeping its own index objects took 2.1 kB
    assert per_chunk < 800, f'{per_chunk:.0f} B kept per chunk of 16 channels'
    with open(next((tmp_path / 'log').glob('*.mcap')), 'rb') as f:
        summary = make_reader(f).get_summary()
    assert len(summary.chunk_indexes) == 1050 and summary.statistics.message_count == 1050 * 16
    assert all(len(c.message_index_offsets) == 16 for c in summary.chunk_indexes)
    log = LogReader(tmp_path / 'log')
    assert [m.message.pose.position.x for m in log.messages(["/t3"])][-1] == pose(1049).pose.position.x


def test_split_by_duration_gives_several_files_read_in_order(tmp_path):
    poses = write_motion_log(tmp_path / 'log', n=1000, split_duration=0.25)
    log = LogReader(tmp_path / 'log')
    assert len(log.files) == 4
    assert [m.data for m in log.messages(['particle/pose'])] == poses
    assert [raw for topic, _, raw, _ in rosbags_messages(tmp_path / 'log') if topic == '/particle/pose'] == poses


def test_truncated_file_reads_to_last_whole_chunk_and_recovers(tmp_path):
    path = tmp_path / 'log'
    writer = LogWriter(path, flush_period=float('inf'))
    writer.add_topic('/particle/pose', 'geometry_msgs/msg/PoseStamped')
    for i in range(500):
        writer.write('/particle/pose', serialize_message(pose(i)), T0 + i)
        if i == 299:
            writer.flush()
    crashed = tmp_path / 'crashed.mcap'
    shutil.copy(writer.files[0], crashed)  # what a SIGKILL now would leave: 300 flushed messages
    writer.close()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(crashed.read_bytes() + b'\x05' * 37)  # plus a torn record
    for broken in (crashed, cut):
        with pytest.warns(TruncatedLogWarning):
            log = LogReader(broken)
        assert log.message_count == 300
        assert [m.message.pose.position.x for m in log.messages()][-1] == pytest.approx(299e-6)
        result = recover(broken, tmp_path / f'recovered-{broken.stem}')
        assert result.messages == 300 and result.truncated == [broken]
        with warnings.catch_warnings():
            warnings.simplefilter('error')
            fixed = LogReader(result.output)
        with open(fixed.files[0], 'rb') as stream:
            assert make_reader(stream).get_summary().statistics.message_count == 300
        assert len(rosbags_messages(result.output)) == 300


def test_summary_export_and_plot(tmp_path):
    write_motion_log(tmp_path / 'log', n=300)
    log = LogReader(tmp_path / 'log')
    summary = summarize(log)
    assert [(t.name, t.count) for t in summary.topics] == [
        ('/particle/contact_state', 3), ('/particle/contact_wrench', 300), ('/particle/pose', 300),
        ('/particle/twist', 300)]
    assert summary.topics[2].rate == pytest.approx(1000.0)
    assert summary.part.x == pytest.approx(299e-6) and summary.part.mode == 'flying'
    text = format_summary(summary)
    assert 'geometry_msgs/msg/PoseStamped' in text and 'mode flying' in text
    files = export_csv(log, tmp_path / 'csv')
    with open(tmp_path / 'csv' / 'particle__pose.csv') as stream:
        rows = list(csv.DictReader(stream))
    assert len(files) == 4 and len(rows) == 300
    assert float(rows[-1]['pose.position.x']) == pytest.approx(299e-6)
    png = plot_log(log, tmp_path / 'plot.png')
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 10_000


def test_info_paces_the_run_from_its_first_moving_pose_not_from_the_held_start(tmp_path):
    """The simulator publishes its held pose at t = 0 when it is built, and the loop starts later (here 0.5 s
    of start-up): a run that then kept real time for 1 s reads 1.00 × real time, not 1 s / 1.5 s."""
    writer = LogWriter(tmp_path / 'log')
    writer.add_topic('/particle/pose', 'geometry_msgs/msg/PoseStamped')
    writer.write('/particle/pose', serialize_message(pose(0)), T0)
    for i in range(1, 1001):
        writer.write('/particle/pose', serialize_message(pose(i)), T0 + 500_000_000 + i * 1_000_000)
    writer.close()
    summary = summarize(LogReader(tmp_path / 'log'))
    assert summary.part.real_time_factor == pytest.approx(1.0)
    assert '(particle/pose stamps, 1.00 × real time)' in format_summary(summary)


def test_message_is_decoded_once(tmp_path):
    write_motion_log(tmp_path / 'log', n=3)
    m = next(LogReader(tmp_path / 'log').messages(['particle/pose']))
    calls = []
    decode = m.decode
    m.decode = lambda data: calls.append(data) or decode(data)
    first = m.message
    assert m.message is first and first.pose.position.x == 0.0
    assert len(calls) == 1


def _loss(path: Path) -> list[str]:
    """The loss lines of ``micro-feeder info``'s summary."""
    lines = format_summary(summarize(LogReader(path))).splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith('loss'))
    return lines[first:]


def test_info_says_a_complete_log_lost_nothing(tmp_path):
    write_run_log(tmp_path / 'log', trajectories=2, receipts=2, diag_commands=2)
    loss = _loss(tmp_path / 'log')
    assert loss[0].startswith('loss       none  (') and len(loss) == 1, loss


def test_info_reports_a_late_start_as_missing(tmp_path):
    """Issue 26: a recorder that joined late has no loss counted (it lost nothing once subscribed), but the
    log misses the start: the first pose is at 0.67 s of sim time (one tick is at most 2 ms) and the one
    command the simulator received before (its /diagnostics counts it; the receipt went out before the
    recorder was there too) is in no topic. ``info`` said 'loss none'."""
    write_run_log(tmp_path / 'log', first=670, diag_commands=1)
    loss = _loss(tmp_path / 'log')
    assert loss[0].startswith('loss       none while recording  (')
    assert loss[1:] == [
        '           start missing: first pose at sim time 0.670000 s, not 0 (one tick is at most 2 ms): the '
        'recorder joined late',
        '           start missing: the first 1 of the 1 commands the simulator received are not in the log '
        '(sent before the recorder subscribed)']


def test_info_reports_missing_first_commands(tmp_path):
    """Poses from t = 0, but the recorder subscribed to actuator/trajectory after the first 2 of 3 commands:
    their receipts are in the log, the commands are not. Commands the recorder counted lost are loss while
    recording, not a missing start."""
    write_run_log(tmp_path / 'log', trajectories=1, receipts=3)
    loss = _loss(tmp_path / 'log')
    assert loss[1:] == ['           start missing: the first 2 of the 3 commands the simulator received are not '
                        'in the log (sent before the recorder subscribed)'], loss
    write_run_log(tmp_path / 'lost', trajectories=1, receipts=3, lost=2)
    loss = _loss(tmp_path / 'lost')
    assert loss[0].startswith('loss       2 messages lost') and not any('start missing' in x for x in loss), loss


def test_info_counts_the_messages_the_middleware_refused_to_take_from_the_simulator_as_lost(tmp_path):
    """A message the middleware refused never reached a subscriber: the recorder cannot count it, the
    simulator's /diagnostics do, and ``info`` must not say 'loss none' for it."""
    write_run_log(tmp_path / 'log', trajectories=2, receipts=2, diag_commands=2, refused=3)
    loss = _loss(tmp_path / 'log')
    assert loss[0].startswith('loss       3 messages lost  (') and 'counted lost by the middleware 0' in loss[0]
    assert loss[1:] == ["           refused by the middleware: 3 of the simulator's messages (no subscriber got "
                        'them; its /diagnostics):',
                        '             /particle/pose: 3'], loss


def test_info_cli_prints_the_missing_start(tmp_path, capsys):
    from micro_feeder.cli import main

    write_run_log(tmp_path / 'log', first=670)
    assert main(['info', str(tmp_path / 'log')]) == 0
    assert 'start missing: first pose at sim time 0.670000 s' in capsys.readouterr().out


def test_the_summary_indexes_every_chunk_as_the_file_holds_it(tmp_path):
    """The sink keeps no chunk index in memory (a 1 MiB chunk goes out every ~0.2 s at 1 kHz, for hours): it
    reads them back from the file when it writes the summary. Every chunk of a log of ~150 is indexed where
    the file holds it, with its times, sizes and message indexes, as the mcap library reads the records."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    path = tmp_path / 'log.mcap'
    write_motion_log(path, n=3000, chunk_size=4_000)
    (mcap_file,) = path.glob('*.mcap') if path.is_dir() else (path,)
    with open(mcap_file, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    chunks = [r for r in StreamReader(str(mcap_file), emit_chunks=True).records if isinstance(r, Chunk)]
    indexes = summary.chunk_indexes
    assert len(indexes) == len(chunks) == summary.statistics.chunk_count > 100
    raw = mcap_file.read_bytes()
    for index, chunk in zip(indexes, chunks, strict=True):
        assert raw[index.chunk_start_offset] == 0x06                          # a Chunk record starts there
        assert (index.message_start_time, index.message_end_time) == (chunk.message_start_time,
                                                                      chunk.message_end_time)
        assert (index.uncompressed_size, index.compressed_size, index.compression) == (
            chunk.uncompressed_size, len(chunk.data), chunk.compression)
        assert index.chunk_length == 9 + int.from_bytes(raw[index.chunk_start_offset + 1:][:8], 'little')
        assert index.message_index_length > 0
        for channel, offset in index.message_index_offsets.items():
            assert raw[offset] == 0x07                                        # a MessageIndex record
            assert int.from_bytes(raw[offset + 9:offset + 11], 'little') == channel
    assert summary.statistics.message_start_time == min(c.message_start_time for c in chunks)
    assert summary.statistics.message_end_time == max(c.message_end_time for c in chunks)


@settings(max_examples=40, deadline=None)
@given(messages=st.lists(st.tuples(st.integers(0, 3), st.integers(0, 2**63 - 1), st.binary(max_size=300),
                                   st.integers(0, 2**63 - 1), st.integers(0, 2**32 - 1)), max_size=200),
       chunk_size=st.integers(1, 8192))
def test_the_fast_mcap_writer_writes_what_mcaps_writer_writes_byte_for_byte(messages, chunk_size):
    """LogWriter's FastWriter (logs/mcap_fast.py) against mcap's own Writer: the same file, summary included,
    for any messages (channels, log and publish times in any order, sizes, sequences) and chunk sizes."""
    def write(writer_class) -> bytes:
        out = io.BytesIO()
        writer = writer_class(out, chunk_size=chunk_size, compression=CompressionType.ZSTD, enable_data_crcs=True)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data')
        channels = [writer.register_channel(f'/topic{i}', 'cdr', schema) for i in range(4)]
        for channel, log_time, data, publish_time, sequence in messages:
            writer.add_message(channels[channel], log_time, data, publish_time, sequence)
        writer.finish()
        return out.getvalue()
    assert write(FastWriter) == write(Writer)
