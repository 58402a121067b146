"""What the console costs the daemon: its tick p50 with and without a console attached, in one run.

``python -m wmm_qp_service.console.cost [--rounds 3] [--phase-s 20] [--browser] [--json]``

Starts a sim and a daemon (isolated ports), then alternates phases without and with
``wmm-qp console`` attached (optionally with Debian's headless chromium showing the page),
ABBA… so that a slow spell of a shared machine falls on both. In each phase it reads the
daemon's own tick percentiles (``status.loop.tick_p50_us``, over its last 2048 ticks) once a
second after a settling time, and reports the median of each phase kind and their ratio.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..config import ServiceConfig
from ..processes import CLI


def _console(s: ServiceConfig, port: int, log: Path) -> subprocess.Popen[bytes]:
    args = ["--port", str(port), "--prefix", s.prefix, "--robot", s.robot,
            "--daemon-endpoint", s.zenoh.daemon_endpoint, "--sim-endpoint", s.zenoh.sim_endpoint]
    return subprocess.Popen([*CLI, "console", *args],
                            stdin=subprocess.DEVNULL, stdout=open(log, "ab"), stderr=subprocess.STDOUT)


def _browser(port: int, profile: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen(["/usr/bin/chromium", "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                             "--disable-background-networking", "--disable-component-update", "--disable-sync",
                             f"--user-data-dir={profile}", "--window-size=1280,800", f"http://127.0.0.1:{port}"],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _stop(p: subprocess.Popen[bytes] | None) -> None:
    if p is not None and p.poll() is None:
        p.send_signal(2)
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def main(argv: list[str] | None = None) -> int:
    from ..client import Client
    from ..processes import Stack, free_port, isolated_config

    ap = argparse.ArgumentParser(prog="python -m wmm_qp_service.console.cost", description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3, help="pairs of phases (without, with), ABBA order")
    ap.add_argument("--phase-s", type=float, default=20.0, help="[s] each phase (the first 6 s settle)")
    ap.add_argument("--browser", action="store_true", help="also show the page in headless chromium")
    ap.add_argument("--rate", type=float, default=500.0, help="[Hz] daemon rate")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="wmm-qp-console-cost-"))
    samples: dict[str, list[float]] = {"without": [], "with": []}
    order = []
    for r in range(a.rounds):
        order += ["without", "with"] if r % 2 == 0 else ["with", "without"]
    with Stack(isolated_config(), rate_hz=a.rate, log_dir=tmp) as stack, Client(stack.svc, name="cost") as c:
        if c.wait_for_daemon(60.0) is None:
            print("error: the daemon did not answer", file=sys.stderr)
            return 1
        time.sleep(5.0)
        for kind in order:
            console = browser = None
            if kind == "with":
                port = free_port()
                console = _console(stack.svc, port, tmp / "console.log")
                if a.browser:
                    time.sleep(8.0)
                    browser = _browser(port, tmp / f"profile{len(samples['with'])}")
            end = time.monotonic() + a.phase_s
            time.sleep(6.0 if kind == "without" else (6.0 if not a.browser else 2.0))
            while time.monotonic() < end:
                st = c.latest_status()
                if st is not None:
                    samples[kind].append(st.loop.tick_p50_us)
                time.sleep(1.0)
            _stop(browser)
            _stop(console)
    med = {k: statistics.median(v) for k, v in samples.items() if v}
    out = {"p50_us_median": med, "ratio_with_over_without": med["with"] / med["without"],
           "samples": {k: len(v) for k, v in samples.items()}, "rounds": a.rounds, "phase_s": a.phase_s,
           "browser": a.browser, "rate_hz": a.rate, "order": order}
    if a.json:
        print(json.dumps(out))
    else:
        seq = "".join("A" if k == "without" else "B" for k in order)
        print(f"daemon tick p50: without console {med['without']:.1f} µs, with {med['with']:.1f} µs "
              f"(x{out['ratio_with_over_without']:.3f}; {out['samples']} samples, phases {seq})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
