"""The compiled GJK of the collision rows (wmm_qp/limits/_gjk.py) against coal: convex hulls
against hulls, boxes, capsules, spheres and planes at random poses; cores that touch or overlap
are left to coal; and the pair search with GJK gives the candidates coal gives, pair for pair."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import coal
import numpy as np
import pinocchio as pin
import pytest
from wmm_qp_tools.bench.collision import coal_search, leave_to_coal

import wmm_qp as w
from wmm_qp.limits import _gjk as G  # noqa: N812
from wmm_qp.limits.pair_search import ShapeArenas, Table
from wmm_qp.model.collision import convex_hull

REQ = coal.DistanceRequest()


def hull(rng: np.random.Generator, n: int = 40, scale: float = 0.1) -> coal.ConvexBase:
    """The convex hull of n random points (a random ellipsoid's worth)."""
    m = coal.BVHModelOBBRSS()
    pts = rng.normal(size=(n, 3)) * scale * rng.uniform(0.3, 1.5, 3)
    m.beginModel(0, n)
    for p in pts:
        m.addVertex(p)
    m.endModel()
    return convex_hull(m)


def arm_walk(model: w.WmmModel, seed: int, steps: int, scale: float) -> Iterator[None]:
    """The arm's data (forward kinematics, joint Jacobians) at each step of a random walk of its
    joints from its start (normal steps of ``scale`` rad)."""
    arm, rng = model.arm, np.random.default_rng(seed)
    q = np.array(model.config.arm.start, dtype=float)
    for _ in range(steps):
        q = q + rng.normal(scale=scale, size=q.shape)
        pin.computeJointJacobians(arm.model, arm.data, arm.pin_q(q))
        yield


def table(*shapes: tuple[Any, pin.SE3]) -> Table:
    t = Table(len(shapes))
    for k, (s, M) in enumerate(shapes):
        t.set(k, s, M, np.zeros(3))
    return t


def convex_pair(t: Table, p: np.ndarray, q: np.ndarray, n: np.ndarray,
                warm: np.ndarray | None = None) -> tuple[float, bool]:
    """``G.convex_pair`` of shapes 0 and 1 of t, its arrays packed as the compiled passes take them
    (``ShapeArenas``); ``warm``: the pair's warm start (1, WARM_WIDTH), read and updated (None: a
    cold start)."""
    a = ShapeArenas(t, warm_rows=1)
    if warm is not None:
        a.warm[:] = warm
    d, ok = G.convex_pair(a.F, a.I, a.L, 0, a.F, a.I, a.L, 1, p, q, n, -1 if warm is None else a.ow, a.ws, a.wi)
    if warm is not None:
        warm[:] = a.warm
    return d, ok


def coal_d(a: Any, Ma: pin.SE3, b: Any, Mb: pin.SE3) -> float:
    return float(coal.distance(a, coal.Transform3s(Ma.rotation, Ma.translation), b,
                               coal.Transform3s(Mb.rotation, Mb.translation), REQ, coal.DistanceResult()))


def test_hull_distances_agree_with_coal_and_touching_cores_are_left_to_it() -> None:
    rng = np.random.default_rng(7)
    p, q, n = np.empty(3), np.empty(3), np.empty(3)
    seen = {"separated": 0, "left": 0}
    for k in range(1200):
        A = hull(rng)
        B = (hull(rng), coal.Box(*rng.uniform(0.05, 0.3, 3)), coal.Capsule(rng.uniform(0.02, 0.08), 0.2),
             coal.Sphere(rng.uniform(0.02, 0.1)))[k % 4]
        Ma = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(scale=0.25, size=3))
        Mb = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(scale=0.25, size=3))
        t = table((A, Ma), (B, Mb))
        assert t.kind[0] == 3
        d, ok = convex_pair(t, p, q, n)
        ref = coal_d(A, Ma, B, Mb)
        if not ok:  # only where the cores touch or overlap: the shapes are then in contact or nearly
            seen["left"] += 1
            assert ref < 0.2 + 1e-9, ref  # (the capsule's and the sphere's radii are at most 0.1)
            continue
        seen["separated"] += 1
        assert d == pytest.approx(ref, abs=1e-6), (k, d, ref)
        np.testing.assert_allclose(p - q, d * n, atol=1e-9)
        assert np.linalg.norm(n) == pytest.approx(1.0)
    assert seen["separated"] > 900 and seen["left"] > 20, seen  # both branches ran


