"""``wmm-qp teleop``: stream setpoints to the daemon (haptic-like stream or the paper's circle)."""

from __future__ import annotations

import argparse
import sys

HELP = "stream setpoints to the daemon: a haptic-like stream, the paper's circle, the keyboard or a gamepad"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli_common import add_service_arguments
    from .common import add_robot_argument

    parser.add_argument("stream", choices=("haptic", "circle", "keyboard", "gamepad"), nargs="?", default="haptic",
                        help="haptic: jittery, jumpy stream; circle: the paper's circle with "
                             "feed-forward velocity; keyboard: keys move the EE target (a terminal UI); "
                             "gamepad: a gamepad's sticks do (Linux evdev)")
    parser.add_argument("--speed", type=float, default=0.05,
                        help="[m/s] keyboard/gamepad: the target's speed along each axis (default 0.05)")
    parser.add_argument("--angular-speed", type=float, default=0.3,
                        help="[rad/s] keyboard/gamepad with the pose task: its turn rate (default 0.3)")
    parser.add_argument("--device", default=None, metavar="PATH",
                        help="gamepad: its /dev/input/eventN (default: the first gamepad found)")
    parser.add_argument("--duration", type=float, default=20.0, help="[s] how long to stream")
    parser.add_argument("--rate", type=float, default=100.0, help="[Hz] send rate")
    parser.add_argument("--seed", type=int, default=0, help="jitter/jump seed (haptic)")
    parser.add_argument("--no-mode", action="store_true",
                        help="do not switch the daemon to track mode first")
    add_service_arguments(parser)
    add_robot_argument(parser)


def run(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from ..client import Client
    from ..teleop import stream_circle, stream_haptic
    from .common import robot_service_config

    if not (args.duration > 0 and args.rate > 0 and args.speed > 0 and args.angular_speed > 0):
        print("wmm-qp teleop: error: --duration, --rate, --speed and --angular-speed must be > 0", file=sys.stderr)
        return 2
    if args.stream == "keyboard" and not (sys.stdin.isatty() and sys.stdout.isatty()):
        print("wmm-qp teleop: error: keyboard teleop needs a terminal (stdin and stdout a tty)", file=sys.stderr)
        return 2
    _, svc = robot_service_config(args)
    if args.stream in ("keyboard", "gamepad"):
        return _run_device(args, svc)
    with Client(svc, name="teleop") as c:
        info = c.wait_for_daemon(5.0)
        if info is None or not info.status.x:
            print("wmm-qp teleop: error: no daemon with a live robot answers", file=sys.stderr)
            return 1
        if not args.no_mode:
            c.set_mode("track")
            time.sleep(0.1)
            info = c.info() or info
        x0 = np.array(info.status.x)
        if args.stream == "circle":
            n = stream_circle(c, x0, args.duration, args.rate)
        else:
            n = stream_haptic(c, x0, args.duration, args.rate, seed=args.seed)
    print(f"teleop: sent {n} setpoints ({args.stream}) in {args.duration:g} s")
    return 0


def _run_device(args: argparse.Namespace, svc: object) -> int:
    import time

    import numpy as np

    from ..client import Client
    from ..console.geometry import quat_to_matrix, xyzw_to_wxyz
    from ..devices import GamepadDevice, KeyboardDevice, TargetIntegrator, open_gamepad
    from ..devices.base import InputDevice
    from ..teleop import DeviceTeleop, run_keyboard

    source = open_gamepad(args.device) if args.stream == "gamepad" else None
    with Client(svc, name=f"teleop-{args.stream}") as c:  # type: ignore[arg-type]
        info = c.wait_for_daemon(5.0)
        if info is None or not info.status.x:
            print(f"wmm-qp teleop: error: {c.no_daemon_reason() if info is None else 'the daemon has no live robot'}",
                  file=sys.stderr)
            return 1
        pose = info.task == "pose"
        if not args.no_mode:
            c.set_mode("track")
            time.sleep(0.1)
            info = c.info() or info
        st = info.status
        R = quat_to_matrix(xyzw_to_wxyz(st.quat_d)) if pose and st.quat_d else (np.eye(3) if pose else None)
        integ = TargetIntegrator(np.asarray(st.x, float), R, speed=args.speed, angular_speed=args.angular_speed)
        device: InputDevice = (GamepadDevice(source, rotations=pose) if source is not None
                               else KeyboardDevice(rotations=pose))
        t = DeviceTeleop(c, device, integ, pose=pose)
        try:
            if isinstance(device, KeyboardDevice):
                run_keyboard(t, device, c.svc.robot, info.task or "position", rate_hz=min(args.rate, 100.0))
            else:
                print(f"teleop: gamepad on robot {c.svc.robot}: sticks move the target; A holds, Y tracks, "
                      f"START quits", flush=True)
                while not t.quit:
                    t.tick()
                    time.sleep(1.0 / min(args.rate, 100.0))
        finally:
            device.close()
    print(f"teleop: {args.stream}: sent {t.sent} setpoints; last target {[round(float(v), 4) for v in t.integ.x]}")
    return 0
