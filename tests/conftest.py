"""Shared fixtures: a sim + daemon stack on loopback with a unique prefix and ports.

The helpers the test modules share live in the package ``support`` (``tests/support/``); their
asserts are rewritten like a test module's, so a failure in one shows its values."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

pytest.register_assert_rewrite("support")


@pytest.fixture
def service_stack(tmp_path: Path) -> Iterator[Callable[..., object]]:
    """Factory of started :class:`wmm_qp_service.processes.Stack`; all stopped at teardown."""
    from wmm_qp_service.processes import Stack, isolated_config

    stacks: list[Stack] = []

    def make(rate_hz: float = 500.0, **kw: object) -> Stack:
        s = Stack(isolated_config(), rate_hz=rate_hz, log_dir=tmp_path, **kw)  # type: ignore[arg-type]
        stacks.append(s)
        return s.start()

    yield make
    for s in stacks:
        s.stop()
