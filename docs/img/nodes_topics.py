"""Draw docs/img/nodes_topics.png: the nodes, the topics between them (type and QoS) and the services.

Run: .venv/bin/python docs/img/nodes_topics.py [OUT.png]   (also part of make figures)

The topics, types and QoS are those of docs/interface.md (test/test_readme.py checks that they agree).
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

# (topic, type, QoS as in docs/interface.md's table)
COMMANDS = [
    ('actuator/trajectory', 'trajectory_msgs/JointTrajectory', 'reliable, volatile, depth 10'),
    ('actuator/command', 'std_msgs/Float64MultiArray', 'reliable, volatile, depth 10'),
]
STATE = [
    ('particle/pose', 'geometry_msgs/PoseStamped', 'reliable, volatile, depth 100'),
    ('particle/twist', 'geometry_msgs/TwistStamped', 'reliable, volatile, depth 100'),
    ('particle/contact_wrench', 'geometry_msgs/WrenchStamped', 'reliable, volatile, depth 100'),
    ('particle/contact_state', 'std_msgs/String', 'reliable, transient local, keep last 1000'),
    ('particle/transitions', 'diagnostic_msgs/DiagnosticArray', 'reliable, volatile, keep last 1000'),
    ('particles/poses', 'geometry_msgs/PoseArray', 'reliable, volatile, depth 100'),
    ('particles/states', 'std_msgs/Float64MultiArray', 'reliable, volatile, depth 100'),
    ('particles/transitions', 'diagnostic_msgs/DiagnosticArray', 'reliable, volatile, keep last 1000'),
    ('actuator/joint_states', 'sensor_msgs/JointState', 'reliable, volatile, depth 100'),
    ('surface/markers', 'visualization_msgs/MarkerArray', 'reliable, volatile, depth 1'),
    ('simulator/parameters', 'rcl_interfaces/ParameterEvent', 'reliable, transient local, depth 1'),
    ('simulator/command_receipts', 'std_msgs/Header', 'reliable, volatile, depth 100'),
    ('simulator/trajectories_received', 'trajectory_msgs/JointTrajectory', 'reliable, volatile, depth 100'),
    ('simulator/command_status', 'diagnostic_msgs/DiagnosticArray', 'reliable, volatile, depth 100'),
    ('simulator/entity_changes', 'diagnostic_msgs/DiagnosticArray', 'reliable, transient local, keep last 1000'),
    ('/clock', 'rosgraph_msgs/Clock', 'best effort, volatile, depth 1'),
    ('/diagnostics', 'diagnostic_msgs/DiagnosticArray', 'reliable, volatile, depth 10'),
]
NODE_COLOUR, TOPIC_COLOUR, LINE = '#cfe2f3', '#f3f3f3', '#555555'


def node(ax, x: float, y: float, w: float, h: float, name: str, lines: list[str]) -> None:
    ax.add_patch(FancyBboxPatch((x - w / 2, y - h / 2), w, h, boxstyle='round,pad=0.02,rounding_size=0.25',
                                fc=NODE_COLOUR, ec='#3d6f9e', lw=1.5))
    ax.text(x, y + h / 2 - 0.35, name, ha='center', va='top', fontsize=12, fontweight='bold', family='monospace')
    for i, line in enumerate(lines):
        ax.text(x, y + h / 2 - 0.95 - 0.42 * i, line, ha='center', va='top', fontsize=8.5, color='#333333')


def topic(ax, x: float, y: float, name: str, kind: str, qos: str, w: float = 4.6) -> None:
    ax.add_patch(FancyBboxPatch((x - w / 2, y - 0.36), w, 0.72, boxstyle='round,pad=0.01,rounding_size=0.08',
                                fc=TOPIC_COLOUR, ec='#999999', lw=0.8))
    ax.text(x, y + 0.1, name, ha='center', va='center', fontsize=9.5, family='monospace')
    line = f'{kind} · {qos}'
    ax.text(x, y - 0.19, line, ha='center', va='center', fontsize=6.6 if len(line) < 72 else 5.4, color='#555555')


def arrow(ax, start: tuple[float, float], end: tuple[float, float], rad: float = 0.0, **style) -> None:
    ax.add_patch(FancyArrowPatch(start, end, arrowstyle='-|>', mutation_scale=11, lw=style.pop('lw', 1.0),
                                 color=style.pop('color', LINE), connectionstyle=f'arc3,rad={rad}', **style))


def line(ax, points: list[tuple[float, float]], **style) -> None:
    """A polyline ending in an arrow head."""
    xs, ys = zip(*points, strict=True)
    ax.plot(xs, ys, color=style.get('color', LINE), lw=1.0, solid_capstyle='butt')
    arrow(ax, points[-2], points[-1], color=style.get('color', LINE))


def draw(out: Path) -> None:
    step, bottom = 0.84, 1.2                       # the state topics' column, from the bottom up
    top = bottom + (len(STATE) - 1) * step
    lift = top - 9.6                               # everything else moves up with the column's top
    fig, ax = plt.subplots(figsize=(14.5, 8.0 * (12.0 + lift) / 12.0))
    ax.set_xlim(0, 23.5)
    ax.set_ylim(-1.5, 10.5 + lift)
    ax.axis('off')
    mid = lift / 2.0

    # left: who sends strokes
    node(ax, 1.95, 8.0 + mid, 3.8, 2.6, 'actuator', ['plays stroke.* as a burst', 'or a stream (stroke.count 0,',
                                               'follows actuator/joint_states)', 'services ~/start, ~/stop'])
    node(ax, 1.95, 3.5 + mid, 3.8, 2.7, 'your controller', ['or feed_controller', '(micro-feeder hil)',
                                                      'lockstep: each command', 'or simulator/step = 1 step'])
    # commands
    for (name, kind, qos), y in zip(COMMANDS, (7.0 + mid, 5.4 + mid), strict=True):
        topic(ax, 6.75, y, name, kind.split('/')[1], qos, w=4.5)
    arrow(ax, (3.85, 7.7 + mid), (4.5, 7.1 + mid))
    arrow(ax, (3.85, 4.3 + mid), (4.5, 6.85 + mid))
    arrow(ax, (3.85, 3.9 + mid), (4.5, 5.3 + mid))
    # the simulator
    node(ax, 11.1, 5.3 + mid, 3.4, 9.0 + lift, 'simulator',
         ['checks every command', '(a bad one is refused,', 'answered, counted)', '', 'integrates the part',
          'on sim time, publishes', 'at 1 kHz', '', 'simulation_interfaces', 'services, SimulateSteps,',
          'FollowJointTrajectory;', '~/reset ~/pause ~/step', '', 'parameters: every', 'model parameter, ...'])
    arrow(ax, (9.0, 7.0 + mid), (9.4, 7.0 + mid))
    arrow(ax, (9.0, 5.4 + mid), (9.4, 5.4 + mid))
    # state out, to a bus every subscriber takes from
    bus = 19.9
    for i, (name, kind, qos) in enumerate(STATE):
        y = top - i * step
        topic(ax, 16.35, y, name, kind, qos, w=6.3)
        arrow(ax, (12.8, y), (13.2, y), lw=0.8)
        ax.plot([19.5, bus], [y, y], color=LINE, lw=0.8)
    ax.plot([bus, bus], [top, bottom - 0.9], color=LINE, lw=1.0)
    # right: who listens
    node(ax, 22.0, 7.0 + mid, 2.4, 2.4, 'recorder', ['every topic', '→ MCAP log', '~/stop'])
    node(ax, 22.0, 3.2 + mid, 2.4, 2.4, 'viewers', ['RViz, Foxglove', '(--foxglove),', 'your nodes'])
    arrow(ax, (bus, 7.0 + mid), (20.8, 7.0 + mid))
    arrow(ax, (bus, 3.2 + mid), (20.8, 3.2 + mid))
    # back to the controller
    line(ax, [(bus, bottom - 0.9), (bus, -0.45), (1.95, -0.45), (1.95, 2.15 + mid)], color='#8a6d3b')
    ax.text(10.8, -0.3, 'particle/*, particles/*, /clock: the state your controller decides on '
            '(every message of one instant carries the same sim-time stamp)', ha='center', va='bottom',
            fontsize=8.5, color='#8a6d3b')
    ax.text(0.1, -1.2, 'Names are relative: --namespace feeder1 (or -r __ns:=/feeder1) moves every topic and '
            'service except /clock and /diagnostics. Full contract: docs/interface.md.', fontsize=8.5,
            color='#333333')
    fig.savefig(out, dpi=110, bbox_inches='tight')
    plt.close(fig)


if __name__ == '__main__':
    draw(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_suffix('.png'))
