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
    assert c.W is None  # the robot's: the Gen3 file gives the paper's W
    assert (c.ee_box_lower[2], c.ee_box_upper[2]) == (0.36, 0.56)
    r = w.load_robot_config()
    np.testing.assert_array_equal(c.weights_for(r), [1, 1, 1, 1, 2.5, 2.5, 2.5])
    np.testing.assert_array_equal(r.arm.torque_limit, [32] * 4 + [13] * 3)
    assert r.arm.acceleration_max.max() <= 10.0 and r.arm.acceleration_max[:4].max() <= 5.2


def test_configs_are_frozen() -> None:
    c = w.load_controller_config()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.K_x = 3.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        c.direction[0] = 2.0
    with pytest.raises(ValueError):
        w.load_robot_config().arm.start[0] = 2.0


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
        ("[dm]\nW = [1, -2]\n", "dm.W"),
        ("[task]\nkind = 'joint'\n", "task.kind"),
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


def _robot_file(tmp_path: Path, old: str = "", new: str = "") -> Path:
    """The Gen3's robot file in tmp_path with one replacement (its URDF copied next to it)."""
    robots = default_config_dir() / "robots"
    src = (robots / "gen3_mecanum.toml").read_text()
    (tmp_path / "gen3_7dof.urdf").write_text((robots / "gen3_7dof.urdf").read_text())
    assert old in src
    p = tmp_path / "robot.toml"
    p.write_text(src.replace(old, new, 1))
    return p


def test_robot_config_errors_name_file_and_key(tmp_path: Path) -> None:
    p = _robot_file(tmp_path, "wheel_radius = 0.0762", "wheel_radius = -1")
    with pytest.raises(w.ConfigError, match=r"base\.wheel_radius"):
        w.load_robot_config(p)
    p.write_text("not toml [")
    with pytest.raises(w.ConfigError, match="not valid TOML"):
        w.load_robot_config(p)


BAD_ROBOT_FILES = {  # (replace this, with this) → the key the error must name, and a word of its reason
    "frame the URDF lacks": (('ee_frame = "end_effector_link"', 'ee_frame = "tool0"'), "arm.ee_frame", "no link"),
    "ee_frame a joint, not a link": (('ee_frame = "end_effector_link"', 'ee_frame = "end_effector"'), "arm.ee_frame",
                                     "is a joint of the URDF, not a link (its child link: 'end_effector_link')"),
    "joint not in the URDF": (('"joint_7"]', '"joint_8"]'), "arm.joints", "no joint"),
    "joints not one chain": (('joints = ["joint_1", "joint_2"', 'joints = ["joint_2", "joint_1"'), "arm.joints",
                             "order"),
    "unknown base kind": (('kind = "mecanum"', 'kind = "tracked"'), "base.kind", "must be one of"),
    "no acceleration limit": (("acceleration_max = [5.2, 5.2, 5.2, 5.2, 10.0, 10.0, 10.0]", ""), "arm.acceleration_max",
                              "missing"),
    "URDF that does not parse": (('urdf = "gen3_7dof.urdf"', 'urdf = "broken.urdf"'), "arm.urdf", "cannot load"),
    "missing URDF": (('urdf = "gen3_7dof.urdf"', 'urdf = "nowhere.urdf"'), "arm.urdf", "not found"),
    "missing optional package": (('urdf = "gen3_7dof.urdf"', 'urdf = "package://example-robot-data-x/robots/a.urdf"'),
                                 "arm.urdf", "not installed"),
    "pkg:// of a Python package not installed": (('urdf = "gen3_7dof.urdf"', 'urdf = "pkg://no_such_pkg_x/a.urdf"'),
                                                 "arm.urdf", "Python package 'no_such_pkg_x', which is not installed"),
    "pkg:// of a file the package lacks": (('urdf = "gen3_7dof.urdf"', 'urdf = "pkg://wmm_qp/nowhere.urdf"'),
                                           "arm.urdf", "has no file 'nowhere.urdf'"),
    "a jerk limit that is not positive": (("[base]", "jerk_max = -1.0\n\n[base]"), "arm.jerk_max", "> 0"),
    "start outside the limits": (("start = [0.0, 0.5235987755982988", "start = [0.0, 2.5"), "arm.start", "outside"),
    "start of the wrong length": (("start = [0.0, ", "start = ["), "arm.start", "list of 7"),
    "a wheel limit per wheel of the wrong count": (("wheel_speed_max = 13.0", "wheel_speed_max = [13.0, 13.0]"),
                                                   "base.wheel_speed_max", "4 numbers"),
    "a key of another base kind": (("l2 = 0.22", "l2 = 0.22\ntrack_width = 0.5"), "base.track_width", "unknown key"),
    "locked joint that is controlled": (("[base]", "locked = {joint_1 = 0.0}\n\n[base]"), "arm.locked.joint_1",
                                        "controlled joint"),
}


