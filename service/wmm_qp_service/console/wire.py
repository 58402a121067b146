"""Drive a running console the way a browser does: viser's own messages over its websocket.

A browser that drags the target gizmo sends viser's ``TransformControlsUpdateMessage`` (msgpack,
on the websocket with the ``viser-v<version>`` subprotocol); :func:`move_gizmo` sends the same
message, so tests and scripts move the target with no mouse and no browser.
"""

from __future__ import annotations

from collections.abc import Sequence

TARGET_GIZMO = "/target"


def move_gizmo(url: str, position: Sequence[float], wxyz: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
               name: str = TARGET_GIZMO, timeout: float = 10.0) -> None:
    """Move a console's gizmo ``name`` to ``position`` [m] (world) and orientation ``wxyz``.

    Args:
        url: the console's ``http://HOST:PORT`` (or ``ws://``).
        position, wxyz: the pose a drag would end at.
    """
    import msgspec
    import viser
    from viser import _messages
    from websockets.sync.client import connect

    ws_url = url.replace("http://", "ws://").replace("https://", "wss://")
    msg = _messages.TransformControlsUpdateMessage(
        name=name, wxyz=(float(wxyz[0]), float(wxyz[1]), float(wxyz[2]), float(wxyz[3])),
        position=(float(position[0]), float(position[1]), float(position[2])))
    with connect(ws_url, subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
                 open_timeout=timeout, max_size=None) as ws:
        ws.send(msgspec.msgpack.encode(msg.as_serializable_dict()))
        ws.recv(timeout=timeout)  # the server's first message: it has read ours before it closes
