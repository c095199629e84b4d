"""Issue 30 item 5: a client setting many model parameters one by one gets one INFO line from the simulator
(they wait for ~/reset), not one per set."""

from __future__ import annotations

from node_helpers import start_process, stop_process
from rcl_interfaces.srv import SetParameters
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import wait_until
from std_srvs.srv import Trigger


def test_many_parameter_sets_log_one_line(ros_context: Context) -> None:
    """200 model parameters set one by one (each its own ~/set_parameters call): one INFO line says they
    wait for ~/reset, not 200; after a reset the next change says so again."""
    proc = start_process('simulator')
    client = Node('client', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(client)
    service = client.create_client(SetParameters, 'simulator/set_parameters')

    def set_one(value: float) -> None:
        future = service.call_async(SetParameters.Request(
            parameters=[Parameter('contact.friction_scale', value=value).to_parameter_msg()]))
        wait_until(future.done, 10, executor=executor, what='the set_parameters answer')
        assert future.result().results[0].successful, future.result().results[0].reason

    try:
        wait_until(service.service_is_ready, 120, executor=executor, what='simulator/set_parameters')
        for k in range(200):
            set_one(0.0100 + k * 1e-5)
        reset = client.create_client(Trigger, 'simulator/reset')
        wait_until(reset.service_is_ready, 10, executor=executor, what='simulator/reset')
        future = reset.call_async(Trigger.Request())
        wait_until(future.done, 30, executor=executor, what='the reset answer')
        assert future.result().success, future.result().message
        set_one(0.0105)
    finally:
        executor.shutdown()
        client.destroy_node()
        code, out = stop_process(proc)
    lines = [line for line in out.splitlines() if 'model parameters changed' in line]
    assert code == 0, out
    assert len(lines) == 2, '\n'.join(lines[:5]) + f'\n... {len(lines)} lines'
    assert len([line for line in out.splitlines() if '[INFO]' in line]) < 10, out
