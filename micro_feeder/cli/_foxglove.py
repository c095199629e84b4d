"""``--foxglove [HOST:]PORT`` of ``run``, ``hil`` and ``replay``: a live view in Foxglove (micro_feeder.viz)."""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Iterator
from typing import Any

from . import CommandError

DEFAULT = '127.0.0.1:8765'


def add_foxglove_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        '--foxglove', nargs='?', const=DEFAULT, metavar='[HOST:]PORT',
        help=f'serve a live view to Foxglove (WebSocket, default {DEFAULT}; loopback only unless you give '
             'a host): the topics, a 3D scene and sim time. In Foxglove: Open connection -> Foxglove '
             'WebSocket -> ws://127.0.0.1:8765; layout config/foxglove_layout.json')


@contextlib.contextmanager
def live_view(spec: str | None) -> Iterator[Any]:
    """A started :class:`micro_feeder.viz.viewer.Viewer` for ``--foxglove`` (None without the option);
    its summary goes to stderr when it stops. Raises :class:`CommandError` when it cannot listen. Where to
    connect is said by :func:`announce`, once the nodes are tapped."""
    if spec is None:
        yield None
        return
    from ..viz.endpoint import parse_endpoint
    from ..viz.viewer import Viewer, ViewerError
    try:
        endpoint = parse_endpoint(spec)
        viewer = Viewer(endpoint)
    except (ValueError, ViewerError) as err:
        raise CommandError(f'--foxglove {spec}: {err}') from err
    try:
        yield viewer
    finally:
        print(viewer.summary(), file=sys.stderr, flush=True)
        viewer.close()


def announce(viewer: Any) -> None:
    """Say where to connect (once), when every node is tapped: a client that connects while channels are
    still being created can be refused a subscription by the server (seen with foxglove-sdk)."""
    if viewer is None or viewer.announced:
        return
    viewer.announced = True
    print(f'foxglove: live view on {viewer.url} (Foxglove: Open connection -> Foxglove WebSocket)',
          file=sys.stderr, flush=True)
    if not viewer.endpoint.loopback:
        print(f'foxglove: warning: {viewer.endpoint.host} is not a loopback address: other hosts can connect',
              file=sys.stderr, flush=True)
