"""The driver contract (docs/drivers.md) checked by its kit (``wmm_qp_tools.contract``, the
checks of ``wmm-qp contract``) against both drivers: the sim (``wmm-qp sim``, the reference) and
the Franka FR3 driver (``wmm-qp driver franka``) with franky-sim in a child process (libfranka's
connect holds the GIL: never in the test's process). Each driver is started on an isolated prefix
and yields its service config, robot, rate and command timeout. That the checks can fail, one
mutant driver per check: tests/integration/test_contract_command.py.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from wmm_qp_service.processes import Stack, isolated_config
from wmm_qp_sim import load_sim_config
from wmm_qp_tools import contract

import wmm_qp as w

pytestmark = pytest.mark.integration

Driver = tuple[Any, w.RobotConfig, float, float]  # service config, robot, rate [Hz], command timeout [s]


@contextlib.contextmanager
def sim_driver(tmp: Path) -> Iterator[Driver]:
    """``wmm-qp sim`` for the default robot."""
    robot = w.load_robot_config()
    stack = Stack(isolated_config(robot=robot), log_dir=tmp)
    stack.start_sim()
    try:
        cfg = load_sim_config()
        yield stack.svc, robot, cfg.rate_hz, cfg.stale_timeout
    finally:
        stack.stop()


@contextlib.contextmanager
def franka_driver(tmp: Path) -> Iterator[Driver]:
    """``wmm-qp driver franka`` against franky-sim, each in its own process."""
    pytest.importorskip("pylibfranka", reason="needs pylibfranka (pip install 'wmm-qp[franka]')")
    pytest.importorskip("franky_sim", reason="needs franky-sim (pip install franky-sim)")
    from support.franky_rig import FR3, driver_stack, start_franky_sim

    robot = w.load_robot_config(FR3)
    sim = start_franky_sim(robot)
    try:
        with driver_stack(sim, tmp, serve=False) as (svc, _):
            yield svc, robot, 1000.0, 0.025
    finally:
        sim.close()


DRIVERS: dict[str, Callable[[Path], contextlib.AbstractContextManager[Driver]]] = {
    "sim": sim_driver, "franka": franka_driver}


@pytest.fixture(params=sorted(DRIVERS), scope="module")
def verdicts(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Every check of the kit against one driver, by name."""
    with contextlib.ExitStack() as stack:
        svc, robot, rate, timeout = stack.enter_context(DRIVERS[request.param](tmp_path_factory.mktemp(request.param)))
        c = stack.enter_context(contract.Controller(svc, robot))
        contract.wait_for_driver(c, 90.0)  # a first start compiles
        return contract.check_all(c, rate, timeout)


@pytest.mark.parametrize("name", contract.NAMES)
def test_the_driver_meets_each_duty_of_the_contract(verdicts: dict[str, Any], name: str) -> None:
    r = verdicts[name]
    assert r.passed, r.detail