@pytest.mark.parametrize("case", list(BAD_ROBOT_FILES))
def test_bad_robot_files_name_the_file_and_the_key(tmp_path: Path, case: str) -> None:
    (old, new), key, why = BAD_ROBOT_FILES[case]
    p = _robot_file(tmp_path, old, new)
    (tmp_path / "broken.urdf").write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'>")
    with pytest.raises(w.ConfigError) as e:
        w.load_robot_config(p)
    assert e.value.key == key and e.value.path == p, str(e.value)
    assert why in e.value.reason, str(e.value)
    assert "\n" not in str(e.value)  # one line


def test_a_controller_W_of_another_length_than_the_robot_is_a_clear_error(tmp_path: Path) -> None:
    p = tmp_path / "controller.toml"
    p.write_text("[dm]\nW = [1.0, 2.0, 3.0]\n")
    c = w.load_controller_config(p)
    with pytest.raises(w.ConfigError) as e:
        c.weights_for(w.load_robot_config())
    assert e.value.key == "dm.W" and e.value.path == p and "7 joints" in e.value.reason
    with pytest.raises(w.ConfigError, match=r"dm\.W"):
        w.make_controller("qp", w.WmmModel(w.load_robot_config()), c)


def test_W_defaults_to_the_torque_ratio_without_the_robot_files_weight(tmp_path: Path) -> None:
    p = _robot_file(tmp_path, "torque_weight = [1.0, 1.0, 1.0, 1.0, 2.5, 2.5, 2.5]", "")
    r = w.load_robot_config(p)
    assert r.arm.torque_weight is None
    np.testing.assert_allclose(r.arm.default_W(), [1, 1, 1, 1, 32 / 13, 32 / 13, 32 / 13])  # tau_ref/tau_lim, eq. (8)


def test_pkg_urdf_resolves_inside_an_installed_python_package(tmp_path: Path) -> None:
    import shutil

    import wmm_qp

    pkg = Path(wmm_qp.__file__).parent
    target = pkg / "_test_pkg_urdf.urdf"  # a file inside an installed package, removed after
    shutil.copy(default_config_dir() / "robots" / "gen3_7dof.urdf", target)
    try:
        p = _robot_file(tmp_path, 'urdf = "gen3_7dof.urdf"', 'urdf = "pkg://wmm_qp/_test_pkg_urdf.urdf"')
        r = w.load_robot_config(p)
    finally:
        target.unlink()
    assert r.arm.urdf == target and r.arm.jerk_max is None


def test_the_fr3_file_holds_frankas_published_limits() -> None:
    pytest.importorskip("franky_sim", reason="the FR3's URDF ships with franky-sim (pip install franky-sim)")
    r = w.load_robot_config(default_config_dir() / "robots" / "fr3.toml")
    a = r.arm
    assert r.base.kind == "fixed" and a.n == 7 and a.ee_frame == "fr3_link8"
    np.testing.assert_array_equal(a.position_upper, [2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159])
    np.testing.assert_array_equal(a.velocity_max, [2.62] * 4 + [5.26, 4.18, 5.26])
    np.testing.assert_array_equal(a.acceleration_max, [10.0] * 7)
    assert a.jerk_max is not None
    np.testing.assert_array_equal(a.jerk_max, [5000.0] * 7)
