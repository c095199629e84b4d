"""The live view (``--foxglove``): a real Foxglove WebSocket client (npm ``@foxglove/ws-protocol``,
subprotocol ``foxglove.sdk.v1``, installed by ``make test`` into test/foxglove_client) against
``micro-feeder run``; the server's address rules; the endpoint parsing."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from micro_feeder.viz.endpoint import Endpoint, is_loopback, parse_endpoint
from micro_feeder.viz.scene import MODE_COLORS, PART_SIZE
from micro_feeder.viz.viewer import Viewer, ViewerError

CLIENT_DIR = Path(__file__).parent / 'foxglove_client'
MICRO_FEEDER = str(Path(sys.executable).parent / 'micro-feeder')
SUBSCRIBED = ('/particle/pose', '/foxglove/scene', '/foxglove/friction_limit', '/particles/poses')
PARTS_X0 = '[0.5e-3,1.5e-3,2.5e-3]'     # m: part 0 where the single part starts by default, two more far off
FORWARDED = re.compile(r'(\d+) (/\S+?)(?:,|$)')


def free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def start_run(*args: str) -> subprocess.Popen:
    return subprocess.Popen([MICRO_FEEDER, 'run', *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def wait_listening(proc: subprocess.Popen, timeout: float = 120.0) -> str:
    """The first stderr line of ``run`` once the server listens (the kernel may compile first)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if 'live view on' in line:
            return line
        if not line and proc.poll() is not None:
            break
    proc.kill()
    raise AssertionError(f'no "live view on" line from micro-feeder run: {proc.communicate()}')


def forwarded_counts(stderr: str) -> dict[str, int]:
    """``{topic: messages sent}`` from the server's summary line (``foxglove: ws://...: forwarded N /topic, ...``)."""
    lines = [line for line in stderr.splitlines() if line.startswith('foxglove: ws://') and 'forwarded' in line]
    assert lines, stderr
    return {topic: int(n) for n, topic in FORWARDED.findall(lines[-1])}


def listening_addresses(port: int) -> set[str]:
    """Local addresses with a TCP socket listening on ``port`` (IPv4, from /proc/net/tcp)."""
    addresses = set()
    for line in Path('/proc/net/tcp').read_text().splitlines()[1:]:
        local, state = line.split()[1], line.split()[3]
        address, port_hex = local.split(':')
        if state == '0A' and int(port_hex, 16) == port:
            addresses.add(socket.inet_ntoa(bytes.fromhex(address)[::-1]))
    return addresses


