"""`wmm-qp demo` end to end (short): both processes, every mode, strict-JSON summary."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def test_demo_json_summary() -> None:
    out = subprocess.run([sys.executable, "-m", "wmm_qp_service.cli", "demo", "--duration", "6",
                          "--json"], capture_output=True, text=True, timeout=180, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    d = json.loads(out.stdout)
    for k in ("rate_hz", "tick_p50_us", "tick_p99_us", "deadline_misses", "ticks"):
        assert k in d["loop"]
    assert d["loop"]["ticks"] > 1000
    assert d["violations_total"] == 0 and set(d["violations"]) >= {"position", "velocity"}
    assert 0.0 <= d["ee_error_max"] < 0.05
    assert d["dm_end"] > d["dm_start"]  # the DM phases raised DM along x
    assert [p["phase"] for p in d["phases"]][:3] == ["hold", "dm_cartesian", "dm_nullspace"]
    assert d["exit_codes"] == {"sim": 0, "daemon": 0}


def test_demo_rejects_bad_arguments() -> None:
    out = subprocess.run([sys.executable, "-m", "wmm_qp_service.cli", "demo", "--rate", "-1"],
                         capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 2 and "Traceback" not in out.stderr
