"""``wmm-qp teleop keyboard`` in a real terminal (tmux): keys move the EE target and the
simulated EE follows, the hold key holds (the daemon goes to hold, keys move nothing), the quit
key quits (exit status 0)."""

from __future__ import annotations

import re
import shutil
import subprocess
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from support.console_helpers import service_args, wait_for
from wmm_qp_service.processes import CLI

pytestmark = [pytest.mark.integration, pytest.mark.slow]

TARGET = re.compile(r"target\s+x\s+([-+]\d+\.\d+)\s+y\s+([-+]\d+\.\d+)\s+z\s+([-+]\d+\.\d+)")


class Tmux:
    """A private tmux server (its own socket) running one command in a 160×20 pane."""

    def __init__(self, command: str) -> None:
        self.sock = f"wmmtest{uuid.uuid4().hex[:8]}"
        self._run("new-session", "-d", "-s", "t", "-x", "160", "-y", "20", command)

    def _run(self, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(["tmux", "-L", self.sock, *args], capture_output=True, text=True, timeout=30)

    def keys(self, *keys: str) -> None:
        self._run("send-keys", "-t", "t", *keys)

    def screen(self) -> str:
        return self._run("capture-pane", "-p", "-t", "t").stdout

    def alive(self) -> bool:
        return self._run("has-session", "-t", "t").returncode == 0

    def target(self) -> np.ndarray | None:
        m = TARGET.search(self.screen())
        return None if m is None else np.array([float(v) for v in m.groups()])

    def kill(self) -> None:
        self._run("kill-server")


def test_keyboard_teleop_in_tmux(tmp_path: Path) -> None:
    if shutil.which("tmux") is None:
        pytest.skip("tmux missing: apt-get install -y tmux")
    from wmm_qp_service.client import Client
    from wmm_qp_service.processes import Stack, isolated_config

    with Stack(isolated_config(), log_dir=tmp_path) as stack, Client(stack.svc, name="observer") as obs:
        assert obs.wait_for_daemon(60.0) is not None, "daemon did not answer"
        exit_file = tmp_path / "exit"
        cmd = " ".join([*CLI, "teleop", "keyboard", "--speed", "0.1",
                        *service_args(stack.svc)])
        tmux = Tmux(f"{cmd} 2> {tmp_path / 'teleop.log'}; echo $? > {exit_file}")
        try:
            x0 = wait_for("the teleop's screen", tmux.target, timeout=60.0)
            assert "mode" in tmux.screen() and "daemon" in tmux.screen()
            wait_for("mode track", lambda: (s := obs.latest_status()) is not None and s.mode == "track")
            ee0 = np.asarray(wait_for("a truth", obs.latest_truth).ee_true)

            def pressed_forward() -> bool:  # w: +x, a key press at a time, as a held key repeats
                tmux.keys("w")
                time.sleep(0.05)
                t, st = tmux.target(), obs.latest_truth()
                return t is not None and t[0] > x0[0] + 0.04 and st is not None and st.ee_true[0] > ee0[0] + 0.03

            wait_for("the target and the simulated EE 3-4 cm forward", pressed_forward, timeout=60.0, every=0.0)
            t1 = tmux.target()
            assert t1 is not None and abs(t1[1] - x0[1]) < 1e-3 and abs(t1[2] - x0[2]) < 1e-3  # x only

            tmux.keys("Space")
            wait_for("mode hold after the hold key",
                     lambda: (s := obs.latest_status()) is not None and s.mode == "hold")
            wait_for("HOLDING on the screen", lambda: "HOLDING" in tmux.screen())
            held = tmux.target()
            x_d = np.asarray(obs.latest_status().x_d)  # type: ignore[union-attr]
            for _ in range(10):
                tmux.keys("w")
                time.sleep(0.05)
            time.sleep(0.5)
            assert tmux.target() == pytest.approx(held)           # keys move nothing while holding
            # the daemon holds where the EE came to rest (mm), not where ten more presses would be (cm)
            assert np.asarray(obs.latest_status().x_d) == pytest.approx(x_d, abs=5e-3)  # type: ignore[union-attr]

            tmux.keys("q")
            wait_for("the teleop to quit", lambda: exit_file.exists() and exit_file.read_text().strip(), timeout=30.0)
            assert exit_file.read_text().strip() == "0", (tmp_path / "teleop.log").read_text()
        finally:
            tmux.kill()