def test_a_warm_start_from_the_last_simplex_gives_the_cold_distance_as_the_shapes_move() -> None:
    """Each pair's warm row holds the simplex its last call ended on (its points by their numbers on
    the shapes): the next call starts there where the shapes are now. Along small random motions
    (a tick's) and jumps (a reset, a teleport) of hulls, boxes, capsules and spheres, the warm call
    gives the cold call's distance and coal's; the warm row's simplex is used (its size is set)."""
    rng = np.random.default_rng(11)
    p, q, n = np.empty(3), np.empty(3), np.empty(3)
    p0, q0, n0 = np.empty(3), np.empty(3), np.empty(3)
    used = compared = 0
    for k in range(120):
        A = (hull(rng), coal.Box(*rng.uniform(0.05, 0.3, 3)))[k % 2]
        B = (hull(rng), coal.Box(*rng.uniform(0.05, 0.3, 3)), coal.Capsule(0.05, 0.2), coal.Sphere(0.05))[k % 4]
        Ma = pin.SE3(pin.exp3(rng.normal(size=3)), np.zeros(3))
        Mb = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.3 + np.array([0.6, 0.0, 0.0]))
        warm = np.zeros((1, G.WARM_WIDTH))
        for step in range(40):
            jump = step % 13 == 12
            scale = 0.5 if jump else 0.01
            Ma = Ma * pin.SE3(pin.exp3(rng.normal(scale=scale, size=3)), rng.normal(scale=scale * 0.2, size=3))
            Mb = Mb * pin.SE3(pin.exp3(rng.normal(scale=scale, size=3)), rng.normal(scale=scale * 0.2, size=3))
            t = table((A, Ma), (B, Mb))
            used += warm[0, 3] > 0.0
            d, ok = convex_pair(t, p, q, n, warm)
            d0, ok0 = convex_pair(t, p0, q0, n0)
            if not (ok and ok0):
                continue
            compared += 1
            assert d == pytest.approx(d0, abs=2e-6), (k, step, d, d0)
            assert d == pytest.approx(coal_d(A, Ma, B, Mb), abs=2e-6), (k, step)
            np.testing.assert_allclose(p - q, d * n, atol=1e-9)
    assert used > 3000 and compared > 3000, (used, compared)


def test_box_distances_agree_with_coal_and_touching_boxes_are_left_to_it() -> None:
    """Two boxes (TIAGo's hand and column, the FR3's fingers): GJK on their corners, as coal's."""
    rng = np.random.default_rng(5)
    p, q, n = np.empty(3), np.empty(3), np.empty(3)
    seen = {"separated": 0, "left": 0}
    for _ in range(600):
        A, B = coal.Box(*rng.uniform(0.02, 0.4, 3)), coal.Box(*rng.uniform(0.02, 0.4, 3))
        Ma = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(scale=0.25, size=3))
        Mb = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(scale=0.25, size=3))
        t = table((A, Ma), (B, Mb))
        assert t.kind.tolist() == [1, 1]
        d, ok = convex_pair(t, p, q, n)
        ref = coal_d(A, Ma, B, Mb)
        if not ok:
            seen["left"] += 1
            assert ref < 1e-6, ref  # touching or overlapping
            continue
        seen["separated"] += 1
        assert d == pytest.approx(ref, abs=1e-6)
        np.testing.assert_allclose(p - q, d * n, atol=1e-9)
    assert seen["separated"] > 200 and seen["left"] > 50, seen


