"""The driver contract (docs/drivers.md) checked by its kit (``wmm_qp_tools.contract``) against
both drivers: the sim (``wmm-qp sim``, the reference) and the Franka FR3 driver
(``wmm-qp driver franka``) with franky-sim in a child process (libfranka's connect holds the GIL:
never in the test's process). Each driver is a factory: it starts the driver on an isolated
prefix and yields its service config, robot, rate and command timeout.
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
def controller(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    with contextlib.ExitStack() as stack:
        svc, robot, rate, timeout = stack.enter_context(DRIVERS[request.param](tmp_path_factory.mktemp(request.param)))
        c = stack.enter_context(contract.Controller(svc, robot))
        c.until(lambda st: True, 90.0, "a first state from the driver")  # a first start compiles
        yield c, rate, timeout


def test_it_publishes_states_at_its_rate_with_one_instance_and_its_token(controller: Any) -> None:
    c, rate, _ = controller
    out = contract.check_states(c, rate)
    assert out["states"] > 0


def test_it_obeys_only_the_lease_holder_for_its_instance(controller: Any) -> None:
    c, _, _ = controller
    contract.check_lease(c)


def test_it_brakes_to_rest_on_stale_commands(controller: Any) -> None:
    c, _, timeout = controller
    out = contract.check_brakes_when_stale(c, timeout)
    assert out["detect_s"] < timeout + contract.SLACK


def test_a_stale_stop_ends_the_stream_and_a_new_stream_resumes(controller: Any) -> None:
    c, _, timeout = controller
    contract.check_stale_ends_the_stream(c, timeout)


def test_it_refuses_a_command_past_the_limits_with_a_protective_stop(controller: Any) -> None:
    c, _, _ = controller
    contract.check_refuses_past_limits(c)


def test_after_a_stop_only_a_new_stream_resumes(controller: Any) -> None:
    c, _, _ = controller
    contract.check_stops_the_stopped_stream(c)


def test_the_kit_catches_a_robot_without_firmware(tmp_path: Path) -> None:
    """The kit can fail: a sim whose firmware is off (``firmware = false``) applies a command past
    the velocity limit, and :func:`~wmm_qp_tools.contract.check_refuses_past_limits` says so."""
    from wmm_qp.config import default_config_dir as cfg_dir

    sim_toml = tmp_path / "sim_no_firmware.toml"
    sim_toml.write_text((cfg_dir() / "sim.toml").read_text().replace("firmware = true", "firmware = false"))
    robot = w.load_robot_config()
    stack = Stack(isolated_config(robot=robot), log_dir=tmp_path, extra_sim_args=["--sim-config", str(sim_toml)])
    stack.start_sim()
    try:
        with contract.Controller(stack.svc, robot) as c:
            c.until(lambda st: True, 90.0, "a first state from the sim")
            contract.check_lease(c)
            with pytest.raises(contract.ContractError, match="protective stop"):
                contract.check_refuses_past_limits(c)
    finally:
        stack.stop()
