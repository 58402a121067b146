"""Bodies inside another body of their link: the rows compute their self pairs only while the
containers' pair is near d_s (``RobotGeometry.covered_by``, ``row_pairs``, ``covered_pairs``).

A shape inside another is at least as far from anything as the other, so the rows that keep the
container d_s apart keep it too. The attacks: the distances themselves (coal's, on the row shapes),
over random configurations, for every pair so left out; a sphere 1 mm too large, or a capsule that
reaches out, is not taken as covered; ``wmm-qp verify`` on the Panda (states sampled inside d_s,
where a covered pair has rows of its own)."""

from __future__ import annotations

from dataclasses import replace

import coal
import numpy as np
import pytest
from support.collision_robots import model

import wmm_qp as w
from wmm_qp.config import ShapeConfig
from wmm_qp.model.collision import COVER_REACH, RobotGeometry, distance, robot_geometry


def _geometry(name: str) -> RobotGeometry:
    m = model(name)
    return robot_geometry(m.config, m.arm)


def test_the_pandas_end_spheres_are_left_to_their_cylinders_capsules() -> None:
    """example-robot-data's Panda draws each capsule as a cylinder and two spheres at its ends: the
    cylinder's row shape (its capsule) contains both: 22 of its 40 bodies, whose self pairs the
    rows compute only near d_s."""
    geo = _geometry("panda_diffdrive.toml")
    b = geo.bodies
    covered = [k for k, c in enumerate(geo.covered_by) if c >= 0]
    assert len(covered) == 22
    for k in covered:
        c = geo.covered_by[k]
        assert isinstance(b[k].shape, coal.Sphere) and isinstance(b[c].shape, coal.Cylinder), (b[k].name, b[c].name)
        assert b[k].link == b[c].link and geo.covered_by[c] == -1
    assert len(geo.row_pairs) < len(geo.self_pairs) / 4
    assert sorted(geo.row_pairs + [(i, j) for i, j, _ in geo.covered_pairs]) == sorted(geo.self_pairs)
    for name in ("gen3_mecanum.toml", "fr3.toml", "ur5_omni.toml", "tiago.toml"):  # none: every pair monitored
        other = _geometry(name)
        assert other.row_pairs == other.self_pairs and not other.covered_pairs, name


@pytest.mark.parametrize("seed", range(3))
def test_no_pair_the_rows_leave_out_is_nearer_than_the_pair_they_keep(seed: int) -> None:
    """For every self pair the rows may leave out, at random configurations inside the joint
    limits: its distance (coal, on the row shapes) is no less than that of the containers' pair,
    which the rows monitor."""
    m = model("panda_diffdrive.toml")
    geo = _geometry("panda_diffdrive.toml")
    arm, b = m.config.arm, geo.bodies
    assert geo.covered_pairs

    rng = np.random.default_rng(seed)
    for _ in range(40):
        M = geo.placements(rng.uniform(arm.position_lower, arm.position_upper))
        for i, j, k in geo.covered_pairs:
            a, c = geo.row_pairs[k]
            assert (a, c) == tuple(sorted((geo.container(i), geo.container(j))))
            d = distance(b[i].row, M[i], b[j].row, M[j])[0]
            assert d >= distance(b[a].row, M[a], b[c].row, M[c])[0] - 1e-9, (b[i].name, b[j].name)


@pytest.mark.parametrize("seed", range(2))
def test_the_search_leaves_out_only_pairs_whose_containers_are_beyond_reach(seed: int) -> None:
    """The compiled search at random configurations: every self pair within d_i (coal, on the row
    shapes) is a candidate, but for a covered pair whose containers' pair is beyond d_s +
    COVER_REACH; with that reach infinite, every one is."""
    from wmm_qp.limits._pair_passes import robot_passes
    from wmm_qp.limits.pair_search import PairSearch

    m = model("panda_diffdrive.toml")
    geo = _geometry("panda_diffdrive.toml")
    p = w.load_controller_config().collision
    d_i, b, arm = p.influence_distance, geo.bodies, m.config.arm
    rng = np.random.default_rng(seed)
    for reach in (p.safety_distance + COVER_REACH, np.inf):
        left_out = 0
        search = PairSearch(geo, p)
        args = (*search.robot_args[:-1], reach)
        for _ in range(15):
            M = geo.placements(rng.uniform(arm.position_lower, arm.position_upper))  # (the arm's data's)
            search.place_joints()
            n, _ = robot_passes(*args)
            c = search.candidates
            got = {(int(c.body[k]), int(c.other[k])) for k in range(n) if c.d[k] < d_i and c.other[k] >= 0}
            dist = {(i, j): distance(b[i].row, M[i], b[j].row, M[j])[0] for i, j in geo.self_pairs}
            near = {q for q, d in dist.items() if d < d_i}
            missed = near - got
            left_out += len(missed)
            for i, j, k in geo.covered_pairs:
                if (i, j) in missed:
                    assert dist[geo.row_pairs[k]] >= reach - 1e-9, (b[i].name, b[j].name)
            assert missed <= {(i, j) for i, j, _ in geo.covered_pairs}, missed
            assert got <= {q for q, d in dist.items() if d < d_i + 1e-9}
        assert (left_out > 0) == np.isfinite(reach), left_out  # (the default leaves some out: the point)