def test_a_hull_against_a_plane_is_its_deepest_vertex() -> None:
    rng = np.random.default_rng(3)
    floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), -0.2)  # solid z <= -0.2
    p, q, n = np.empty(3), np.empty(3), np.empty(3)
    for _ in range(200):
        A = hull(rng)
        Ma = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(scale=0.2, size=3))
        t = table((A, Ma))
        d = G.convex_plane(t.c, t.R, t.verts, t.vs, t.vc, 0, np.array([0.0, 0.0, -1.0]), 0.2, p, q, n)
        assert d == pytest.approx(coal_d(A, Ma, floor, pin.SE3.Identity()), abs=1e-9)
        assert q[2] == pytest.approx(-0.2) and n.tolist() == [0.0, 0.0, 1.0]


def test_a_broken_support_function_is_caught() -> None:
    """The check above can fail: a hull that forgets its last vertex is farther than coal says
    for some pose (the vertex it drops is the nearest one)."""
    rng = np.random.default_rng(11)
    p, q, n = np.empty(3), np.empty(3), np.empty(3)
    wrong = 0
    for _ in range(200):
        A, B = hull(rng), hull(rng)
        Ma, Mb = pin.SE3.Identity(), pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
        t = table((A, Ma), (B, Mb))
        t.vc[0] -= 1  # the mutation
        d, ok = convex_pair(t, p, q, n)
        wrong += ok and abs(d - coal_d(A, Ma, B, Mb)) > 1e-6
    assert wrong > 0


@pytest.mark.parametrize("robot", ["fr3.toml", "tiago.toml"])
def test_the_pair_search_with_gjk_gives_coals_candidates(robot: str) -> None:
    """Every step of a random walk of the arm: the same pairs, distances and normals as the search
    that leaves every hull to coal (coal at a GJK tolerance of 1e-12: its default's normals are
    ~1e-3 off at a centimetre)."""
    from wmm_qp_tools.bench.collision import load_scene

    from wmm_qp.config import default_config_dir

    model = w.WmmModel(w.load_robot_config(default_config_dir() / "robots" / robot))
    ctl = w.make_controller("qp", model, w.load_controller_config().with_(collision={"enabled": True}))
    ctl.set_scene(load_scene())
    gjk = ctl.collision.search  # type: ignore[attr-defined]
    # hulls and boxes to coal (a box's capsules: compiled); coal's default GJK tolerance, 1e-6,
    # leaves its normals ~1e-3 off at 1 cm
    coal_only = coal_search(gjk, kinds=(3, 1), gjk_tolerance=1e-12)
    assert (gjk._shapes.kind == 3).sum() >= 9
    arm = model.arm
    rng = np.random.default_rng(2)
    q = np.array(model.config.arm.start, dtype=float)
    limits = model.config.arm
    lo = np.where(np.isfinite(limits.position_lower), limits.position_lower, -np.pi)
    hi = np.where(np.isfinite(limits.position_upper), limits.position_upper, np.pi)
    by_gjk = 0
    for _ in range(60):
        q = np.clip(q + rng.normal(scale=0.15, size=q.shape), lo, hi)
        pin.forwardKinematics(arm.model, arm.data, q)
        gjk.search(np.zeros(3))
        coal_only.search(np.zeros(3))
        a, b = gjk.candidates, coal_only.candidates
        assert a.n == b.n and (a.body[:a.n] == b.body[:b.n]).all() and (a.other[:a.n] == b.other[:b.n]).all()
        np.testing.assert_allclose(a.d[:a.n], b.d[:b.n], atol=1e-9)
        far = b.d[:b.n] > 1e-3  # the normal is defined well away from contact
        np.testing.assert_allclose(a.normal[:a.n][far], b.normal[:b.n][far], atol=1e-6)
        by_gjk += int(a.ok[:a.n].sum() - b.ok[:b.n].sum())
    assert by_gjk > 100  # GJK, not coal, computed the hulls' pairs
    assert (gjk._warm != 0.0).any(axis=1).sum() >= 10  # ... each from where its last call ended
    ctl.reset()  # a reset forgets them, as it does the solvers' warm starts
    assert not gjk._warm.any()


