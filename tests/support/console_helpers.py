"""Helpers of the console tests: start ``wmm-qp console`` on a stack, a headless Debian chromium,
screenshot analysis, polling."""

from __future__ import annotations

import os
import queue
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
SHOTS_ENV = "WMM_QP_CONSOLE_SHOTS"
"""A folder to copy the tests' screenshots to (docs/img when the docs' figures are made)."""

T = TypeVar("T")


def browser_missing() -> str | None:
    """Why the browser test cannot run here (None: it can)."""
    if not Path(CHROMIUM).exists():
        return f"{CHROMIUM} missing: apt-get install -y chromium"
    try:
        import playwright  # noqa: F401
        import viser  # noqa: F401
        import yourdfpy  # noqa: F401
    except ImportError as e:
        return f"{e.name} missing: pip install '.[test]'"
    return None


class Drag:
    """Drags a console's target gizmo to ``target``, and again when asked or every ``every`` s: a
    gap longer than the daemon's setpoint timeout in the console's 1 s stream brings the target to
    rest (docs/protocol.md), and on a loaded machine an operator would drag again."""

    def __init__(self, url: str, target: np.ndarray, every: float = 3.0) -> None:
        self.url, self.target, self.every = url, target, every
        self.now()

    def now(self) -> None:
        from wmm_qp_service.console.wire import move_gizmo

        move_gizmo(self.url, self.target)
        self.at = time.monotonic()

    def if_due(self) -> None:
        if time.monotonic() - self.at > self.every:
            self.now()


def wait_for(what: str, fn: Callable[[], T | None], timeout: float = 30.0, every: float = 0.1) -> T:
    """Poll ``fn`` until it returns something truthy; fail with ``what`` after ``timeout`` [s]."""
    end = time.monotonic() + timeout
    while True:
        v = fn()
        if v is not None and (v is not False) and (not hasattr(v, "__len__") or isinstance(v, np.ndarray) or len(v)):
            return v
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(every)


def service_args(svc: Any) -> list[str]:
    return ["--prefix", svc.prefix, "--daemon-endpoint", svc.zenoh.daemon_endpoint,
            "--sim-endpoint", svc.zenoh.sim_endpoint]


@contextmanager
def console_process(args: list[str], log: Path, timeout: float = 60.0,
                    prefix: list[str] | None = None) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """Run ``wmm-qp console ARGS`` (under ``prefix``, e.g. ``ip netns exec NS``) until its URL is
    printed; yields (process, url); always stopped."""
    cmd = [*(prefix or []), sys.executable, "-P", "-m", "wmm_qp_service.cli", "console", *args]
    p = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=open(log, "w"),  # noqa: SIM115
                         text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert p.stdout is not None
        for line in p.stdout:
            lines.put(line)

    threading.Thread(target=pump, daemon=True).start()
    try:
        end = time.monotonic() + timeout
        url = ""
        while not url:
            try:
                line = lines.get(timeout=0.5)
            except queue.Empty:
                if p.poll() is not None:
                    raise AssertionError(f"console exited {p.returncode}: {log.read_text()[-2000:]}") from None
                if time.monotonic() > end:
                    tail = log.read_text()[-2000:]
                    raise AssertionError(f"console printed no URL in {timeout:g} s: {tail}") from None
                continue
            if line.startswith("console: http"):
                url = line.split()[1]
                p.url_line = line.strip()  # type: ignore[attr-defined]
        yield p, url
    finally:
        if p.poll() is None:
            p.send_signal(2)
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=5)