def test_a_covered_pair_is_a_candidate_while_its_containers_are_within_reach() -> None:
    """Random configurations where a containers' pair is nearer than d_s + COVER_REACH (and not
    touching): each of its covered pairs within d_i is computed, so it has rows of its own. (Left
    to the containers down to contact, the Panda's right finger's sphere went 0.1 mm nearer the
    base's box from 2.67 cm: ``wmm-qp verify --samples 1500 --solver daqp``, 4 violations.)"""
    from wmm_qp.limits._pair_passes import robot_passes
    from wmm_qp.limits.pair_search import PairSearch

    m = model("panda_diffdrive.toml")
    geo = _geometry("panda_diffdrive.toml")
    p = w.load_controller_config().collision
    b, arm, reach = geo.bodies, m.config.arm, p.safety_distance + COVER_REACH
    search = PairSearch(geo, p)
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(400):
        M = geo.placements(rng.uniform(arm.position_lower, arm.position_upper))
        within = [(i, j) for i, j, k in geo.covered_pairs
                  if 0.0 < distance(b[geo.row_pairs[k][0]].row, M[geo.row_pairs[k][0]], b[geo.row_pairs[k][1]].row,
                                    M[geo.row_pairs[k][1]])[0] < reach
                  and distance(b[i].row, M[i], b[j].row, M[j])[0] < p.influence_distance]
        if not within:
            continue
        search.reset()
        search.place_joints()
        n, _ = robot_passes(*search.robot_args)
        c = search.candidates
        got = {(int(c.body[t]), int(c.other[t])) for t in range(n)}
        assert set(within) <= got, set(within) - got
        hits += len(within)
    assert hits >= 20, hits


def test_a_pair_inside_the_safety_distance_comes_no_nearer_on_the_panda() -> None:
    """States sampled inside d_s (9 cm into the base's box): a sphere at a capsule's end went 0.2 mm
    deeper while the capsule came out, when its pairs had no rows of their own there."""
    from wmm_qp.scene import load_scene
    from wmm_qp.verify import verify_controller

    m = model("panda_diffdrive.toml")
    ctl = w.make_controller("qp", m, w.load_controller_config().with_(collision={"enabled": True}))
    report = verify_controller(ctl, m, 60, 0, scene=load_scene())  # (4 violations when never computed)
    assert report.violations == 0, report.examples


def _gen3_with(*extra: ShapeConfig) -> RobotGeometry:
    robot = w.load_robot_config("configs/robots/gen3_mecanum.toml")
    robot = replace(robot, collision=replace(robot.collision, shapes=(*robot.collision.shapes, *extra)))
    m = w.WmmModel(robot)
    return robot_geometry(robot, m.arm)


def _sphere(name: str, link: str, radius: float, xyz: list[float]) -> ShapeConfig:
    return ShapeConfig(name, link, "sphere", np.array([radius, 0.0, 0.0]), np.array(xyz), np.zeros(3))


def test_only_a_shape_inside_another_of_its_link_is_covered() -> None:
    """The Gen3's forearm capsule (radius 0.045, to [0, −0.20843, −0.006375]): a sphere of its
    radius at that end is inside it, and a small one at its middle; one 1 mm larger there is not,
    nor a thin capsule from its start that reaches 4 cm past its end, nor one that starts 4 cm
    behind its start."""
    end = [0.0, -0.20843, -0.006375]
    geo = _gen3_with(_sphere("inside", "forearm_link", 0.045, end), _sphere("larger", "forearm_link", 0.046, end),
                     _sphere("mid", "forearm_link", 0.02, [0.0, -0.1, -0.003]),
                     ShapeConfig("long", "forearm_link", "capsule", np.array([0.01, 0.25, 0.0]),
                                 np.array([0.0, -0.125, 0.0]), np.array([np.pi / 2, 0.0, 0.0])),
                     ShapeConfig("back", "forearm_link", "capsule", np.array([0.01, 0.19, 0.0]),
                                 np.array([0.0, -0.055, 0.0]), np.array([np.pi / 2, 0.0, 0.0])))
    names = {b.name: k for k, b in enumerate(geo.bodies)}
    by = {b.name: (geo.bodies[geo.covered_by[k]].name if geo.covered_by[k] >= 0 else None)
          for k, b in enumerate(geo.bodies)}
    assert by["inside"] == "forearm" and by["mid"] == "forearm"
    assert by["larger"] is None and by["long"] is None and by["back"] is None
    assert by["forearm"] is None
    # the larger sphere contains the forearm's end and the small one, not the forearm: it stays
    assert any(names["larger"] in p for p in geo.row_pairs)
    assert not any(names["inside"] in p for p in geo.row_pairs)


def test_a_covered_body_keeps_its_own_pair_where_its_container_has_none() -> None:
    """Left to the containers are only the pairs whose containers' pair the rows monitor: where
    that pair was excluded as touching by construction (95 % of random configurations within 3 cm:
    the Panda's link1/link3), a covered body's own pair is computed every tick."""
    geo = _geometry("panda_diffdrive.toml")
    monitored = set(geo.self_pairs)

    own = [(i, j) for i, j in geo.row_pairs if geo.container(i) != i or geo.container(j) != j]  # every tick
    assert own, "every covered body's pairs were left to its container"
    for i, j in own:
        assert tuple(sorted((geo.container(i), geo.container(j)))) not in monitored
