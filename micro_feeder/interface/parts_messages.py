"""Every part's state as standard messages, serialized once per tick (several parts, docs/parts.md):

* ``particles/poses``: ``geometry_msgs/PoseArray`` in ``feeder``, one pose per part in part order (the order
  along the feeder, which never changes): position (x, 0, z) (m), orientation the contact frame's tilt;
* ``particles/states``: ``std_msgs/Float64MultiArray``, a (parts × :data:`PART_STATE_FIELDS`) row-major table
  whose layout names its dimensions (``part`` and the fields): sim time t (s), contact mode (:data:`MODE_CODES`),
  x (m), ẋ (m/s), z (m), ż (m/s), the normal load N (N; > 0 presses; in flight −F_att) and the friction T (N)
  in the contact frame. The type has no header, so each row carries its sim time.
"""

from __future__ import annotations

from geometry_msgs.msg import Pose, PoseArray
from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension, MultiArrayLayout

from ..physics.dynamics import MODES, Observation
from .messages import SerializedTemplate, tilt_quaternion
from .names import FEEDER_FRAME
from .stamps import stamp_parts

PART_STATE_FIELDS = ('t', 'mode', 'x', 'xdot', 'z', 'zdot', 'normal_load', 'friction')
MODE_CODES = {mode: float(code) for code, mode in enumerate(MODES)}      # stuck 0, sliding 1, flying 2


def _put_all(values: list[float], targets: list[tuple[object, str]]) -> None:
    for (obj, attr), value in zip(targets, values, strict=True):
        setattr(obj, attr, value)


class PartsMessages:
    """``particles/poses`` and ``particles/states`` of ``n_parts`` parts as CDR bytes (a
    :class:`~micro_feeder.interface.messages.SerializedTemplate` each, patched every tick)."""

    def __init__(self, n_parts: int):
        self.n_parts = n_parts
        poses = PoseArray(header=Header(frame_id=FEEDER_FRAME), poses=[Pose() for _ in range(n_parts)])
        targets = [(obj, axis) for pose in poses.poses
                   for obj, axes in ((pose.position, 'xyz'), (pose.orientation, 'xyzw')) for axis in axes]
        self._poses = SerializedTemplate(poses, poses.header.stamp,
                                         [(lambda v: _put_all(v, targets), 7 * n_parts)])
        width = len(PART_STATE_FIELDS)
        layout = MultiArrayLayout(dim=[
            MultiArrayDimension(label='part', size=n_parts, stride=n_parts * width),
            MultiArrayDimension(label=','.join(PART_STATE_FIELDS), size=width, stride=width)])
        states = Float64MultiArray(layout=layout)
        self._states = SerializedTemplate(states, None, [(lambda v: setattr(states, 'data', v), width * n_parts)])
        self.poses = self.states = b''

    def update(self, observations: list[Observation]) -> None:
        """Serialize both messages from every part's outputs (one :class:`Observation` per part, one sim time)."""
        if len(observations) != self.n_parts:
            raise ValueError(f'{len(observations)} parts observed for messages of {self.n_parts}')
        sec, nanosec = stamp_parts(observations[0].t)
        pose_values: list[float] = []
        state_values: list[float] = []
        for obs in observations:
            pose_values += (obs.x, 0.0, obs.z, *tilt_quaternion(obs.theta))
            state_values += (obs.t, MODE_CODES[obs.mode], obs.x, obs.xdot, obs.z, obs.zdot, obs.normal_load,
                             obs.friction)
        self.poses = self._poses.serialize(sec, nanosec, pose_values)
        self.states = self._states.serialize(0, 0, state_values)
