"""Robots for the service tests: the Gen3 on other bases, written to temporary robot files, and
the shipped robots (import from test modules)."""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

import pytest

import wmm_qp as w

GEN3 = w.default_robot_file()
SHIPPED = sorted((GEN3.parent).glob("*.toml"))
"""Every shipped robot file (configs/robots/*.toml)."""

BASES = {
    "diff_drive": 'kind = "diff_drive"\nwheel_radius = 0.0762\ntrack_width = 0.44\n'
                  "wheel_speed_max = 13.0\nwheel_acceleration_max = 20.0\n",
    "omni": 'kind = "omni"\nwheel_radius = 0.0762\nbase_radius = 0.3\n'
            "wheel_speed_max = 13.0\nwheel_acceleration_max = 20.0\n",
    "fixed": 'kind = "fixed"\n',
}

_BASE_KEYS = {"kind", "wheel_radius", "l1", "l2", "base_radius", "track_width", "wheel_speed_max",
              "wheel_acceleration_max"}


def gen3_text(base: str | None = None, **arm: str) -> str:
    """The Gen3 robot file with its URDF made absolute, its [base] replaced by ``BASES[base]``
    (None: the Mecanum base) and some [arm] keys replaced by the given TOML values."""
    text = GEN3.read_text()
    text = text.replace('urdf = "gen3_7dof.urdf"', f'urdf = "{GEN3.parent / "gen3_7dof.urdf"}"')
    for key, value in arm.items():
        text, n = re.subn(rf"^{key} = .*$", f"{key} = {value}", text, count=1, flags=re.M)
        if n == 0:
            text = text.replace("[arm]\n", f"[arm]\n{key} = {value}\n", 1)
    if base is not None:  # the [base] table's kind, geometry and wheel limits replaced, the rest kept
        out, in_base = [], False
        for line in text.splitlines():
            if line.startswith("["):
                in_base = line.strip() == "[base]"
                out.append(line)
                if in_base:
                    out += BASES[base].splitlines()
                continue
            key = line.split("=")[0].strip()
            if in_base and key in _BASE_KEYS:
                continue
            out.append(line)
        text = "\n".join(out) + "\n"
    return text


def gen3_file(folder: Path, base: str | None = None, name: str | None = None, **arm: str) -> Path:
    """A Gen3 robot file in ``folder`` (see :func:`gen3_text`), named ``gen3_<base>``."""
    text = gen3_text(base, **arm)
    robot = name or f"gen3_{base or 'mecanum'}"
    text = text.replace('name = "wmm"', f'name = "{robot}"')
    p = folder / f"{robot}.toml"
    p.write_text(text)
    return p


@cache
def shipped(stem: str) -> w.RobotConfig:
    """A shipped robot (skips when its optional package, example-robot-data, is missing)."""
    try:
        return w.load_robot_config(GEN3.parent / f"{stem}.toml")
    except w.ConfigError as e:
        if "example-robot-data" in str(e) or "package" in str(e):
            pytest.skip(f"needs the robots extra: {e}")
        raise
