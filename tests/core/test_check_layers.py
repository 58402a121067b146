"""The layer check (``tools/check_layers.py``): the real tree passes; a copy of it with one import
that breaks ``wmm_qp`` ← ``wmm_qp_sim`` ← ``wmm_qp_service`` fails, naming the file, line and import."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "check_layers.py"
PACKAGES = ("wmm_qp", "robot/wmm_qp_robot", "sim/wmm_qp_sim", "service/wmm_qp_service", "tools/wmm_qp_tools")


def check(root: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(TOOL), "--root", str(root)], capture_output=True, text=True,
                          timeout=60, check=False)


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the five packages' sources (no caches), as the repository lays them out."""
    root = tmp_path_factory.mktemp("tree")
    for folder in PACKAGES:
        shutil.copytree(ROOT / folder, root / folder, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    return root


def test_the_real_tree_keeps_the_layers() -> None:
    r = check(ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("layers: OK")


def test_the_untouched_copy_passes(tree: Path) -> None:
    r = check(tree)
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.mark.parametrize(("file", "code", "at", "named"), [
    # module level: computation imports the service
    ("wmm_qp/_probe.py", "from wmm_qp_service.config import ServiceConfig\n", 1,
     "wmm_qp imports wmm_qp_service ('from wmm_qp_service.config import ServiceConfig')"),
    # inside a function: the sim imports the service (what its Zenoh adapter did)
    ("sim/wmm_qp_sim/_probe.py", "def _late():\n    from wmm_qp_service.keys import Keys\n    return Keys\n", 2,
     "wmm_qp_sim imports wmm_qp_service ('from wmm_qp_service.keys import Keys')"),
    # only for the type checker: still an upward edge
    ("wmm_qp/_probe.py", "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import wmm_qp_sim.robot\n", 3,
     "wmm_qp imports wmm_qp_sim ('import wmm_qp_sim.robot')"),
    # by name at run time
    ("sim/wmm_qp_sim/_probe.py", "import importlib\n_d = importlib.import_module('wmm_qp_service.daemon')\n", 2,
     "wmm_qp_sim imports wmm_qp_service (\"importlib.import_module('wmm_qp_service.daemon')\")"),
    # the robot side every robot shares imports the sim (a driver would load the sim through it)
    ("robot/wmm_qp_robot/_probe.py", "from wmm_qp_sim.plant import Plant\n", 1,
     "wmm_qp_robot imports wmm_qp_sim ('from wmm_qp_sim.plant import Plant')"),
    # a real robot's driver imports the sim (it shares only wmm_qp_robot with it)
    ("service/wmm_qp_service/drivers/_probe.py", "from wmm_qp_sim.robot import SimRobot\n", 1,
     "the driver wmm_qp_service.drivers._probe imports the sim ('from wmm_qp_sim.robot import SimRobot')"),
    # the runtime imports a tool (a robot process would load the bench)
    ("service/wmm_qp_service/_probe.py", "from wmm_qp_tools.bench import run_bench\n", 1,
     "wmm_qp_service imports wmm_qp_tools ('from wmm_qp_tools.bench import run_bench')"),
    # transport below the service layer
    ("sim/wmm_qp_sim/_probe.py", "def _open():\n    import zenoh\n    return zenoh\n", 2,
     "wmm_qp_sim imports zenoh ('import zenoh'): transport stays at the edge"),
    # ROS 2 outside its package: every other module must load without a ROS 2 installation
    ("service/wmm_qp_service/daemon/_probe.py", "import rclpy\n", 1,
     "wmm_qp_service.daemon._probe imports rclpy ('import rclpy'): ROS 2 is imported only in wmm_qp_service.ros2"),
    ("service/wmm_qp_service/drivers/_probe.py", "from sensor_msgs.msg import JointState\n", 1,
     "wmm_qp_service.drivers._probe imports sensor_msgs"),
    # the ROS 2 driver imports the sim (only the stand-in robot, ros2/sim_robot.py, may)
    ("service/wmm_qp_service/ros2/_probe.py", "from wmm_qp_sim.plants import make_plant\n", 1,
     "the driver wmm_qp_service.ros2._probe imports the sim ('from wmm_qp_sim.plants import make_plant')"),
])
def test_an_upward_import_fails_the_check_naming_it(tree: Path, file: str, code: str, at: int, named: str) -> None:
    """``code`` is a new module ``file`` of the copy; ``at``: its offending line (1-based)."""
    path = tree / file
    path.write_text(code)
    try:
        r = check(tree)
    finally:
        path.unlink()
    assert r.returncode == 1, r.stdout + r.stderr
    assert f"{file}:{at}: {named}" in r.stdout, r.stdout
    assert "layers: FAIL: 1 import(s)" in r.stdout


def test_downward_and_own_imports_pass(tree: Path) -> None:
    path = tree / "service/wmm_qp_service/_probe.py"
    path.write_text("import zenoh\nimport wmm_qp_sim.robot\n\n\ndef _f():\n    from wmm_qp import scene\n"
                    "    from . import config\n    return scene, config, zenoh\n")
    try:
        r = check(tree)
    finally:
        path.unlink()
    assert r.returncode == 0, r.stdout


def test_a_tool_may_import_every_layer_and_zenoh(tree: Path) -> None:
    path = tree / "tools/wmm_qp_tools/_probe.py"
    path.write_text("import zenoh\nimport wmm_qp_sim.robot\nfrom wmm_qp_service import cli\nimport wmm_qp\n")
    try:
        r = check(tree)
    finally:
        path.unlink()
    assert r.returncode == 0, r.stdout


def test_a_root_without_the_packages_is_bad_usage(tmp_path: Path) -> None:
    r = check(tmp_path)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and f"--root {tmp_path}" in r.stderr and "sim/wmm_qp_sim" in r.stderr


def test_an_import_circle_between_files_fails_the_check_naming_its_modules(tree: Path) -> None:
    """Two files of one package that import each other at load time (through the package's
    ``__init__`` re-export: ``from wmm_qp_sim import SimRobot`` names the ``__init__``)."""
    probe = tree / "sim/wmm_qp_sim/_probe.py"
    probe.write_text("from wmm_qp_sim import SimRobot\n")
    init = tree / "sim/wmm_qp_sim/__init__.py"
    before = init.read_text()
    init.write_text(before + "\nfrom wmm_qp_sim import _probe\n")
    try:
        r = check(tree)
    finally:
        probe.unlink()
        init.write_text(before)
    assert r.returncode == 1, r.stdout
    assert "import circle: wmm_qp_sim → wmm_qp_sim._probe" in r.stdout, r.stdout
    assert "layers: FAIL: 1 import circle(s) between files" in r.stdout


def test_an_import_only_for_the_type_checker_or_inside_a_function_closes_no_circle(tree: Path) -> None:
    probe = tree / "sim/wmm_qp_sim/_probe.py"
    probe.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from wmm_qp_sim import SimRobot\n\n\n"
                     "def _late():\n    from wmm_qp_sim import SimRobot\n    return SimRobot\n")
    init = tree / "sim/wmm_qp_sim/__init__.py"
    before = init.read_text()
    init.write_text(before + "\nfrom wmm_qp_sim import _probe\n")
    try:
        r = check(tree)
    finally:
        probe.unlink()
        init.write_text(before)
    assert r.returncode == 0, r.stdout
