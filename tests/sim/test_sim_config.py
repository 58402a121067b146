"""sim.toml loads into a frozen SimConfig; errors name the file and the dotted key."""

from __future__ import annotations

from pathlib import Path

import pytest
from wmm_qp_sim import load_sim_config

from wmm_qp.exceptions import ConfigError


def test_shipped_sim_config_loads() -> None:
    c = load_sim_config()
    assert c.rate_hz == 1000.0 and c.stale_timeout == 0.025 and c.slip.enabled


@pytest.mark.parametrize("text, key", [
    ("[slip]\nwheel_noise_tau = -1\n", "slip.wheel_noise_tau"),
    ("[box]\nbogus = 1\n", "box.bogus"),
    ("seed = -3\n", "seed"),
    ("rate_hz = 'fast'\n", "rate_hz"),
    ("mystery = 1\n", "mystery"),
    ("[box]\nenabled = true\nmass = 0\n", "box.mass"),
    ("rt_priority = 1.5\n", "rt_priority"),
    ("rt_priority = -1\n", "rt_priority"),
    ("rt_priority = 100\n", "rt_priority"),
])
def test_sim_config_errors_name_file_and_key(tmp_path: Path, text: str, key: str) -> None:
    p = tmp_path / "sim.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_sim_config(p)
    assert e.value.key == key and str(p) in str(e.value)


class _Started(Exception):
    """Raised by the fake SimNode: what ``wmm-qp sim`` asked for, without starting it."""


@pytest.mark.parametrize(("text", "flags", "expected"), [
    (None, [], 50),                       # the shipped configs/sim.toml
    ("rt_priority = 0\n", [], 0),         # a file that turns it off
    (None, ["--rt-priority", "7"], 7),    # the flag wins
])
def test_wmm_qp_sim_asks_for_the_configs_realtime_priority(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, text: str | None, flags: list[str], expected: int) -> None:
    import wmm_qp_service.drivers.sim_node as adapter
    from wmm_qp_service.commands import sim
    from wmm_qp_tools.cli import build_parser

    def fake_node(*args: object, rt_priority: int = 0, **kw: object) -> None:
        raise _Started(rt_priority)

    monkeypatch.setattr(adapter, "SimNode", fake_node)
    if text is not None:
        (tmp_path / "sim.toml").write_text(text)
        flags = [*flags, "--sim-config", str(tmp_path / "sim.toml")]
    args = build_parser("sim").parse_args(["sim", *flags])
    with pytest.raises(_Started) as e:
        sim.run(args)
    assert e.value.args == (expected,)
