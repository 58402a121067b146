"""Live obstacles messages: every malformed obstacle is rejected with the offending key
named, the message as a whole (no partial sets), and the last accepted set stays in force.

The validator is the only gate between the obstacles topic and the collision rows, so each case
here is an attack: a message that reached the rows could make them NaN, infinite or huge.
"""

from __future__ import annotations

import math
from typing import Any

import pytest
from wmm_qp_service.config import ServiceConfig
from wmm_qp_service.protocol import ObstaclesMsg, encode
from wmm_qp_service.validation import Validator

ROBOT = "wmm"
LIM = ServiceConfig().validation
BALL: dict[str, Any] = {"id": "ball", "kind": "sphere", "radius": 0.1, "xyz": [1.0, 0.0, 0.5]}


def message(*obstacles: dict[str, Any], source: str = "perception") -> bytes:
    return encode(ObstaclesMsg(robot=ROBOT, source=source, obstacles=list(obstacles)))


def validator() -> Validator[ObstaclesMsg]:
    v: Validator[ObstaclesMsg] = Validator(ObstaclesMsg, ROBOT, LIM)
    assert v(message(BALL)) is not None  # a valid set first: it must survive what follows
    assert [s.name for s in v.shapes] == ["ball"]
    return v


def with_(**change: Any) -> dict[str, Any]:
    return {**BALL, **change}


CASES = [
    ("unknown kind", with_(kind="torus"), "kind"),
    ("negative radius", with_(radius=-0.1), "radius"),
    ("NaN radius", with_(radius=math.nan), "radius"),
    ("infinite position", with_(xyz=[math.inf, 0.0, 0.0]), "xyz"),
    ("NaN position", with_(xyz=[0.0, math.nan, 0.0]), "xyz"),
    ("position of 2 numbers", with_(xyz=[0.0, 0.0]), "xyz"),
    ("position as text", with_(xyz="here"), "xyz"),
    ("unknown key", with_(colour="red"), "colour"),
    ("NaN velocity", with_(velocity=[0.0, math.nan, 0.0]), "velocity"),
    ("exempt not a list", with_(exempt="ee"), "exempt"),
    ("empty id", with_(id=""), "id"),
    ("a box without size", {"id": "crate", "kind": "box", "xyz": [1.0, 0.0, 0.0]}, "size"),
    ("a box of zero width", {"id": "crate", "kind": "box", "size": [0.0, 0.2, 0.2], "xyz": [1.0, 0.0, 0.0]}, "size"),
    ("far away", with_(xyz=[1e6, 0.0, 0.0]), "xyz"),
    ("huge", with_(radius=1e4), "size"),
]


@pytest.mark.parametrize(("what", "obstacle", "key"), CASES, ids=[c[0] for c in CASES])
def test_a_malformed_obstacle_is_rejected_naming_its_key(what: str, obstacle: dict[str, Any], key: str) -> None:
    v = validator()
    good = {"id": "crate", "kind": "box", "size": [0.2, 0.2, 0.2], "xyz": [0.0, 1.0, 0.1]}
    assert v(message(good, obstacle)) is None, what  # one bad obstacle: the whole message
    assert key in v.last_rejection, v.last_rejection
    assert sum(v.rejected.values()) == 1
    assert [s.name for s in v.shapes] == ["ball"]  # the last accepted set is kept


def test_duplicate_ids_too_many_obstacles_and_an_empty_source_are_rejected() -> None:
    v = validator()
    assert v(message(BALL, with_(xyz=[2.0, 0.0, 0.5]))) is None
    assert "unique" in v.last_rejection
    many = [with_(id=f"b{i}") for i in range(LIM.obstacles_max + 1)]
    assert v(message(*many)) is None
    assert f"at most {LIM.obstacles_max}" in v.last_rejection
    assert v(message(BALL, source="")) is None
    assert "source" in v.last_rejection
    assert [s.name for s in v.shapes] == ["ball"]


def test_an_empty_list_clears_the_live_set() -> None:
    v = validator()
    assert v(message()) is not None
    assert v.shapes == ()