@contextmanager
def chromium_page(user_dir: Path, width: int = 1400, height: int = 850) -> Iterator[Any]:
    """A page of Debian's headless chromium (Playwright, executable_path=/usr/bin/chromium, a fresh profile)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        ctx = pw.chromium.launch_persistent_context(str(user_dir), executable_path=CHROMIUM, headless=True,
                                                    args=CHROMIUM_ARGS, viewport={"width": width, "height": height})
        try:
            yield ctx.new_page()
        finally:
            ctx.close()


class StatusLog:
    """Every status the daemon publishes (a FIFO subscriber on an open client's session), so a
    mode that a fault on a loaded machine ends quickly is still seen."""

    def __init__(self, client: Any) -> None:
        import msgspec
        import zenoh
        from wmm_qp_service.protocol import StatusMsg

        self._dec = msgspec.msgpack.Decoder(StatusMsg)
        self._sub = client.session.declare_subscriber(client.keys.status, zenoh.handlers.FifoChannel(10_000))
        self.seen: list[Any] = []

    def poll(self) -> list[Any]:
        while (s := self._sub.try_recv()) is not None:
            self.seen.append(self._dec.decode(s.payload.to_bytes()))
        return self.seen

    def mark(self) -> int:
        return len(self.poll())

    def mode_seen(self, mode: str, since: int) -> bool:
        return any(st.mode == mode for st in self.poll()[since:])

    def summary(self, since: int, last: int = 12) -> str:
        """The changes of (mode, safe stop, resume needed, last fault) in the statuses since
        ``since``: what a failed wait prints."""
        runs: list[tuple[Any, ...]] = []
        for st in self.poll()[since:]:
            key = (st.mode, st.safe_stop, st.resume_needed, st.last_fault)
            if not runs or runs[-1] != key:
                runs.append(key)
        return f"{len(self.seen) - since} statuses; changes: " + "; ".join(
            f"mode={m} safe_stop={s} resume_needed={r} last_fault={f!r}" for m, s, r, f in runs[-last:])


def click_until_mode(page: Any, log: StatusLog, label: str, mode: str, timeout: float = 90.0,
                     again: float = 10.0) -> int:
    """Click the button ``label`` until the daemon's status shows ``mode``, again every ``again``
    [s] as an operator would (a mode sent while the page's websocket reconnects, or during a safe
    stop on a loaded machine, is lost or overruled: docs/protocol.md); fails after ``timeout`` [s]
    with what the statuses showed. Returns the number of clicks."""
    since = log.mark()
    end, last, clicks = time.monotonic() + timeout, -float("inf"), 0
    while not log.mode_seen(mode, since):
        now = time.monotonic()
        if now > end:
            raise AssertionError(f"timed out after {timeout:g} s waiting for mode {mode} in the daemon's "
                                 f"status after {clicks} clicks on {label!r}: {log.summary(since)}")
        if now - last > again:
            click_button(page, label)
            clicks, last = clicks + 1, now
        time.sleep(0.1)
    return clicks


def log_tails(folder: Path, chars: int = 1500) -> str:
    """The ends of the ``*.log`` files in ``folder`` (the stack's and the console's logs)."""
    return "\n".join(f"--- {f.name}:\n{f.read_text(errors='replace')[-chars:]}" for f in sorted(folder.glob("*.log")))


def click_button(page: Any, text: str) -> None:
    """A real mouse click (DevTools input events) at the centre of the button labelled ``text``.

    Playwright's own ``click`` first waits until the page has drawn two equal frames; software
    WebGL on a loaded machine draws them seconds apart, so the button is located with one script
    call and clicked where it is."""
    box = page.evaluate("""(text) => {
        const b = Array.from(document.querySelectorAll('button')).find(e => e.innerText.trim() === text);
        if (!b) return null;
        b.scrollIntoView({block: 'center'});
        const r = b.getBoundingClientRect();
        return [r.x + r.width / 2, r.y + r.height / 2];
    }""", text)
    if box is None:
        raise AssertionError(f"no button {text!r} on the page")
    page.mouse.click(box[0], box[1])


def screenshot(page: Any) -> bytes:
    """A PNG of the page through the DevTools protocol (``Page.captureScreenshot``: it takes the
    last composited frame; Playwright's own screenshot waits for a new one, which software WebGL
    on a loaded machine may not deliver within its time-out)."""
    import base64

    cdp = page.context.new_cdp_session(page)
    try:
        return base64.b64decode(cdp.send("Page.captureScreenshot", {"format": "png"})["data"])
    finally:
        cdp.detach()


def scene_pixels(png: bytes, panel_px: int = 420) -> np.ndarray:
    """The 3D view's pixels (RGB) of a screenshot: the page without the control panel on its right."""
    import io

    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)
    return img[:, : img.shape[1] - panel_px]


def canvas_not_blank(px: np.ndarray) -> tuple[bool, str]:
    """Whether the 3D view shows something: the robot's dark base and arm (pixels darker than 130
    in every channel: ≥ 0.1 % of the view) and a spread of colours (≥ 50 distinct, 4-bit per
    channel). A white or uniform canvas fails both. The whole Gen3 robot is 0.8 % of the default
    view (docs/img/console.png); CI once drew only part of it in 240 s (0.29 %), which is still
    a drawn robot. The 'odometry' label alone is under 0.03 %."""
    dark = float(np.mean((px < 130).all(axis=2)))
    q = (px // 16).reshape(-1, 3)
    distinct = len(np.unique(q[:, 0] * 256 + q[:, 1] * 16 + q[:, 2]))
    ok = dark >= 0.001 and distinct >= 50
    return ok, f"dark fraction {dark:.4f}, {distinct} distinct colours"


def save_shot(png: bytes, tmp: Path, name: str) -> Path:
    """Write a screenshot to tmp (and to $WMM_QP_CONSOLE_SHOTS when set)."""
    out = tmp / name
    out.write_bytes(png)
    dest = os.environ.get(SHOTS_ENV)
    if dest:
        Path(dest).mkdir(parents=True, exist_ok=True)
        shutil.copy(out, Path(dest) / name)
    return out


def urdf_mesh_links(urdf: Path) -> int:
    """How many links of a URDF have a visual mesh (read from its XML, not by the console's loader)."""
    import xml.etree.ElementTree as ET

    return sum(1 for link in ET.parse(urdf).getroot().iter("link") if link.find("visual/geometry/mesh") is not None)
