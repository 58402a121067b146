"""The firmware's stream rules, once for every robot (``wmm_qp_robot.stream_rules``)."""

from __future__ import annotations

from wmm_qp_robot.shaper import CommandShaper
from wmm_qp_robot.stream_rules import StreamRules, Verdict
from wmm_qp_sim.robot import SimRobot

from wmm_qp.fault_codes import FaultCode


def rules() -> StreamRules:
    r = StreamRules()
    r.reset_rules()
    return r


def test_an_illegal_command_is_a_protective_stop_that_ends_its_stream() -> None:
    r = rules()
    assert r.receive("a", None, at_rest=True) is Verdict.FOLLOW
    assert r.receive("a", "too fast", at_rest=False) is Verdict.REFUSED
    assert r.protective and r.protective_stops == 1 and r.protective_code == FaultCode.REFUSED_COMMAND.value
    assert r.protective_reason == "refused command: too fast"
    assert r.receive("a", None, at_rest=False) is Verdict.ENDED  # the stopped stream: ended, no new fault
    assert r.receive("b", None, at_rest=False) is Verdict.BRAKING  # a new one, still moving: refused
    assert r.receive("b", None, at_rest=True) is Verdict.RESUME and not r.protective
    assert (r.refused, r.ended, r.protective_stops) == (2, 1, 1)


def test_a_stale_stop_ends_its_stream_and_a_new_stream_resumes_at_once() -> None:
    r = rules()
    r.receive("a", None, at_rest=True)
    assert r.go_stale() and not r.go_stale()  # one event
    assert r.receive("a", None, at_rest=False) is Verdict.ENDED
    assert r.receive("b", None, at_rest=False) is Verdict.FOLLOW and not r.stale  # moving or not
    assert (r.refused, r.ended, r.protective_stops) == (0, 1, 0)


def test_an_illegal_first_command_of_a_new_stream_at_rest_makes_the_stop_its_own() -> None:
    r = rules()
    r.receive("a", "bad", at_rest=True)
    assert r.receive("b", "bad", at_rest=True) is Verdict.REFUSED and r.stopped_stream == "b"
    assert r.receive("b", None, at_rest=True) is Verdict.ENDED
    assert r.receive("a", None, at_rest=True) is Verdict.RESUME  # "a" is no longer the stopped one


def test_every_robot_is_the_same_rules() -> None:
    """The simulated robot and the shaper (the FR3) are both StreamRules and neither redefines
    the rules themselves: one definition of the stream rules."""
    for robot in (SimRobot, CommandShaper):
        assert issubclass(robot, StreamRules)
        for name in ("receive", "go_stale", "releases", "restop", "reset_rules"):
            assert getattr(robot, name) is getattr(StreamRules, name), (robot.__name__, name)