def test_parallel_faces_give_the_exact_gap_not_a_fallback() -> None:
    """A hull of a cube's corners facing a box face to face (flat simplices, many equally near
    supports): the gap itself, by GJK, at every offset and small tilt."""
    m = coal.BVHModelOBBRSS()
    corners = [np.array([x, y, z]) * 0.1 for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    m.beginModel(0, 8)
    for c in corners:
        m.addVertex(c)
    m.endModel()
    cube = convex_hull(m)
    box = coal.Box(0.3, 0.5, 0.2)
    p, q, n = np.empty(3), np.empty(3), np.empty(3)
    for gap in (0.001, 0.0473, 0.12):
        for tilt in (0.0, 1e-9, 1e-4):
            Mb = pin.SE3(pin.exp3(np.array([0.0, 0.0, tilt])), np.array([0.1 + 0.15 + gap, 0.03, 0.02]))
            t = table((cube, pin.SE3.Identity()), (box, Mb))
            d, ok = convex_pair(t, p, q, n)
            assert ok, (gap, tilt)
            assert d == pytest.approx(coal_d(cube, pin.SE3.Identity(), box, Mb), abs=1e-9)
            if tilt == 0.0:
                assert d == pytest.approx(gap, abs=1e-12)


def test_tiagos_column_against_its_arm_link_is_gjks_where_a_step_stalls_on_rounding() -> None:
    """A TIAGo configuration of the bench's circle where a GJK step on its column's box and
    arm_6_link's hull gets no nearer through rounding: GJK's distance stands (within 1e-9 m of
    the bound that step gives), every hull pair is GJK's and equals coal's."""
    from wmm_qp.config import default_config_dir

    model = w.WmmModel(w.load_robot_config(default_config_dir() / "robots" / "tiago.toml"))
    ctl = w.make_controller("qp", model, w.load_controller_config().with_(collision={"enabled": True}))
    search = ctl.collision.search  # type: ignore[attr-defined]
    coal_only = coal_search(search, gjk_tolerance=1e-12)
    q = [0.16785213350729672, 0.42460319762495263, -1.3691945807292063, -0.3332646455706371, 1.6772312133895007,
         -1.7939971571707616, 0.5741980904734524, 5.551984119496981e-16]
    pin.forwardKinematics(model.arm.model, model.arm.data, np.array(q))
    a, b = search.search(np.zeros(3)), coal_only.search(np.zeros(3))
    kinds = search.placed.kind
    hull_pairs = [k for k in range(a.n) if a.other[k] >= 0 and 3 in (kinds[a.body[k]], kinds[a.other[k]])]
    names = [search.name(int(a.body[k]), int(a.other[k])) for k in hull_pairs]
    assert "torso_fixed_column_link_0/arm_6_link_0" in names, names
    assert all(a.ok[k] for k in hull_pairs), [n for k, n in zip(hull_pairs, names, strict=True) if not a.ok[k]]
    np.testing.assert_allclose(a.d[hull_pairs], b.d[hull_pairs], atol=1e-9)


def test_obstacle_pairs_keep_their_warm_starts_and_the_rows_their_names_until_reset() -> None:
    """The (obstacle, body) pairs keep GJK's start as the self pairs do (a reset forgets them);
    a tick's row names stay that tick's when the obstacle set changes afterwards."""
    from wmm_qp.config import default_config_dir
    from wmm_qp.limits.collision import warm_up_obstacles

    model = w.WmmModel(w.load_robot_config(default_config_dir() / "robots" / "fr3.toml"))
    ctl = w.make_controller("qp", model, w.load_controller_config().with_(collision={"enabled": True}))
    q = ctl.warm_up_configuration()
    obstacles = warm_up_obstacles(model.ee_position(np.zeros(3), q))
    ctl.set_obstacles(obstacles)
    search = ctl.collision.search  # type: ignore[attr-defined]
    ctl.step(w.RobotState(np.zeros(3), q), w.Reference("hold"))
    assert (search._warm_solid != 0.0).any(axis=1).sum() >= 3  # the hulls against the box and sphere
    rows = ctl.last_collision_rows()
    assert rows is not None
    names = list(rows.names)
    assert any(n.endswith("/warm-up sphere") for n in names), names
    ctl.set_obstacles(list(reversed(obstacles))[:1])  # another set: other indices, one obstacle
    assert list(rows.names) == names
    ctl.reset()
    assert not search._warm_solid.any() and not search._warm.any()


def test_the_placements_read_in_place_follow_every_forward_kinematics() -> None:
    """The pair search reads the joints' placements in Pinocchio's own memory (``placement_table``):
    along a random walk of TIAGo's arm its candidates equal, bit for bit, those of a search that
    copies each placement off ``data.oMi`` as before; a view that stops following them (a copy
    taken once) gives other candidates, and a memory laid out otherwise is refused, not misread."""
    from wmm_qp.config import default_config_dir
    from wmm_qp.limits.pair_search import PairSearch, placement_table

    model = w.WmmModel(w.load_robot_config(default_config_dir() / "robots" / "tiago.toml"))
    ctl = w.make_controller("qp", model, w.load_controller_config().with_(collision={"enabled": True}))
    in_place = ctl.collision.search  # type: ignore[attr-defined]
    copied, stale = PairSearch(in_place.geo, in_place.p), PairSearch(in_place.geo, in_place.p)
    assert in_place._in_place and in_place._oMi.base is not None  # a view, not a copy
    copied._in_place, copied._oMi = False, np.zeros((0, 12))
    stale._oMi = np.array(stale._oMi)  # the mutation: the placements as they were once
    copied._bind(), stale._bind()
    arm = model.arm
    differs = 0
    for _ in arm_walk(model, 5, 40, 0.1):
        a, b, s = (x.search(np.zeros(3)) for x in (in_place, copied, stale))
        assert a.n == b.n and (a.body[:a.n] == b.body[:b.n]).all() and (a.other[:a.n] == b.other[:b.n]).all()
        assert np.array_equal(a.d[:a.n], b.d[:b.n]) and np.array_equal(a.p_a[:a.n], b.p_a[:b.n])
        differs += s.n != a.n or not np.array_equal(s.d[:s.n], a.d[:a.n])
    assert differs > 30

    class Moved:  # each placement but the first in memory of its own, not where a packed SE3 would be
        def __init__(self, oMi: Any) -> None:
            self.oMi = [oMi[0]] + [pin.SE3(M) for M in list(oMi)[1:]]

    assert placement_table(Moved(arm.data.oMi)) is None


def _same_within(a: Any, b: Any, d_i: float) -> tuple[int, int]:
    """Asserts the candidates ``a`` (a search that leaves pairs out) within d_i are those of ``b``
    (one that does not), bit for bit; returns (how many fewer ``a`` has, how many are within d_i)."""
    near_a, near_b = np.flatnonzero(a.d[: a.n] < d_i), np.flatnonzero(b.d[: b.n] < d_i)
    assert near_a.shape == near_b.shape
    for f in ("d", "p_a", "p_b", "normal", "body", "other"):
        assert np.array_equal(getattr(a, f)[near_a], getattr(b, f)[near_b]), f
    return b.n - a.n, near_b.shape[0]


@pytest.mark.parametrize("robot", ["fr3", "tiago", "ur5_omni"])
def test_the_bounding_capsules_contain_their_shapes_and_cull_only_pairs_beyond_the_influence_distance(
        robot: str) -> None:
    """Each body's bounding capsule (``bounding_capsule``) holds every vertex of its hull and every
    corner of its box; along a random walk of the arm, the search that leaves out the pairs whose
    capsules are further apart than d_i gives, bit for bit, the candidates within d_i of one
    that computes every pair the spheres let through (both started cold each tick), and leaves some
    pair out. A capsule one vertex short (its radius shrunk) is caught."""
    from wmm_qp.config import default_config_dir
    from wmm_qp.limits.pair_search import PairSearch
    from wmm_qp.model.collision import bounding_capsule

    model = w.WmmModel(w.load_robot_config(default_config_dir() / "robots" / f"{robot}.toml"))
    ctl = w.make_controller("qp", model, w.load_controller_config().with_(collision={"enabled": True}))
    culled = ctl.collision.search  # type: ignore[attr-defined]
    every = PairSearch(culled.geo, culled.p)
    every._cap_r[:] = np.inf  # the capsules never cull

    def outside(shape: Any, a: np.ndarray, b: np.ndarray, r: float) -> float:
        """How far the shape's farthest point is outside the capsule (≤ 0: inside)."""
        if isinstance(shape, coal.Box):
            h = np.asarray(shape.halfSide)
            pts = np.array([[sx * h[0], sy * h[1], sz * h[2]] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        elif isinstance(shape, coal.ConvexBase):
            pts = np.array([np.asarray(shape.point(i)) for i in range(shape.num_points)])
        else:
            return -1.0
        u = b - a
        t = np.clip((pts - a) @ u / max(float(u @ u), 1e-300), 0.0, 1.0)
        return float(np.max(np.linalg.norm(pts - (a + np.outer(t, u)), axis=1)) - r)

    kinds = set()
    for body in culled.geo.bodies:
        a, b, r = bounding_capsule(body.row)
        kinds.add(type(body.row).__name__)
        assert outside(body.row, a, b, r) <= 0.0, body.name
        if not isinstance(body.row, coal.Capsule | coal.Sphere):
            assert outside(body.row, a, b, r - 1e-3) > 0.0, body.name  # the mutation: 1 mm short
    assert "Box" in kinds or robot != "tiago"
    d_i = culled.p.influence_distance
    left_out = 0
    for _ in arm_walk(model, 7, 60, 0.15):
        culled.reset()
        every.reset()
        left_out += _same_within(culled.search(np.zeros(3)), every.search(np.zeros(3)), d_i)[0]
    assert left_out > 0


@pytest.mark.parametrize(("robot", "scale"), [("panda_diffdrive", 0.01), ("panda_diffdrive", 0.04),
                                              ("gen3_mecanum", 0.03)])
def test_a_pair_left_out_by_its_last_distance_has_not_come_within_the_influence_distance(
        robot: str, scale: float) -> None:
    """The search leaves out a pair of capsules while its last distance (or its bounding spheres'
    gap), less how far either body can have moved since (``body_travel``), keeps it beyond d_i.
    Along random walks of the arm (steps of 0.01–0.04 rad a joint: a few ticks at full speed
    each), its candidates within d_i equal, bit for bit, those of a search that computes every pair
    each step (its slack forgotten before each), and it leaves pairs out. The
    mutations caught (in ``_pair_passes``): the travel without the bodies' rotation (its centre's
    only), the travel of the last step only, none (a pair beyond d_i once is left out while it
    passes the bounding spheres), and the spheres' gap taken for the slack without d_i."""
    from wmm_qp.config import default_config_dir
    from wmm_qp.limits.pair_search import PairSearch

    model = w.WmmModel(w.load_robot_config(default_config_dir() / "robots" / f"{robot}.toml"))
    ctl = w.make_controller("qp", model, w.load_controller_config().with_(collision={"enabled": True}))
    coherent = ctl.collision.search  # type: ignore[attr-defined]
    every = PairSearch(coherent.geo, coherent.p)
    d_i = coherent.p.influence_distance
    left_out = near_pairs = 0
    for seed in range(4):
        coherent.reset()
        for _ in arm_walk(model, seed, 150, scale):
            every._slack[:, 0] = -math.inf  # every pair computed (its warm starts kept: GJK's pairs alike)
            out, near = _same_within(coherent.search(np.zeros(3)), every.search(np.zeros(3)), d_i)
            left_out += out
            near_pairs += near
    assert left_out > 0 and near_pairs > 0


def test_the_rows_wait_for_the_candidates_left_to_coal() -> None:
    """Without obstacles the search and the rows run in one compiled call (``_robot_rows``), which
    returns no rows where it left candidates to coal: the rows are made once coal has filled them.
    The FR3's rows with its hulls left to coal (every tick has such candidates) are its rows with
    GJK's distances (the same pairs; C and l within 1e-6), at every step of random walks of the
    arm; rows made before coal's distances (or none) would not be."""
    from wmm_qp.config import default_config_dir
    from wmm_qp.limits.collision import CollisionRows

    model = w.WmmModel(w.load_robot_config(default_config_dir() / "robots" / "fr3.toml"))
    ctl = w.make_controller("qp", model, w.load_controller_config().with_(collision={"enabled": True}))
    a = ctl.collision  # type: ignore[attr-defined]
    b = CollisionRows(a.geo, a.M, a.p, a.latency, a._accel, a.inside.dt)
    leave_to_coal(b.search, kinds=(3, 1))
    b.search._req.gjk_tolerance = 1e-12
    n_v = a.n_w + a.n_a
    v0, lb, ub = np.zeros(n_v), -np.ones(n_v), np.ones(n_v)
    compared = 0
    for seed in range(3):
        for _ in arm_walk(model, seed, 40, 0.08):
            ra, rb = (x.rows(np.zeros(3), np.zeros(a.n_a), v0, lb, ub) for x in (a, b))
            assert list(rb.names) == list(ra.names)
            np.testing.assert_allclose(rb.C, ra.C, atol=1e-6)
            np.testing.assert_allclose(rb.l, ra.l, atol=1e-6)
            compared += ra.n
    assert compared > 0


def _spun_capsule(y0: float, dtheta: float, half: float = 0.3, r: float = 0.02,
                  d_i: float = 0.15) -> tuple[int, int]:
    """A capsule (half-length ``half``) spun about its own centre in the xy-plane, in steps of
    ``dtheta``, its end sweeping towards a sphere at (0, y0, 0): its centre never moves, so only the
    travel's rotation term (‖ΔR‖_F ρ) keeps the pair in. The compiled passes each step, with the
    pair's slack kept and forgotten: (pairs the first left out, steps whose candidates within d_i
    differ)."""
    from wmm_qp.limits._pair_passes import body_travel, place_kernel, self_pass

    kind, joint = np.zeros(2, np.int64), np.arange(2)
    l_a0, l_a1 = np.array([[0.0, 0, 0], [-half, 0, 0]]), np.array([[0.0, 0, 0], [half, 0, 0]])
    rad, radii = np.array([r, r]), np.array([r, half + r])
    pairs = np.array([[0, 1]])
    pair_r = radii[pairs[:, 0]] + radii[pairs[:, 1]]
    Hj = np.tile(np.eye(4), (2, 1, 1))
    Hj[0, 1, 3] = y0
    kept = [(np.full((1, 2), -math.inf), np.zeros((2, 5)), Hj.copy()) for _ in range(2)]
    t = Table(2)
    t.kind[:], t.r[:] = 0, rad
    g = ShapeArenas(t, warm_rows=1)  # (t's arrays become views of its arenas: place_kernel fills them)
    a0, a1, c, R, centre = t.a0, t.a1, t.c, t.R, np.zeros((2, 3))
    left = differ = 0
    theta = 0.0
    while theta < math.pi:
        cs, sn = math.cos(theta), math.sin(theta)
        Hj[1, :3, :3] = [[cs, -sn, 0.0], [sn, cs, 0.0], [0.0, 0.0, 1.0]]
        place_kernel(Hj, joint, kind, l_a0, l_a1, np.zeros((2, 3)), np.tile(np.eye(3), (2, 1, 1)), np.zeros((2, 3)),
                     a0, a1, c, R, centre)
        got = []
        for forget, (slack, moved, last_H) in zip((False, True), kept, strict=True):
            if forget:
                slack[:, 0] = -math.inf
            body_travel(Hj, joint, centre, radii, last_H, moved, slack)
            d, P, Q, N = np.empty(1), np.empty((1, 3)), np.empty((1, 3)), np.empty((1, 3))
            n = self_pass(t.kind, a0, a1, t.r, g.F, g.I, g.L, centre, pairs, pair_r, d_i, 0.03, d, P, Q, N,
                          np.ones(1, bool), np.empty(1, np.int64), np.empty(1, np.int64), np.empty(1), 0, g.ow, g.ws,
                          g.wi, np.zeros((2, 2, 3)), radii, moved, slack, np.full(1, -1, np.int64), np.empty(1), 0.0)
            got.append((n, [float(x) for x in d[:n] if x < d_i]))
        left += got[1][0] - got[0][0]
        differ += got[0][1] != got[1][1]
        theta += dtheta
    return left, differ


def test_a_capsule_spun_about_its_centre_is_not_left_out_once_its_end_comes_within_the_influence_distance() -> None:
    """A rotation moves a body's points while its bounding sphere's centre stays: the travel's
    rotation term alone keeps a pair in. A capsule spun about its centre towards a sphere, at three
    distances and three step sizes (the coherent pass leaves the pair out for most steps): its
    candidates within d_i are, at every step, those of a pass that forgets its slack. Caught: the
    rotation term halved (‖ΔR‖₂ is ‖ΔR‖_F/√2 for a rotation, and a point at ρ moves ~‖ΔR‖₂ ρ)."""
    left = 0
    for y0 in (0.40, 0.43, 0.46):
        for dtheta in (0.004, 0.01, 0.03):
            out, differ = _spun_capsule(y0, dtheta)
            assert differ == 0, (y0, dtheta)
            left += out
    assert left > 1000


def test_the_travel_sum_keeps_its_rounding_however_many_steps_it_adds() -> None:
    """``body_travel`` adds each step compensated (Kahan): 100,000 steps of 1e-7 m onto 0.5 m,
    whose plain sum drifts by ~5e-12 m (every addition rounds the same way), end within 1e-15 m of
    the exact sum; and past ``TRAVEL_RESTART`` every body's travel starts again from 0 and every
    pair's slack is forgotten."""
    from wmm_qp.limits._pair_passes import TRAVEL_RESTART, body_travel

    step, n = 1e-7, 100_000
    plain = 0.5
    for _ in range(n):
        plain += step
    exact = math.fsum([0.5] + [step] * n)
    assert abs(plain - exact) > 1e-12  # the case rounds, one way
    Hj, joint, radii = np.tile(np.eye(4), (1, 1, 1)), np.zeros(1, np.int64), np.ones(1)
    last_H, slack = Hj.copy(), np.zeros((3, 2))
    moved = np.array([[0.0, 0.0, 0.0, 0.5, 0.0]])
    at = (np.zeros((1, 3)), np.array([[step, 0.0, 0.0]]))
    for k in range(n):
        body_travel(Hj, joint, at[(k + 1) % 2], radii, last_H, moved, slack)
    assert abs(moved[0, 3] - exact) <= 1e-15 and (slack[:, 0] == 0.0).all()
    body_travel(Hj, joint, np.array([[step + TRAVEL_RESTART, 0.0, 0.0]]), radii, last_H, moved, slack)
    assert moved[0, 3] == 0.0 and (slack[:, 0] == -math.inf).all()
