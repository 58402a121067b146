"""service.toml loads into a frozen ServiceConfig; errors name the file and the dotted key."""

from __future__ import annotations

from pathlib import Path

import pytest
from wmm_qp_service.config import load_service_config

from wmm_qp.exceptions import ConfigError


def test_shipped_service_config_loads() -> None:
    c = load_service_config()
    assert c.loop.rate_hz == 500.0 and c.watchdog.command_hold == 0.035 and c.zenoh.config.is_file()
    # command_hold is the robot's command timeout plus the state age the daemon checks
    from wmm_qp_sim import load_sim_config

    assert c.watchdog.command_hold - c.watchdog.state_age_max == pytest.approx(load_sim_config().stale_timeout)
    assert c.watchdog.resume == "manual" and c.loop.queries_per_tick == 1
    assert c.loop.trigger in ("rate", "state")


@pytest.mark.parametrize("text, key", [
    ("[loop]\nrate_hz = -1\n", "loop.rate_hz"),
    ("[loop]\nrt_priority = 1.5\n", "loop.rt_priority"),
    ("[zenoh]\nbogus = 1\n", "zenoh.bogus"),
    ("[zenoh]\ndaemon_endpoint = ''\n", "zenoh.daemon_endpoint"),
    ("mystery = 1\n", "mystery"),
    ("[validation]\nz_min = 11.0\n", "validation.z_min"),
    ("[loop]\ntrigger = \"clock\"\n", "loop.trigger"),
])
def test_service_config_errors_name_file_and_key(tmp_path: Path, text: str, key: str) -> None:
    p = tmp_path / "service.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_service_config(p)
    assert e.value.key == key and str(p) in str(e.value)


def test_negative_z_min_is_allowed(tmp_path: Path) -> None:
    p = tmp_path / "service.toml"
    p.write_text("[validation]\nz_min = -0.3\n")
    assert load_service_config(p).validation.z_min == -0.3


def test_the_robot_id_is_the_robot_files_name_unless_set(tmp_path: Path) -> None:
    """Each robot file has its own keys: an open robot id (no `robot` in service.toml, no
    --robot) is the robot description's name; one the service config sets is kept."""
    from support.service_robots import gen3_file
    from wmm_qp_service.config import ServiceConfig, default_robot_id

    import wmm_qp as w

    robot = w.load_robot_config(gen3_file(tmp_path, "diff_drive"))
    p = tmp_path / "service.toml"
    p.write_text("prefix = \"lab\"\n")
    open_id = load_service_config(p)
    assert open_id.robot == "" and open_id.with_robot(robot).robot == "gen3_diff_drive"
    p.write_text("robot = \"cell-3\"\n")
    assert load_service_config(p).with_robot(robot).robot == "cell-3"
    assert ServiceConfig().resolved().robot == default_robot_id() == w.load_robot_config().name == "wmm"
    bad = w.load_robot_config(gen3_file(tmp_path, "fixed", name="two words"))
    with pytest.raises(ConfigError) as e:
        ServiceConfig().with_robot(bad)
    assert e.value.key == "name" and "two words" in str(e.value)
