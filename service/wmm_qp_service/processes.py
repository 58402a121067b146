"""Start and stop the sim and the daemon as separate processes on loopback.

Used by ``wmm-qp demo`` and the integration tests: unique ports and key prefix per run, so
runs never collide; clean shutdown with SIGINT, then SIGKILL as a last resort.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import wmm_qp as w

from .config import ServiceConfig, load_service_config

CLI: tuple[str, ...] = (sys.executable, "-P", "-m", "wmm_qp_service.cli")
"""The command that runs ``wmm-qp`` in a new process, as installed: ``-P`` keeps the working
directory off ``sys.path`` (started from a checkout's root, ``-m`` would import its ``wmm_qp/``
instead of the installed one, and compile its own numba kernels there: every stack of a fresh
CI venv paid that once, ~25 s of CPU)."""

_HANDED_OUT: set[int] = set()


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now and that this process has not handed out
    before (the kernel may give the same free port to two calls in a row: a sim and a daemon
    given one port, the second could not listen — seen once in CI)."""
    for _ in range(1000):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", 0))
            port = int(s.getsockname()[1])
        if port not in _HANDED_OUT:
            _HANDED_OUT.add(port)
            return port
    raise RuntimeError("no free TCP port on 127.0.0.1 that was not handed out already")


def isolated_config(base: ServiceConfig | None = None, prefix: str | None = None,
                    robot: w.RobotConfig | None = None) -> ServiceConfig:
    """A service config with a unique key prefix and fresh loopback ports; with ``robot``, its
    name is the robot id (an isolated run of that robot, whatever id the service config sets)."""
    base = base or load_service_config()
    if robot is not None:
        base = base.with_(robot="").with_robot(robot)
    return base.with_(prefix=prefix or f"wmmrun{uuid.uuid4().hex[:10]}",
                      zenoh={"daemon_endpoint": f"tcp/127.0.0.1:{free_port()}",
                             "sim_endpoint": f"tcp/127.0.0.1:{free_port()}"})


def log_folder(path: str | Path | None, tag: str) -> Path:
    """Where the processes' logs go: ``path`` (created if missing) or a fresh temporary folder."""
    import tempfile

    folder = Path(path) if path else Path(tempfile.mkdtemp(prefix=f"wmm-qp-{tag}-"))
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _service_args(svc: ServiceConfig, robot_file: Path | None = None, scene_file: Path | None = None) -> list[str]:
    out = ["--prefix", svc.prefix, "--robot", svc.robot,
           "--daemon-endpoint", svc.zenoh.daemon_endpoint, "--sim-endpoint", svc.zenoh.sim_endpoint]
    out += ["--robot-config", str(robot_file)] if robot_file is not None else []
    return out + (["--scene", str(scene_file)] if scene_file is not None else [])


@dataclass
class Stack:
    """A sim and a daemon process, or one embedded process (a context manager that always stops them).

    Attributes:
        svc: the config both run with (an open robot id is filled from the robot file's name,
            so that clients of ``svc`` find the processes).
        rate_hz: [Hz] daemon rate.
        log_dir: where their stderr goes (None: discarded).
        robot_file: the robot description both get (``--robot-config``); None: the default.
        scene_file: the scene both get (``--scene``); None: the default scene.
        embedded: one process instead of two: ``wmm-qp sim --embedded --control-rate rate_hz``
            (named ``embedded``), hosting the control core in the sim's cycle; it takes the
            extra sim arguments and then the extra daemon arguments.
    """

    svc: ServiceConfig
    rate_hz: float = 500.0
    log_dir: Path | None = None
    extra_daemon_args: list[str] = field(default_factory=list)
    extra_sim_args: list[str] = field(default_factory=list)
    robot_file: Path | None = None
    scene_file: Path | None = None
    embedded: bool = False
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.svc.robot:
            self.svc = (self.svc.resolved() if self.robot_file is None
                        else self.svc.with_robot(w.load_robot_config(self.robot_file)))

    def _spawn(self, name: str, argv: list[str]) -> subprocess.Popen[bytes]:
        err = subprocess.DEVNULL if self.log_dir is None else open(self.log_dir / f"{name}.log", "ab")  # noqa: SIM115
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        p = subprocess.Popen([*CLI, *argv],
                             stdin=subprocess.DEVNULL, stdout=err, stderr=err, env=env)
        self.procs[name] = p
        return p

    def start_sim(self) -> subprocess.Popen[bytes]:
        """Start (or restart) the sim."""
        return self._spawn("sim", ["sim", *_service_args(self.svc, self.robot_file, self.scene_file),
                                           *self.extra_sim_args])

    def start_daemon(self) -> subprocess.Popen[bytes]:
        """Start (or restart) the daemon."""
        return self._spawn("daemon", ["serve", *_service_args(self.svc, self.robot_file, self.scene_file),
                                      "--rate", f"{self.rate_hz:g}", *self.extra_daemon_args])

    def start_embedded(self) -> subprocess.Popen[bytes]:
        """Start (or restart) the sim with the control core in its cycle (``--embedded``)."""
        return self._spawn("embedded", ["sim", *_service_args(self.svc, self.robot_file, self.scene_file),
                                        "--embedded", "--control-rate", f"{self.rate_hz:g}",
                                        *self.extra_sim_args, *self.extra_daemon_args])

    def start_driver(self, kind: str, robot_ip: str | None = None) -> subprocess.Popen[bytes]:
        """Start a real robot's driver (``wmm-qp driver KIND --robot-ip IP``; ``driver ros2``: no
        address, the robot file's ``[ros2]`` topics) in the sim's place (embedded: with the control
        core in its cycle, taking the extra daemon arguments)."""
        extra = ["--embedded", "--control-rate", f"{self.rate_hz:g}", *self.extra_daemon_args] if self.embedded else []
        where = ["--robot-ip", robot_ip] if robot_ip is not None else []
        return self._spawn("driver", ["driver", kind, *where, *_service_args(self.svc, self.robot_file), *extra])

    def start(self) -> Stack:
        """Start both (embedded: the one process)."""
        if self.embedded:
            self.start_embedded()
            return self
        self.start_sim()
        self.start_daemon()
        return self

    def exited(self) -> str | None:
        """The first started process that has ended, with its exit status and the last line of its
        log (None: every one runs)."""
        for name, p in self.procs.items():
            if (code := p.poll()) is None:
                continue
            last = ""
            if self.log_dir is not None and (log := self.log_dir / f"{name}.log").is_file():
                lines = log.read_text(errors="replace").strip().splitlines()
                last = lines[-1].strip() if lines else ""
            return f"the {name} exited with status {code}" + (f" ({name}.log: {last})" if last else "")
        return None

    def kill(self, name: str, sig: int = signal.SIGKILL) -> None:
        """Send a signal to one process and, for SIGKILL, reap it."""
        p = self.procs.get(name)
        if p is not None and p.poll() is None:
            p.send_signal(sig)
            if sig == signal.SIGKILL:
                p.wait(timeout=10)

    def stop(self, timeout: float = 10.0) -> dict[str, int | None]:
        """SIGINT everything, wait, SIGKILL what is left; returns the exit codes."""
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        codes: dict[str, int | None] = {}
        for name, p in self.procs.items():
            try:
                codes[name] = p.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=5)
                codes[name] = None
        return codes

    def __enter__(self) -> Stack:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
