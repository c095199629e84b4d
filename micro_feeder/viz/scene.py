"""The feeder as a Foxglove 3D scene, from plain numbers (no ROS).

Everything is in the ``feeder`` frame (REP 103: x along the feeder, z up, y to the left; metres), the
frame of the simulator's topics: the deformed surface h(x) as a line over the actuators ± 4 widths, one
piezo stack per actuator (a block whose top follows its stroke, labelled with the stroke in µm), the part
as a sphere coloured by contact mode (stuck green, sliding orange, flying red) with its mode as a label,
and the ``contact`` frame's x (red, along the surface tangent) and z (blue, along the normal) axes at the
part. :meth:`FeederScene.transforms` gives the same frame as a ``foxglove.FrameTransform`` so that the 3D
panel can also display data in ``contact`` (the contact wrench's frame).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CubePrimitive,
    FrameTransform,
    FrameTransforms,
    LinePrimitive,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from ..interface.names import CONTACT_FRAME, FEEDER_FRAME
from ..physics.surface import surface_profile

SURFACE_POINTS = 200            # points of the surface line
PART_SIZE = 100e-6              # m: diameter of the part's sphere (the ~100 µm part)
STACK_HEIGHT = 0.4e-3           # m: drawn height of a piezo stack below the surface
AXIS_LENGTH = 200e-6            # m: length of the contact frame's axes
MODE_COLORS = {'stuck': (0.2, 0.7, 0.2), 'sliding': (0.95, 0.6, 0.1), 'flying': (0.9, 0.2, 0.2)}
UNKNOWN_MODE_COLOR = (0.6, 0.6, 0.6)


def _color(rgb: Sequence[float], a: float = 1.0) -> Color:
    return Color(r=rgb[0], g=rgb[1], b=rgb[2], a=a)


def _about_y(angle: float) -> Quaternion:
    """A rotation by ``angle`` (rad) about +y."""
    return Quaternion(x=0.0, y=math.sin(angle / 2.0), z=0.0, w=math.cos(angle / 2.0))


def _timestamp(t_ns: int) -> Timestamp:
    return Timestamp(*divmod(max(t_ns, 0), 1_000_000_000))


class FeederScene:
    """Builds ``foxglove.SceneUpdate`` messages of one feeder geometry (actuator ``centers`` and Gaussian
    ``widths``, m)."""

    def __init__(self, centers: Sequence[float], widths: Sequence[float], part_size: float = PART_SIZE,
                 track_lift: float | None = None):
        self.centers = np.asarray(centers, dtype=float)
        self.widths = np.asarray(widths, dtype=float)
        if self.centers.shape != self.widths.shape or self.centers.ndim != 1 or not self.centers.size:
            raise ValueError(f'one width per actuator: {len(self.centers)} centers, {len(self.widths)} widths')
        self.part_size = part_size
        self.track_lift = track_lift        # a track (sin β): flat at s sin β, drawn around the part
        self.xs = np.linspace(float(np.min(self.centers - 4 * self.widths)),
                              float(np.max(self.centers + 4 * self.widths)), SURFACE_POINTS)

    def update(self, t_ns: int, strokes: Sequence[float], x: float, z: float, theta: float,
               mode: str, others: Sequence[tuple[float, float, str]] = ()) -> SceneUpdate:
        """The scene at sim time ``t_ns`` (ns): actuator ``strokes`` (m), the part at (``x``, ``z``) (m) on a
        surface tilted by ``theta`` = atan(h_x) (rad), in contact ``mode``; with several parts, the ``others``
        (parts 1, 2, …) as (x, z, mode), each a sphere coloured by its mode and labelled with its index."""
        strokes = np.asarray(strokes, dtype=float)
        if strokes.shape != self.centers.shape:
            raise ValueError(f'{strokes.size} strokes for {self.centers.size} actuators')
        stamp = _timestamp(t_ns)
        if self.track_lift is None:
            xs, heights = self.xs, surface_profile(self.xs, strokes, self.centers, self.widths)
        else:
            xs = x + self.xs - float(np.mean(self.xs))
            heights = np.full(xs.size, self.track_lift * float(strokes[-1]))   # the normal motion's actuator
        surface = SceneEntity(timestamp=stamp, frame_id=FEEDER_FRAME, id='surface', lines=[LinePrimitive(
            thickness=3.0, scale_invariant=True, color=_color((0.55, 0.6, 0.75)),
            points=[Point3(x=float(px), y=0.0, z=float(pz)) for px, pz in zip(xs, heights, strict=True)])])
        return SceneUpdate(entities=[surface, self._actuators(stamp, strokes), self._part(stamp, x, z, theta, mode),
                                     self._others(stamp, others)])

    def transforms(self, t_ns: int, x: float, z: float, theta: float) -> FrameTransforms:
        """``contact`` in ``feeder``: at the part, rotated by −θ about y (docs/interface.md, *Frames*)."""
        return FrameTransforms(transforms=[FrameTransform(
            timestamp=_timestamp(t_ns), parent_frame_id=FEEDER_FRAME, child_frame_id=CONTACT_FRAME,
            translation=Vector3(x=x, y=0.0, z=z), rotation=_about_y(-theta))])

    def _actuators(self, stamp: Timestamp, strokes: np.ndarray) -> SceneEntity:
        tops = surface_profile(self.centers, strokes, self.centers, self.widths)
        cubes, texts = [], []
        for k, (c, w, s, top) in enumerate(zip(self.centers, self.widths, strokes, tops, strict=True)):
            center_z = float(top) - 0.3 * self.part_size - STACK_HEIGHT / 2.0
            cubes.append(CubePrimitive(
                pose=Pose(position=Vector3(x=float(c), y=0.0, z=center_z), orientation=_about_y(0.0)),
                size=Vector3(x=float(w), y=float(w), z=STACK_HEIGHT), color=_color((0.35, 0.45, 0.7), 0.8)))
            texts.append(TextPrimitive(
                pose=Pose(position=Vector3(x=float(c), y=0.0, z=center_z - STACK_HEIGHT / 2.0 - self.part_size),
                          orientation=_about_y(0.0)),
                billboard=True, font_size=13.0, scale_invariant=True, color=_color((0.85, 0.85, 0.9)),
                text=f'piezo_{k} {s * 1e6:+.1f} µm'))
        return SceneEntity(timestamp=stamp, frame_id=FEEDER_FRAME, id='actuators', cubes=cubes, texts=texts)

    def _others(self, stamp: Timestamp, others: Sequence[tuple[float, float, str]]) -> SceneEntity:
        r = self.part_size / 2.0
        spheres, texts = [], []
        for index, (x, z, mode) in enumerate(others, start=1):
            rgb = MODE_COLORS.get(mode, UNKNOWN_MODE_COLOR)
            spheres.append(SpherePrimitive(pose=Pose(position=Vector3(x=x, y=0.0, z=z + r), orientation=_about_y(0.0)),
                                           size=Vector3(x=2 * r, y=2 * r, z=2 * r), color=_color(rgb)))
            texts.append(TextPrimitive(pose=Pose(position=Vector3(x=x, y=0.0, z=z + 3 * r), orientation=_about_y(0.0)),
                                       billboard=True, font_size=12.0, scale_invariant=True, color=_color(rgb),
                                       text=str(index)))
        return SceneEntity(timestamp=stamp, frame_id=FEEDER_FRAME, id='other_parts', spheres=spheres, texts=texts)

    def _part(self, stamp: Timestamp, x: float, z: float, theta: float, mode: str) -> SceneEntity:
        r = self.part_size / 2.0
        rgb = MODE_COLORS.get(mode, UNKNOWN_MODE_COLOR)
        at = Vector3(x=x, y=0.0, z=z)
        sphere = SpherePrimitive(pose=Pose(position=Vector3(x=x, y=0.0, z=z + r), orientation=_about_y(0.0)),
                                 size=Vector3(x=2 * r, y=2 * r, z=2 * r), color=_color(rgb))
        axes = [ArrowPrimitive(pose=Pose(position=at, orientation=_about_y(angle)), shaft_length=0.75 * AXIS_LENGTH,
                               shaft_diameter=AXIS_LENGTH / 25, head_length=0.25 * AXIS_LENGTH,
                               head_diameter=AXIS_LENGTH / 10, color=_color(color))
                for angle, color in ((-theta, (0.9, 0.15, 0.15)), (-theta - math.pi / 2.0, (0.2, 0.35, 0.95)))]
        label = TextPrimitive(pose=Pose(position=Vector3(x=x, y=0.0, z=z + 3 * r), orientation=_about_y(0.0)),
                              billboard=True, font_size=14.0, scale_invariant=True, color=_color(rgb),
                              text=mode or '?')
        return SceneEntity(timestamp=stamp, frame_id=FEEDER_FRAME, id='part', spheres=[sphere], arrows=axes,
                           texts=[label])