def test_a_foxglove_client_decodes_pose_scene_and_sim_time() -> None:
    """5 s of a real client subscribed to the pose, the scene and the friction limit: at least 95 % of what
    the server sent decoded, the scene's part where the pose says, coloured by its mode, Q_max right, and
    sim time advancing; with three parts, the other two drawn where ``particles/poses`` says."""
    if not (CLIENT_DIR / 'node_modules' / '@foxglove' / 'ws-protocol').is_dir():
        pytest.fail('the test client is not installed: run "make test" (npm ci in test/foxglove_client)')
    port = free_port()
    run = start_run('--duration', '9', '--foxglove', f'127.0.0.1:{port}', '--set', f'particle.x0={PARTS_X0}')
    try:
        wait_listening(run)
        client = subprocess.run([shutil.which('node') or 'node', str(CLIENT_DIR / 'client.js'),
                                 f'ws://127.0.0.1:{port}', ','.join(SUBSCRIBED), '5'],
                                capture_output=True, text=True, timeout=60)
        _, err = run.communicate(timeout=120)
    finally:
        run.kill()
    assert client.returncode == 0, client.stderr
    report = json.loads(client.stdout)
    assert run.returncode == 0, err
    assert not report['errors'], report['errors']
    assert 'time' in report['server']['capabilities']
    sent = forwarded_counts(err)
    pose, scene = report['topics']['/particle/pose'], report['topics']['/foxglove/scene']
    assert pose['schema'] == 'geometry_msgs/msg/PoseStamped' and scene['schema'] == 'foxglove.SceneUpdate'
    # 200 Hz and 30 Hz caps over 5 s on a loaded machine: hundreds of poses, tens of scenes
    assert sent.get('/particle/pose', 0) > 250 and sent.get('/foxglove/scene', 0) > 40, err
    for topic, stats in (('/particle/pose', pose), ('/foxglove/scene', scene)):
        assert stats['decoded'] == stats['received'] >= 0.95 * sent[topic], (topic, stats, sent)
    last_pose, last_scene = pose['last'], scene['last']
    assert last_pose['frame_id'] == 'feeder'
    assert last_scene['entities'] == ['surface', 'actuators', 'part', 'other_parts']
    assert set(last_scene['frames']) == {'feeder'}
    parts = report['topics']['/particles/poses']['last']
    assert parts['frame_id'] == 'feeder' and len(parts['xs']) == 3 and parts['xs'][0] == last_pose['x']
    assert [o['x'] for o in last_scene['other_parts']] == pytest.approx(parts['xs'][1:], abs=1e-12)
    assert [o['z'] for o in last_scene['other_parts']] == pytest.approx(
        [z + PART_SIZE / 2 for z in parts['zs'][1:]], abs=1e-12)
    assert last_scene['surface_points'] == 200 and last_scene['actuators'] == 1
    part = last_scene['part']      # the burst is over after 0.1 s: the part rests where the pose says
    assert part['x'] == pytest.approx(last_pose['x'], abs=1e-12)
    assert part['z'] == pytest.approx(last_pose['z'] + PART_SIZE / 2, abs=1e-12)
    assert part['label'] == 'stuck' and part['color'] == pytest.approx(MODE_COLORS['stuck'], abs=1e-6)
    # friction against the static limit: at rest on the flat surface, Q_max at the weight is the seed's
    # 0.8e-7 N (sliding starts at 40 m/s² for the 2e-9 kg part, docs/contact.md)
    limit = report['topics']['/foxglove/friction_limit']
    assert limit['decoded'] == limit['received'] >= 0.95 * sent['/foxglove/friction_limit'] > 250
    assert limit['last']['q_max'] == pytest.approx(0.8e-7, rel=1e-3) and limit['last']['friction'] == 0.0
    assert report['time_monotonic'] and report['time_count'] > 50
    # sim seconds over the client's 5 s: advancing (a loaded 2-core machine ran the run at 0.3 of real time)
    assert report['time_last'] - report['time_first'] > 0.5


def test_the_server_listens_on_loopback_only_by_default() -> None:
    """``--foxglove PORT`` (no host): bound to 127.0.0.1 alone, so no other interface accepts a connection."""
    port = free_port()
    run = start_run('--duration', '60', '--foxglove', str(port))
    try:
        line = wait_listening(run)
        assert f'ws://127.0.0.1:{port}' in line
        assert listening_addresses(port) == {'127.0.0.1'}
        with socket.create_connection(('127.0.0.1', port), timeout=5):
            pass
        for address in outside_addresses():
            with pytest.raises(OSError), socket.create_connection((address, port), timeout=5):
                pass
    finally:
        run.terminate()
        run.communicate(timeout=60)


