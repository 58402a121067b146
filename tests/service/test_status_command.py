"""``wmm-qp status``'s text: what it says of a robot's referee counts, and of a robot without one."""

from __future__ import annotations

import pytest
from wmm_qp_service.commands.status import show
from wmm_qp_service.protocol import InfoMsg, StatusMsg


def _info(violations: dict[str, int]) -> InfoMsg:
    st = StatusMsg(robot="r", mode="hold", state_ok=True, safe_stop=False, robot_violations=violations)
    return InfoMsg(robot="r", status=st, config={"controller": {"kind": "qp"}})


@pytest.mark.parametrize("violations, line", [
    ({}, "robot      violations not refereed (the robot publishes no truth)"),
    ({"position": 0, "collision": 0}, "robot      violations 0"),
    ({"position": 2, "collision": 0}, "robot      violations 2 {'position': 2, 'collision': 0}"),
])
def test_status_says_whether_the_robot_was_refereed(violations: dict[str, int], line: str,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A driver that publishes no truth has ``{}``: not "0 violations", which would claim a referee
    that never ran; a robot with a referee shows its counts."""
    show(_info(violations), "p/r")
    out = capsys.readouterr().out.splitlines()
    assert line in out, out
    assert not any(x.startswith("sim ") for x in out)
