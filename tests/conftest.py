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


@pytest.fixture(autouse=True)
def _scheduling_left_as_found() -> Iterator[None]:
    """The test process's scheduling as each test found it: a kit held open across a module's
    tests raises its thread to SCHED_FIFO, and every process started later inherits it (CPU hogs
    at FIFO once starved a demo at the same priority for good). Put back after each test."""
    import os

    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
    except (AttributeError, OSError):
        yield
        return
    yield
    if (os.sched_getscheduler(0), os.sched_getparam(0)) != before:
        os.sched_setscheduler(0, *before)
