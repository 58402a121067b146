"""``wmm-qp console``: the operator's web console (viser), a Zenoh client of the daemon; with
``--play FILE.mcap`` it plays a recording back instead (no Zenoh, no daemon)."""

from __future__ import annotations

import argparse
import socket
import sys
from pathlib import Path
from typing import Any

HELP = "a web console: the robot live in 3D, drag its EE target, modes, status, plots (viser)"


def _port(text: str) -> int:
    try:
        p = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 1 <= p <= 65535:
        raise argparse.ArgumentTypeError(f"a port is 1-65535, got {p}")
    return p


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli_common import add_service_arguments
    from .common import add_robot_argument

    parser.add_argument("--port", type=_port, default=8080, help="web server port (default 8080)")
    parser.add_argument("--host", default="127.0.0.1",
                        help="web server address (default 127.0.0.1; 0.0.0.0 serves every interface)")
    parser.add_argument("--scene", type=Path, default=None, metavar="FILE",
                        help="scene file whose obstacles and fence to draw (default: configs/scenes/default.toml)")
    parser.add_argument("--wait", type=float, default=10.0, metavar="S",
                        help="[s] how long to wait for a daemon (default 10)")
    parser.add_argument("--duration", type=float, default=0.0, metavar="S",
                        help="[s] stop after this long (default 0: until Ctrl-C)")
    parser.add_argument("--play", type=Path, default=None, metavar="FILE.mcap",
                        help="play a recording back (serve --record, record) instead of a live robot: no Zenoh")
    parser.add_argument("--speed", type=float, default=1.0, metavar="X",
                        help="with --play: playback speed (default 1; the page can change it)")
    add_service_arguments(parser)
    add_robot_argument(parser)


def _check_bind(host: str, port: int) -> str | None:
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as e:
        return f"--host {host}: {e.strerror}"
    fam, _, _, _, addr = infos[0]
    with socket.socket(fam, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(addr)
        except OSError as e:
            return f"cannot listen on {host}:{port}: {e.strerror} (choose another --port)"
    return None


def run(args: argparse.Namespace) -> int:
    import time

    from wmm_qp import load_scene

    from ..cli_common import service_config, stop_on_signals
    from ..console import Console, ConsoleError, RobotLink

    try:
        import viser  # noqa: F401
        import yourdfpy  # noqa: F401
    except ImportError as e:
        print(f"wmm-qp console: error: {e.name} is not installed: pip install 'wmm-qp[console]'", file=sys.stderr)
        return 2
    if not args.wait > 0 or args.duration < 0:
        print("wmm-qp console: error: --wait must be > 0 and --duration >= 0", file=sys.stderr)
        return 2
    if args.play is None and args.speed != 1.0:
        print("wmm-qp console: error: --speed needs --play FILE", file=sys.stderr)
        return 2
    if args.play is not None:
        return _play(args, stop_on_signals)
    problem = _check_bind(args.host, args.port)
    if problem:
        print(f"wmm-qp console: error: {problem}", file=sys.stderr)
        return 2
    scene = load_scene(args.scene)
    svc = service_config(args)
    stop = stop_on_signals()
    link = RobotLink(svc, fallback=args.robot_config).open()
    console = Console(link, host=args.host, port=args.port, scene=scene)
    try:
        try:
            console.start(timeout=args.wait)
        except ConsoleError as e:
            print(f"wmm-qp console: error: {e}", file=sys.stderr)
            return 1
        a = console.attached
        assert a is not None
        print(f"console: {console.url}  (robot {a.robot_id}; robots seen: "
              f"{', '.join(link.robots()) or a.robot_id}; Ctrl-C stops)", flush=True)
        end = time.monotonic() + args.duration if args.duration > 0 else float("inf")
        while not stop.wait(0.2) and time.monotonic() < end:
            pass
    finally:
        console.close()
    return 0


def _play(args: argparse.Namespace, stop_on_signals: Any) -> int:
    """``--play FILE``: the console on a recording (its robot from the recording's metadata)."""
    import time

    from wmm_qp import WmmQpError, load_scene

    from ..console import Console, ConsoleError
    from ..console.playback import RecordingLink, warn_truncated
    from ..console.timeline import load_timeline
    from ..recording import require

    if not args.speed > 0:
        print(f"wmm-qp console: error: --speed must be > 0, got {args.speed:g}", file=sys.stderr)
        return 2
    try:
        require()
        timeline = load_timeline(args.play)
        link = RecordingLink(timeline, args.play, fallback=args.robot_config, speed=args.speed)
        link.attach()
        recorded_scene = Path(timeline.meta.get("scene", ""))
        scene = load_scene(args.scene if args.scene is not None or not recorded_scene.is_file() else recorded_scene)
    except (WmmQpError, ConsoleError) as e:  # RecordingUnavailable, RecordingError, ConfigError
        print(f"wmm-qp console: error: {e}", file=sys.stderr)
        return 2
    except Exception as e:  # a file no reader expects: still one line
        print(f"wmm-qp console: error: cannot play {args.play}: {type(e).__name__}: {e}".splitlines()[0],
              file=sys.stderr)
        return 2
    problem = _check_bind(args.host, args.port)
    if problem:
        print(f"wmm-qp console: error: {problem}", file=sys.stderr)
        return 2
    warn_truncated(timeline)
    stop = stop_on_signals()
    console = Console(link, host=args.host, port=args.port, scene=scene)
    try:
        console.start(robot_id=link.robot_id)
        print(f"console: {console.url}  (playing {link.summary()}; Ctrl-C stops)", flush=True)
        end = time.monotonic() + args.duration if args.duration > 0 else float("inf")
        while not stop.wait(0.2) and time.monotonic() < end:
            pass
    finally:
        console.close()
    return 0
