"""Configs load into frozen dataclasses; every error names the file and the key."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import wmm_qp as w
from wmm_qp.config import default_config_dir


def test_shipped_configs_hold_the_papers_parameters() -> None:
    c = w.load_controller_config()
    assert (c.K_x, c.alpha, c.k_C, c.k_N, c.sigma_threshold) == (10.0, 0.2, 0.01, 0.2, 0.08)
    np.testing.assert_array_equal(c.W, [1, 1, 1, 1, 2.5, 2.5, 2.5])
    assert (c.ee_box_lower[2], c.ee_box_upper[2]) == (0.36, 0.56)
    r = w.load_robot_config()
    np.testing.assert_array_equal(r.arm.torque_limit, [32] * 4 + [13] * 3)
    assert r.arm.acceleration_max.max() <= 10.0 and r.arm.acceleration_max[:4].max() <= 5.2


def test_configs_are_frozen() -> None:
    c = w.load_controller_config()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.K_x = 3.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        c.W[0] = 2.0


def test_robot_limits_agree_with_the_urdf() -> None:
    import pinocchio as pin

    r = w.load_robot_config()
    m = pin.buildModelFromUrdf(str(r.arm.urdf))
    np.testing.assert_allclose(m.velocityLimit, r.arm.velocity_max)
    for j, (lo, hi) in enumerate(zip(r.arm.position_lower, r.arm.position_upper, strict=True)):
        if np.isfinite(lo):
            assert m.lowerPositionLimit[m.joints[j + 1].idx_q] == pytest.approx(lo)
            assert m.upperPositionLimit[m.joints[j + 1].idx_q] == pytest.approx(hi)


@pytest.mark.parametrize(
    "text, key",
    [
        ("rate_hz = -5\n", "rate_hz"),
        ("[gains]\nalpha = 2.0\n", "gains.alpha"),
        ("[dm]\nW = [1, 2]\n", "dm.W"),
        ("[dm]\ndirection = [0, 0, 0]\n", "dm.direction"),
        ("[qp]\nsolver = 'cplex'\n", "qp.solver"),
        ("[qp]\nbogus = 1\n", "qp.bogus"),
        ("controller = 'magic'\n", "controller"),
    ],
)
def test_controller_config_errors_name_file_and_key(tmp_path: Path, text: str, key: str) -> None:
    p = tmp_path / "controller.toml"
    p.write_text(text)
    with pytest.raises(w.ConfigError) as e:
        w.load_controller_config(p)
    assert e.value.key == key and str(p) in str(e.value)


def test_robot_config_errors_name_file_and_key(tmp_path: Path) -> None:
    src = (default_config_dir() / "robot.toml").read_text()
    (tmp_path / "gen3_7dof.urdf").write_text((default_config_dir() / "gen3_7dof.urdf").read_text())
    p = tmp_path / "robot.toml"
    p.write_text(src.replace("wheel_radius = 0.0762", "wheel_radius = -1"))
    with pytest.raises(w.ConfigError, match=r"base\.wheel_radius"):
        w.load_robot_config(p)
    p.write_text("not toml [")
    with pytest.raises(w.ConfigError, match="not valid TOML"):
        w.load_robot_config(p)
