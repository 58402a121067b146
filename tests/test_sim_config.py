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
])
def test_sim_config_errors_name_file_and_key(tmp_path: Path, text: str, key: str) -> None:
    p = tmp_path / "sim.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_sim_config(p)
    assert e.value.key == key and str(p) in str(e.value)
