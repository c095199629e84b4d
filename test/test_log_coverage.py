"""A log that ends early or covers only part of a run, without ROS processes: the writer keeps what it wrote
when its directory is removed or its file reaches a size limit (finished, with where and why), and ``info``
says where each topic starts, where and why the log ends, and which commands it lacks against the
simulator's receipts. (The same faults with real processes: test_recorder_faults.py.)"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import threading
import warnings
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from log_fixtures import T0, one_of_each, pose
from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterType, ParameterValue
from rclpy.serialization import serialize_message
from std_msgs.msg import Header

from micro_feeder.logs.coverage import coverage
from micro_feeder.logs.reader import LogReader, TruncatedLogWarning
from micro_feeder.logs.summary import format_summary, summarize
from micro_feeder.logs.writer import LogWriter

MS = 1_000_000


def complete(path: Path) -> LogReader:
    """The log, checked to be complete (summary and footer: no truncated file)."""
    with warnings.catch_warnings():
        warnings.simplefilter('error', TruncatedLogWarning)
        return LogReader(path)


def info_text(path: Path) -> str:
    log = LogReader(path)
    summary = summarize(log)
    return format_summary(summary, coverage(log, summary.recorder, summary.part.stamp))


def written_log(path: Path) -> LogWriter:
    """A directory log with 300 poses in whole chunks and 50 in the open one."""
    writer = LogWriter(path, stop_on_error=True, stamp_topic='/particle/pose', flush_period=float('inf'))
    writer.add_topic('/particle/pose', 'geometry_msgs/msg/PoseStamped')
    for i in range(300):
        writer.write('/particle/pose', serialize_message(pose(i)), T0 + i * MS)
    writer.flush()
    for i in range(300, 350):
        writer.write('/particle/pose', serialize_message(pose(i)), T0 + i * MS)
    return writer


def test_a_removed_log_directory_is_restored_up_to_its_last_whole_chunk(tmp_path):
    path = tmp_path / 'log'
    writer = written_log(path)           # 300 poses in whole chunks, 50 in the open chunk
    shutil.rmtree(path)
    fault = writer.check()
    assert fault is not None and fault.reason == 'log directory removed'
    assert not writer.write('/particle/pose', serialize_message(pose(350)), T0 + 350 * MS)
    writer.close()                       # nothing more: the log was finished when the fault was found
    log = complete(path)
    assert [round(m.message.pose.position.x * 1e6) for m in log.messages(['particle/pose'])] == list(range(300))
    assert (fault.kept, fault.cut, fault.readable_until_stamp_ns, fault.at_stamp_ns) == (300, 50, 299 * MS, 349 * MS)
    assert log.recorder_info['stop_reason'] == 'log directory removed'
    assert (path / 'metadata.yaml').is_file() and not (path / '.reserve').exists()
    ends = next(line for line in info_text(path).splitlines() if line.startswith('ends'))
    assert ends.startswith('ends       early: recording stopped at sim time 0.349 s') and \
        'readable up to sim time 0.299 s' in ends and '50 messages received after that were cut' in ends, ends


def test_a_directory_removal_found_between_its_file_and_its_directory_is_a_directory_removal(tmp_path):
    """``rm -r`` unlinks the files, then the directory: a check in between must not restore the file into the
    directory (the removal would fail: not empty) nor call it a deleted file."""
    path = tmp_path / 'log'
    writer = written_log(path)
    (path / 'log_0.mcap').unlink()       # the removal has unlinked the log file, not yet the rest
    rest = threading.Timer(0.1, shutil.rmtree, (path,))
    rest.start()
    fault = writer.check()
    rest.join()
    assert fault is not None and fault.reason == 'log directory removed', fault
    writer.close()
    log = complete(path)                 # restored where it was, up to its last whole chunk
    assert log.recorder_info['stop_reason'] == 'log directory removed'
    assert len(list(log.messages(['particle/pose']))) == 300


def test_a_deleted_log_file_is_restored_and_named_a_deleted_file(tmp_path):
    path = tmp_path / 'log'
    writer = written_log(path)
    (path / 'log_0.mcap').unlink()
    fault = writer.check()
    assert fault is not None and fault.reason == 'log file deleted', fault
    assert 'log_0.mcap was deleted while recording' in fault.detail
    log = complete(path)
    assert log.recorder_info['stop_reason'] == 'log file deleted'
    assert len(list(log.messages(['particle/pose']))) == 300


FILL_TO_LIMIT = '''
import json, resource, signal, sys
sys.path.insert(0, sys.argv[2])
from log_fixtures import T0, pose
from rclpy.serialization import serialize_message
from micro_feeder.logs.writer import LogWriter
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
writer = LogWriter(sys.argv[1], stop_on_error=True, stamp_topic='/particle/pose', chunk_size=1 << 14)
writer.add_topic('/particle/pose', 'geometry_msgs/msg/PoseStamped')
i = 0
while writer.fault is None:
    writer.write('/particle/pose', serialize_message(pose(i)), T0 + i * 1_000_000)
    i += 1
writer.close()
print(json.dumps({'written': i, 'kept': writer.fault.kept, 'reason': writer.fault.reason,
                  'finished': writer.fault.finished}))
'''


def test_a_file_at_its_size_limit_is_finished_in_the_room_it_has(tmp_path):
    """RLIMIT_FSIZE (SIGXFSZ ignored: writes fail with EFBIG) in a process of its own: the file is cut back to
    whole chunks, as many as leave room for its summary."""
    path = tmp_path / 'log'
    done = subprocess.run([sys.executable, '-c', FILL_TO_LIMIT, str(path), str(Path(__file__).parent)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result['reason'] == 'File too large' and result['finished'], result
    log = complete(path)
    assert (path / 'log_0.mcap').stat().st_size <= 200_000
    indices = [round(m.message.pose.position.x * 1e6) for m in log.messages(['particle/pose'])]
    assert indices == list(range(result['kept'])) and 0 < result['kept'] < result['written']
    assert log.recorder_info['stop_detail'].endswith('errno EFBIG')


def _parameters() -> bytes:
    def value(v: float) -> ParameterValue:
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v)
    return serialize_message(ParameterEvent(new_parameters=[Parameter(name='real_time_factor', value=value(1.0)),
                                                            Parameter(name='publish_rate', value=value(1000.0)),
                                                            Parameter(name='step_period', value=value(1e-3))]))


def test_info_says_which_commands_the_log_lacks_against_the_receipts(tmp_path):
    """A new publisher's first commands, sent before the recorder was matched with it, are missing: the
    simulator acknowledged 10 trajectories (every 0.1 s), the log holds the last 4."""
    path = tmp_path / 'log'
    writer = LogWriter(path)
    for topic, type_ in (('/particle/pose', 'geometry_msgs/msg/PoseStamped'),
                         ('/actuator/trajectory', 'trajectory_msgs/msg/JointTrajectory'),
                         ('/simulator/command_receipts', 'std_msgs/msg/Header'),
                         ('/simulator/parameters', 'rcl_interfaces/msg/ParameterEvent')):
        writer.add_topic(topic, type_)
    writer.write('/simulator/parameters', _parameters(), T0)
    trajectory = serialize_message(one_of_each()['/actuator/trajectory'])
    for i in range(1000):
        writer.write('/particle/pose', serialize_message(pose(i)), T0 + i * MS + 1)
        if i % 100 == 0:
            receipt = Header(frame_id='actuator/trajectory')
            receipt.stamp.sec, receipt.stamp.nanosec = divmod(i * MS, 1_000_000_000)
            writer.write('/simulator/command_receipts', serialize_message(receipt), T0 + i * MS + 3)
            if i >= 600:
                writer.write('/actuator/trajectory', trajectory, T0 + i * MS)
    writer.custom_data.update({'received_total': '1015', 'lost_total': '0', 'incompatible_qos_total': '0'})
    writer.close()
    text = info_text(path)
    line = next(line for line in text.splitlines() if 'start missing' in line)
    assert line == ('           start missing: actuator/trajectory: 6 of the 10 commands the simulator acknowledged '
                    '(simulator/command_receipts) are not in the log (4 recorded): acknowledged at sim time '
                    '0.000–0.500 s, before the first recorded one (sent before the recorder was matched with '
                    'their publisher)'), text
    assert 'loss       none while recording' in text
    row = next(line for line in text.splitlines() if line.startswith('/actuator/trajectory'))
    assert row.endswith('0.600 s'), row       # where its record starts, in sim time
    assert 'simulator  real time × 1; 10 commands received' in text


def test_info_counts_the_commands_a_late_recorder_missed_from_the_simulators_own_count(tmp_path):
    """A recorder started 11.8 s into the run: no receipt in the log, but the simulator's /diagnostics count
    the one command it received."""
    path = tmp_path / 'log'
    writer = LogWriter(path)
    for topic, type_ in (('/particle/pose', 'geometry_msgs/msg/PoseStamped'),
                         ('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray'),
                         ('/simulator/parameters', 'rcl_interfaces/msg/ParameterEvent')):
        writer.add_topic(topic, type_)
    writer.write('/simulator/parameters', _parameters(), T0)
    for i in range(11_800, 12_800):
        writer.write('/particle/pose', serialize_message(pose(i)), T0 + i * MS)
    status = DiagnosticStatus(name='simulator: loop', values=[KeyValue(key='commands_received', value='1')])
    writer.write('/diagnostics', serialize_message(DiagnosticArray(status=[status])), T0 + 12_500 * MS)
    writer.close()
    text = info_text(path)
    assert 'simulator  real time × 1; 1 command received (its /diagnostics), 0 of them acknowledged in the log' \
        in text, text
    row = next(line for line in text.splitlines() if line.startswith('/particle/pose'))
    assert row.endswith('11.800 s'), row
    assert 'ends ' not in text      # closed by its writer: no end to explain


def test_info_of_a_log_whose_writer_was_killed_says_it_ends_abruptly(tmp_path):
    path = tmp_path / 'log'
    writer = LogWriter(path, flush_period=float('inf'))
    writer.add_topic('/particle/pose', 'geometry_msgs/msg/PoseStamped')
    for i in range(300):
        writer.write('/particle/pose', serialize_message(pose(i)), T0 + i * MS)
    writer.flush()
    crashed = tmp_path / 'crashed'
    crashed.mkdir()
    shutil.copy(writer.files[0], crashed)      # what a SIGKILL now would leave
    writer.close()
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', TruncatedLogWarning)
        text = info_text(crashed)
    assert 'ends       abruptly, after sim time 0.299 s (log time +0.30 s): the recorder did not finish the log' \
        in text, text


def test_receipts_that_name_their_command_find_the_missing_ones_exactly(tmp_path):
    """The actuator names every trajectory (header.frame_id) and the receipt repeats it after '#': the
    missing ones are found wherever they are, here the first 6 windows of a stream and one later."""
    path = tmp_path / 'log'
    writer = LogWriter(path)
    for topic, type_ in (('/particle/pose', 'geometry_msgs/msg/PoseStamped'),
                         ('/actuator/trajectory', 'trajectory_msgs/msg/JointTrajectory'),
                         ('/simulator/command_receipts', 'std_msgs/msg/Header')):
        writer.add_topic(topic, type_)
    trajectory = one_of_each()['/actuator/trajectory']
    for i in range(1000):
        writer.write('/particle/pose', serialize_message(pose(i)), T0 + i * MS + 1)
        if i % 100 == 0:
            window = f'/actuator:b1:w{i // 100}'
            receipt = Header(frame_id=f'actuator/trajectory#{window}')
            receipt.stamp.sec, receipt.stamp.nanosec = divmod(i * MS, 1_000_000_000)
            writer.write('/simulator/command_receipts', serialize_message(receipt), T0 + i * MS + 3)
            if i >= 600 and i != 800:
                trajectory.header.frame_id = window
                writer.write('/actuator/trajectory', serialize_message(trajectory), T0 + i * MS)
    writer.custom_data.update({'received_total': '1013', 'lost_total': '0', 'incompatible_qos_total': '0'})
    writer.close()
    line = next(line for line in info_text(path).splitlines() if 'missing:' in line)
    assert line == ('           missing: actuator/trajectory: 7 of the 10 commands the simulator acknowledged '
                    '(simulator/command_receipts) are not in the log (3 recorded): 6 acknowledged at sim time '
                    '0.000–0.500 s, before the first recorded one, 1 later'), line
