"""The recorder node in-process: latched state captured, every published message recorded, loss
counters on /diagnostics and in the log, clean stop through the service, parameters validated, a recording
fault reported on /diagnostics."""

from __future__ import annotations

import shutil

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from log_fixtures import pose
from rclpy.exceptions import InvalidParameterValueException
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from ros_helpers import wait_until
from std_msgs.msg import String
from std_srvs.srv import Trigger

from micro_feeder.logs.reader import LogReader
from micro_feeder.logs.summary import summarize
from micro_feeder.nodes.recorder import Recorder


def test_records_latched_state_and_every_message_then_stops_by_service(ros_context, tmp_path):
    source = rclpy.create_node('source', context=ros_context)
    latched = source.create_publisher(String, 'particle/contact_state',
                                      QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    latched.publish(String(data='sliding'))  # before the recorder exists
    poses = source.create_publisher(PoseStamped, 'particle/pose', 100)
    diagnostics = []
    source.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    stop = source.create_client(Trigger, 'recorder/stop')
    recorder = Recorder(context=ros_context, parameter_overrides=[
        Parameter('output', value=str(tmp_path / 'log')), Parameter('flush_period', value=0.2)])
    executor = EventsExecutor(context=ros_context)
    executor.add_node(recorder)
    executor.add_node(source)
    try:
        wait_until(lambda: poses.get_subscription_count() == 1 and stop.service_is_ready(), 10,
                   executor=executor, what='recorder subscribed')
        for i in range(500):
            poses.publish(pose(i))
        wait_until(lambda: recorder.received['/particle/pose'] == 500, 10, executor=executor, what='500 poses')
        wait_until(lambda: any(s.name.startswith('recorder') for d in diagnostics for s in d.status), 5,
                   executor=executor, what='recorder diagnostics')
        future = stop.call_async(Trigger.Request())
        wait_until(future.done, 5, executor=executor, what='stop service')
        assert future.result().success
    finally:
        executor.shutdown()
        recorder.close()
        recorder.destroy_node()
        source.destroy_node()
    log = LogReader(tmp_path / 'log')
    assert (tmp_path / 'log' / 'metadata.yaml').is_file() and not log.truncated
    assert [m.message.pose.position.x for m in log.messages(['particle/pose'])] == \
        [pose(i).pose.position.x for i in range(500)]
    assert [m.message.data for m in log.messages(['particle/contact_state'])] == ['sliding']
    qos = log.topics['/particle/contact_state'].metadata['offered_qos_profiles']
    assert 'durability: transient_local' in qos
    summary = summarize(log)
    assert summary.recorder_source == 'summary'
    assert summary.recorder['lost_total'] == '0' and summary.recorder['received./particle/pose'] == '500'
    status = next(s for d in diagnostics for s in d.status if s.name.startswith('recorder'))
    assert {kv.key for kv in status.values} >= {'received_total', 'lost_total', 'incompatible_qos_total'}


def test_out_of_range_flush_period_is_refused(ros_context, tmp_path):
    with pytest.raises(InvalidParameterValueException):
        Recorder(context=ros_context, parameter_overrides=[
            Parameter('output', value=str(tmp_path / 'log')), Parameter('flush_period', value=0.0)])


def test_a_removed_log_directory_is_reported_once_on_diagnostics_and_the_log_restored(ros_context, tmp_path):
    """The recorder node in-process: the fault reaches /diagnostics as ERROR with its keys, the executor never
    sees an exception, and the log is restored where it was."""
    source = rclpy.create_node('source', context=ros_context)
    poses = source.create_publisher(PoseStamped, 'particle/pose', 100)
    diagnostics = []
    source.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    log = tmp_path / 'log'
    recorder = Recorder(context=ros_context, parameter_overrides=[
        Parameter('output', value=str(log)), Parameter('flush_period', value=0.1)])
    executor = EventsExecutor(context=ros_context)
    executor.add_node(recorder)
    executor.add_node(source)

    def errors() -> list:
        return [s for d in diagnostics for s in d.status
                if s.name.startswith('recorder') and s.level == DiagnosticStatus.ERROR]
    try:
        wait_until(lambda: poses.get_subscription_count() == 1, 10, executor=executor, what='recorder subscribed')
        for i in range(200):
            poses.publish(pose(i))
        wait_until(lambda: (log / 'log_0.mcap').stat().st_size > 2000, 10, executor=executor, what='a chunk on disk')
        shutil.rmtree(log)
        for i in range(200, 300):
            poses.publish(pose(i))
        wait_until(lambda: errors(), 10, executor=executor, what='ERROR on /diagnostics')
        assert recorder.done.done() and recorder.fault.reason == 'log directory removed'
    finally:
        executor.shutdown()
        recorder.close()
        recorder.destroy_node()
        source.destroy_node()
    status = errors()[0]
    assert status.message.startswith('recording stopped at sim time') and 'log directory removed' in status.message
    values = {kv.key: kv.value for kv in status.values}
    assert values['stopped_early'] == 'true' and values['stop_reason'] == 'log directory removed'
    restored = LogReader(log)
    assert not restored.truncated and 0 < restored.message_count <= 300
    assert restored.recorder_info['stop_reason'] == 'log directory removed'