def outside_addresses() -> list[str]:
    """This host's non-loopback IPv4 address (the one a remote viewer would connect to), if it has a route:
    a UDP socket's connect() picks it without sending anything."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(('192.0.2.123', 9))
        except OSError:
            return []
        address = probe.getsockname()[0]
    return [] if address.startswith('127.') else [address]


def test_endpoint_parsing_defaults_to_loopback() -> None:
    assert parse_endpoint('') == Endpoint('127.0.0.1', 8765)
    assert parse_endpoint('9000') == Endpoint('127.0.0.1', 9000)
    assert parse_endpoint('localhost:9000') == Endpoint('localhost', 9000)
    assert parse_endpoint('0.0.0.0:9000') == Endpoint('0.0.0.0', 9000)
    assert parse_endpoint('[::1]:9000') == Endpoint('::1', 9000)
    assert parse_endpoint('127.0.0.1') == Endpoint('127.0.0.1', 8765)
    for bad in ('127.0.0.1:x', ':9000', '127.0.0.1:70000'):
        with pytest.raises(ValueError):
            parse_endpoint(bad)
    assert is_loopback('127.0.0.1') and is_loopback('::1') and is_loopback('localhost')
    assert not is_loopback('0.0.0.0') and not is_loopback('192.0.2.1')


def test_a_port_in_use_is_refused_with_the_reason_and_no_log(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(('127.0.0.1', 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(ViewerError, match=f'127.0.0.1:{port}'):
            Viewer(Endpoint('127.0.0.1', port))
        log = tmp_path / 'run'
        result = subprocess.run([MICRO_FEEDER, 'run', '--duration', '1', '--record', str(log),
                                 '--foxglove', f'127.0.0.1:{port}'], capture_output=True, text=True,
                                timeout=120, env={**os.environ})
    assert result.returncode == 2
    assert f'--foxglove 127.0.0.1:{port}: cannot listen' in result.stderr
    assert not log.exists()


def test_the_layout_plots_fields_the_live_view_sends() -> None:
    """Every panel path of config/foxglove_layout.json names a topic the viewer forwards and a field its
    schema has (a typo would leave a panel silently empty)."""
    from micro_feeder.interface.topics import TOPICS
    from micro_feeder.logs.schemas import field_types
    from micro_feeder.viz.viewer import FRICTION_SCHEMA, FRICTION_TOPIC, SCENE_TOPIC, TRANSFORMS_TOPIC

    layout = json.loads((Path(__file__).parents[1] / 'config' / 'foxglove_layout.json').read_text())
    ros = {('/' + t.name.lstrip('/')): t.type for t in TOPICS}
    paths = [p['value'] for panel in layout['configById'].values() for p in panel.get('paths', [])]
    assert len(paths) >= 10
    for path in paths:
        topic, _, fields = path.partition('.')
        first = re.split(r'[.\[]', fields)[0]
        if topic == FRICTION_TOPIC:
            assert first in FRICTION_SCHEMA['properties'], path
        else:
            assert topic in ros, path
            assert first in dict(field_types(ros[topic])), path
    three_d = layout['configById']['3D!feeder']
    assert set(three_d['topics']) == {SCENE_TOPIC, TRANSFORMS_TOPIC, '/surface/markers'}
    panels = re.findall(r'"([A-Za-z0-9]+![a-z]+)"', json.dumps(layout['layout']))
    assert sorted(panels) == sorted(layout['configById'])


def test_replay_forwards_what_the_player_publishes(tmp_path: Path) -> None:
    """``replay --foxglove``: the recorded CDR bytes go out as they are, and the scene is built from them."""
    from test_log_plot import write_log
    write_log(tmp_path / 'log')
    port = free_port()
    replay = subprocess.Popen([MICRO_FEEDER, 'replay', str(tmp_path / 'log'), '--loop', '--foxglove',
                               f'127.0.0.1:{port}'], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_listening(replay)
        client = subprocess.run(['node', str(CLIENT_DIR / 'client.js'), f'ws://127.0.0.1:{port}',
                                 '/particle/pose,/foxglove/scene', '3'], capture_output=True, text=True, timeout=60)
    finally:
        replay.send_signal(signal.SIGINT)
        _, err = replay.communicate(timeout=60)
    report = json.loads(client.stdout)
    assert not report['errors'], report['errors']
    pose, scene = report['topics']['/particle/pose'], report['topics']['/foxglove/scene']
    assert pose['decoded'] == pose['received'] > 100 and scene['decoded'] == scene['received'] > 20
    assert scene['last']['part']['x'] == pytest.approx(pose['last']['x'], abs=3e-6)   # ≤ 1/30 s apart
    assert scene['last']['actuators'] == 2                # the recorded geometry: two actuators
    assert forwarded_counts(err)['/particle/pose'] >= pose['received']
