"""Every part's state as standard messages, serialized once per tick (several parts, docs/parts.md):

* ``particles/poses``: ``geometry_msgs/PoseArray`` in ``feeder``, one pose per part in part order (the order
  along the feeder, which never changes): position (x, 0, z) (m), orientation the contact frame's tilt;
* ``particles/states``: ``std_msgs/Float64MultiArray``, a (parts × :data:`PART_STATE_FIELDS`) row-major table
  whose layout names its dimensions (``part`` and the fields): sim time t (s), contact mode (:data:`MODE_CODES`),
  x (m), ẋ (m/s), z (m), ż (m/s), the normal load N (N; > 0 presses; in flight −F_att) and the friction T (N)
  in the contact frame. The type has no header, so each row carries its sim time.
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Pose, PoseArray
from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension, MultiArrayLayout

from ..physics.dynamics import MODES, layout
from ..physics.dynamics.model import ObservedParts
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

    def update(self, observed: ObservedParts) -> None:
        """Serialize both messages from every part's outputs at one sim time (read as the rows: 16 parts'
        :class:`Observation` objects took ~60 µs a tick to build)."""
        rows = observed.rows
        if rows.shape[0] != self.n_parts:
            raise ValueError(f'{rows.shape[0]} parts observed for messages of {self.n_parts}')
        sec, nanosec = stamp_parts(float(rows[0, layout.C_T]))
        poses = np.zeros((self.n_parts, 7))
        poses[:, 0], poses[:, 2] = rows[:, layout.C_X], rows[:, layout.C_Z]
        poses[:, 3:] = [tilt_quaternion(theta) for theta in rows[:, layout.C_THETA].tolist()]
        self.poses = self._poses.serialize(sec, nanosec, poses.ravel())
        self.states = self._states.serialize(0, 0, rows[:, STATE_COLUMNS].ravel())


# the output columns of PART_STATE_FIELDS (the mode column holds the MODES index, which is the mode's code)
STATE_COLUMNS = [layout.C_T, layout.C_MODE, layout.C_X, layout.C_XD, layout.C_Z, layout.C_ZD, layout.C_N,
                 layout.C_FRICTION]
