"""Collision safety: the dampers and the fence as hard rows, in closed loop with the
sim's independent collision referee — one test per constraint kind, each able to fail (the same
drive without the rows collides)."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from support.collision_robots import model, qp, start_x
from wmm_qp_sim import SimCommand, SimRobot, load_sim_config

import wmm_qp as w
from wmm_qp.config import default_config_dir
from wmm_qp.scene import Scene, load_scene
from wmm_qp.verify import CollisionJudge, verify_controller

D_S = w.load_controller_config().collision.safety_distance
REFEREE = load_sim_config().referee.collision_distance


def run(
    ctl: w.Controller, reference: w.Reference, steps: int, scene: Scene | None = None, moves: object = None
) -> tuple[SimRobot, Counter[str]]:
    """Controller and sim in process; the sim's referee checks every step. ``moves(k)`` may return
    a new obstacle list at tick k (given to both, as the daemon and the sim would get it over Zenoh)."""
    cfg = replace(load_sim_config(), firmware=False)
    sim = SimRobot(ctl.model, cfg, seed=1, scene=scene, collisions=True)
    sim.reset()
    if scene is not None and hasattr(ctl, "set_scene"):
        ctl.set_scene(scene)
    reasons: Counter[str] = Counter()
    for k in range(steps):
        if moves is not None and (obstacles := moves(k)) is not None:  # type: ignore[operator]
            sim.set_obstacles(obstacles)
            if hasattr(ctl, "set_obstacles"):
                ctl.set_obstacles(obstacles)
        cmd = ctl.step(sim.robot_state(), reference)
        reasons[cmd.reason.split(" at ")[0]] += 1
        sim.step(SimCommand(cmd.wheel_speeds, cmd.arm_rates, period=ctl.dt, seq=k), ctl.dt)
    return sim, reasons


def scene_file(tmp_path: Path, text: str, name: str = "scene.toml") -> Scene:
    """A scene file of ``text`` in tmp_path, loaded."""
    p = tmp_path / name
    p.write_text(text)
    return load_scene(p)


def assert_safe(sim: SimRobot) -> None:
    counts = sim.referee.counts
    assert sum(counts.values()) == 0, (counts, sim.referee.last_event)
    assert sim.collision is not None and sim.collision.min_distance >= REFEREE


def test_the_ee_commanded_into_the_floor_stops_at_the_floor_margin() -> None:
    ctl = qp()
    goal = start_x() + [0.2, 0.0, -1.2]  # 0.85 m below the floor
    sim, reasons = run(ctl, w.Reference("track", x_d=goal), 2500)
    assert_safe(sim)
    floor = model().config.base.floor_z
    margin = w.load_controller_config().collision.floor_margin
    x = model().ee_position(sim.base_odom, sim.q_arm)
    assert x[2] > floor + margin  # the flange (its capsule's radius above the floor margin)
    assert x[2] < floor + margin + 0.1  # and it did go down to it
    assert any("collision:" in r and ("floor" in r or "base_body" in r) for r in reasons), reasons


def test_the_same_drive_without_the_rows_collides() -> None:
    """The referee can fail: the floor drive of the test above with the rows switched off."""
    sim, _ = run(qp(enabled=False), w.Reference("track", x_d=start_x() + [0.2, 0.0, -1.2]), 2500)
    assert sim.referee.counts["collision"] > 0


def test_the_arm_folded_into_the_base_stops_at_the_safety_distance() -> None:
    ctl = qp()
    goal = np.array([0.05, 0.0, -0.15])  # inside the platform, just below the arm's base
    sim, reasons = run(ctl, w.Reference("track", x_d=goal), 3000)
    assert_safe(sim)
    assert sim.collision is not None and sim.collision.min_distance < D_S + 0.01  # it went there
    assert any("collision:" in r for r in reasons), reasons


WALL = """
[[obstacles]]
id = "wall"
kind = "box"
size = [0.1, 4.0, 1.5]
xyz = [1.5, 0.0, 0.2]
"""


def test_a_wall_in_the_base_path_stops_the_robot_at_the_safety_distance(tmp_path: Path) -> None:
    scene = scene_file(tmp_path, WALL)
    ctl = qp()
    goal = start_x() + [3.0, 0.0, 0.0]  # beyond the wall: the base must drive
    sim, reasons = run(ctl, w.Reference("track", x_d=goal), 5000, scene=scene)
    assert_safe(sim)
    assert sim.base_true[0] > 0.3  # it drove towards the wall
    assert sim.collision is not None and sim.collision.min_distance < D_S + 0.02  # up to the wall
    assert any("wall" in r for r in reasons), reasons
    unsafe, _ = run(qp(enabled=False), w.Reference("track", x_d=goal), 5000, scene=scene)
    assert unsafe.referee.counts["collision"] > 0  # without the rows it drives through


def test_an_obstacle_moved_into_the_arm_is_avoided() -> None:
    """A sphere moved towards the resting arm at 5 cm/s (live obstacles): the robot gives way,
    the referee sees no collision."""
    x0 = start_x()

    def moves(k: int) -> list[w.config.ShapeConfig] | None:
        if k % 10:
            return None
        centre = x0 + [0.0, 0.6 - 0.05 * k * 0.002, 0.0]  # from 0.6 m to the left, at 5 cm/s
        shape = w.config.ShapeConfig("ball", "", "sphere", np.array([0.08, 0.0, 0.0]), centre, np.zeros(3),
                                     velocity=np.array([0.0, -0.05, 0.0]))  # it says how it moves
        return [shape]

    ctl = qp()
    sim, reasons = run(ctl, w.Reference("track", x_d=x0), 6000, moves=moves)  # 12 s: the ball passes x0
    assert_safe(sim)
    assert np.linalg.norm(model().ee_position(sim.base_odom, sim.q_arm) - x0) > 0.05  # it gave way
    assert any("ball" in r for r in reasons), reasons


FENCE = """
[fence]
base = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]
ee_lower = [-1.5, -1.5, -0.3]
ee_upper = [1.5, 1.5, 1.2]
"""


def test_a_setpoint_20_m_away_ends_at_the_fence(tmp_path: Path) -> None:
    scene = scene_file(tmp_path, FENCE)
    ctl = qp()
    sim, _ = run(ctl, w.Reference("track", x_d=start_x() + [20.0, 0.0, 0.0]), 5000, scene=scene)
    assert_safe(sim)
    assert scene.fence.contains_base(sim.base_true)
    assert sim.base_true[0] > 0.3  # the base drove, the arm stretched
    x = model().ee_position(sim.base_odom, sim.q_arm)
    assert 1.5 - 1e-3 < x[0] <= 1.5 + 1e-6  # the EE went to the fence's EE box, and not beyond
    wide = scene_file(tmp_path, FENCE.replace("ee_upper = [1.5", "ee_upper = [9.0"))  # now the base polygon stops it
    sim, _ = run(qp(), w.Reference("track", x_d=start_x() + [20.0, 0.0, 0.0]), 5000, scene=wide)
    assert_safe(sim)
    assert 0.8 < sim.base_true[0] <= 1.0 + 1e-3


def test_the_rows_never_make_a_stage_infeasible_and_verify_sees_no_collision(tmp_path: Path) -> None:
    """Random states near self-collisions, obstacles and the fence: every command is refereed on the
    geometry at the predicted configuration; the baselines (no rows) collide in the same run."""
    scene = scene_file(tmp_path, WALL + FENCE.replace("-1.0", "-2.5").replace("1.0,", "2.5,").replace("1.0]", "2.5]"))
    rep = verify_controller(qp(), model(), 60, 1, scene=scene)
    assert rep.violations == 0, rep.examples
    assert rep.statuses.get("safe_stop", 0) == 0, rep.statuses
    assert sum(rep.by_case.get(c, 0) for c in ("near_self", "near_obstacle", "at_fence")) == 0
    base = verify_controller(w.make_controller("traditional", model(), w.load_controller_config()), model(), 60, 1,
                             scene=scene)
    assert base.by_kind["collision"] > 0


def test_the_judge_sees_a_command_into_an_obstacle() -> None:
    """The referee's own rule on a hand-made command: a base driving at full speed into a sphere
    1 cm away is a collision; braking is not."""
    m = model()
    x0 = start_x()
    ball = w.config.ShapeConfig("ball", "", "sphere", np.array([0.05, 0.0, 0.0]), x0 + [0.0, 0.0, 0.09 + D_S],
                                np.zeros(3))  # 4 cm above the flange capsule
    judge = CollisionJudge(m, Scene(obstacles=(ball,)), D_S, D_S)
    state = w.RobotState(np.zeros(3), m.config.arm.start)
    kin = m.kinematics(np.zeros(3), m.config.arm.start)
    up = np.linalg.pinv(kin.J) @ np.array([0.0, 0.0, 5.0])  # 5 m/s up, into the ball
    cmd = w.Command(wheel_speeds=up[:4], arm_rates=up[4:])
    assert judge.check(0.01, state, cmd) > 0
    assert judge.check(0.01, state, w.Command(wheel_speeds=np.zeros(4), arm_rates=np.zeros(7))) == 0


@pytest.mark.parametrize(("name", "solver"), [
    # every robot with the shipped solver, and each other solver on a robot: the full 3 × 3 matrix
    # cost a minute of the suite (OSQP on TIAGo alone 30 s) for no code path these do not run
    ("panda_diffdrive.toml", "proxsuite"), ("ur5_omni.toml", "proxsuite"), ("tiago.toml", "proxsuite"),
    ("tiago.toml", "daqp"), ("ur5_omni.toml", "osqp"), ("panda_diffdrive.toml", "daqp")])
def test_every_robot_with_urdf_geometry_stops_at_the_floor(name: str, solver: str) -> None:
    """With the shipped files and controller config. TIAGo's joints accelerate at 1 rad/s²
    (docs/robots.md): its file asks for a 0.3 m influence distance (with 0.15 m its hand stopped
    8 mm from its base: a collision for the referee).

    proxsuite warm-started from the previous solve used to stop at its iteration cap on some of
    TIAGo's barely feasible stages in one process and solve them in another, and in 1 of 6
    processes TIAGo's hand reached its base's hull (−1.6 mm); with its caps, and its workspace
    dropped after a failure (solvers/proxsuite_backend.py), it hands those stages to DAQP in
    every process."""
    m = model(name)
    cfg = w.load_controller_config().with_(collision={"enabled": True}, qp={"solver": solver})
    ctl = w.make_controller("qp", m, cfg)
    sim, _ = run(ctl, w.Reference("track", x_d=start_x(name) + [0.1, 0.0, -1.5]), 2500)
    assert_safe(sim)
    assert not math.isinf(sim.collision.min_distance)  # type: ignore[union-attr]
    assert m.ee_position(sim.base_odom, sim.q_arm)[2] < start_x(name)[2] - 0.1  # it went down


@pytest.mark.parametrize("name", ["gen3_mecanum.toml", "panda_diffdrive.toml", "ur5_omni.toml", "tiago.toml",
                                  "fr3.toml"])
def test_no_monitored_pair_starts_inside_the_safety_distance(name: str) -> None:
    """The rows keep the shapes they see (a cylinder: its capsule) d_s apart, so a monitored pair
    deep inside d_s at the start fights every task (it asks ξ (d_s − d)/(d_i − d_s) of separation
    speed), and one just inside it pays the rows' inside-d_s path every tick. The Panda's capsules
    of link1 and link3 were 4.4 cm inside each other (0.3 m/s asked) while the pairs were chosen on
    the cylinders; its link3/link5 capsules (2.98 cm) sat just inside d_s until its robot file
    excluded the pair (links that never come near: benchmarks/collision/pair_reach.py). TIAGo's
    arm_1/arm_3 hulls start 2.92 cm apart and stay monitored (docs/model.md "pairs": excluding
    them cost its circle's tracking)."""
    from wmm_qp.model.collision import distance, robot_geometry, row_shape

    m = model(name)
    geo = robot_geometry(m.config, m.arm)
    M = geo.placements(m.config.arm.start)
    b = geo.bodies
    gaps = [(distance(row_shape(b[i].shape), M[i], row_shape(b[j].shape), M[j])[0], b[i].name, b[j].name)
            for i, j in geo.self_pairs]
    assert gaps, "no self pair is monitored"
    floor = 0.029 if name == "tiago.toml" else D_S  # TIAGo's arm_1/arm_3: 2.92 cm, never under 2.85
    assert min(gaps)[0] > floor, min(gaps)
    if name == "panda_diffdrive.toml":  # excluded, with their reasons
        assert any({a, c} == {"panda_link1_0", "panda_link3_0"} and "random configurations" in why
                   for a, c, why in geo.excluded), geo.excluded
        assert any({a, c} == {"panda_link3_0", "panda_link5_0"} and "robot file" in why
                   for a, c, why in geo.excluded), geo.excluded


def test_the_damper_bound_is_the_braking_profile_where_the_linear_damper_asks_too_much() -> None:
    """ḋ ≥ max(−ξ (d − d_s)/(d_i − d_s), −√(2 β a_n (d − d_s))), a_n = Σ_j |C_j| A_j."""
    from wmm_qp.limits.dampers import _row_bounds

    row, accel = np.array([0.0, 0.2, -0.1]), np.array([1.0, 1.0, 2.0])  # a_n = 0.4
    zero, lo, hi = np.zeros(3), -np.ones(3), np.ones(3)

    def bound(d: float) -> float:
        return _row_bounds(row[None, :], 0, zero, zero, lo, hi, d, 0.03, 0.3, 0.5, 0.0, 0.0, accel, 0.25, 0.0)[0]

    assert bound(0.25) == pytest.approx(-math.sqrt(2 * 0.25 * 0.4 * 0.22))  # far: the profile (−0.21, not −0.41)
    assert bound(0.031) == pytest.approx(-0.5 * 0.001 / 0.27)  # near d_s: the linear damper
    assert bound(0.02) == pytest.approx(0.5 * 0.01 / 0.27)  # inside d_s: it pushes apart


def test_the_compiled_distances_agree_with_coal() -> None:
    """The hot path's own distances (capsule, sphere, box, plane) against coal's, on random poses."""
    import coal
    import pinocchio as pin

    from wmm_qp.limits import _distance as D  # noqa: N812

    rng = np.random.default_rng(5)
    req = coal.DistanceRequest()

    def pose() -> pin.SE3:
        return pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(scale=0.3, size=3))

    def coal_d(a: object, Ma: pin.SE3, b: object, Mb: pin.SE3) -> float:
        return coal.distance(a, coal.Transform3s(Ma.rotation, Ma.translation), b,
                             coal.Transform3s(Mb.rotation, Mb.translation), req, coal.DistanceResult())

    p, q, n = np.empty(3), np.empty(3), np.empty(3)
    for _ in range(300):
        r1, r2, l1 = rng.uniform(0.02, 0.1, 3)
        h = rng.uniform(0.05, 0.3, 3)
        Ma, Mb = pose(), pose()
        a0, a1 = Ma.act(np.array([0, 0, -l1 / 2])), Ma.act(np.array([0, 0, l1 / 2]))
        d = D.swept_swept(a0, a1, r1, Mb.translation, Mb.translation, r2, p, q, n)  # capsule-sphere
        assert d == pytest.approx(coal_d(coal.Capsule(r1, l1), Ma, coal.Sphere(r2), Mb), abs=1e-7)
        if d > 0:
            np.testing.assert_allclose(p - q, d * n, atol=1e-9)
        b0, b1 = Mb.act(np.array([0, 0, -l1])), Mb.act(np.array([0, 0, l1]))  # capsule-capsule, by index
        seg0, seg1, radius = np.array([a0, b0]), np.array([a1, b1]), np.array([r1, r2])
        at = [np.zeros(2), np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3))]
        D.swept_swept_at(seg0, seg1, radius, 0, 1, *at, 1)
        d = D.swept_swept(a0, a1, r1, b0, b1, r2, p, q, n)
        assert d == at[0][1] and all(np.array_equal(x, at[k + 1][1]) for k, x in enumerate((p, q, n)))
        assert d == pytest.approx(coal_d(coal.Capsule(r1, l1), Ma, coal.Capsule(r2, 2 * l1), Mb), abs=1e-7)
        d = D.swept_box(a0, a1, r1, Mb.translation, Mb.rotation, h / 2, p, q, n)  # capsule-box
        ref = coal_d(coal.Capsule(r1, l1), Ma, coal.Box(*h), Mb)
        if ref > 0:  # coal's penetration depths are GJK/EPA's; the separated case is exact
            assert d == pytest.approx(ref, abs=1e-6)
        else:
            assert d <= 1e-9
        floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), -0.2)
        d = D.swept_plane(a0, a1, r1, np.array([0.0, 0.0, -1.0]), 0.2, p, q, n)
        assert d == pytest.approx(coal_d(coal.Capsule(r1, l1), Ma, floor, pin.SE3.Identity()), abs=1e-7)
        d = D.box_plane(Mb.translation, Mb.rotation, h / 2, np.array([0.0, 0.0, -1.0]), 0.2, p, q, n)
        assert d == pytest.approx(coal_d(coal.Box(*h), Mb, floor, pin.SE3.Identity()), abs=1e-7)


def test_no_pair_inside_its_safety_distance_is_left_out_of_the_rows(tmp_path: Path) -> None:
    """More pairs inside d_s than MAX_ROWS (the Gen3 inside six boxes, 9 bodies each): every one
    gets its row. The cap had cut them by distance, and left out a Panda's finger 3.8 mm from its
    link5 while the whole robot was sampled inside a wall (verify: 120 collisions in 400 samples)."""
    from wmm_qp.limits.collision import MAX_ROWS

    boxes = "".join(f'[[obstacles]]\nid = "box{k}"\nkind = "box"\nsize = [{3 + k}, 3.0, 3.0]\nxyz = [0.0, 0.0, 0.0]\n\n'
                    for k in range(6))
    scene = scene_file(tmp_path, boxes)
    ctl = qp()
    ctl.set_scene(scene)  # type: ignore[attr-defined]
    m = model()
    ctl.step(w.RobotState(q_base=np.zeros(3), q_arm=m.config.arm.start), w.Reference("hold"))
    rows = ctl.last_collision_rows()
    inside = Counter(n for n in rows.names if n.split("/")[1].startswith("box"))
    assert len(inside) == 6 * len(ctl.collision.geo.bodies) > MAX_ROWS, (len(inside), rows.names)  # type: ignore[attr-defined]
    assert set(inside.values()) == {2}, inside  # its row, and its row on the bodies where braking ends


def test_a_capsule_whose_segment_is_inside_a_box_is_left_to_coal() -> None:
    """The kernel's depth is its deepest point's (−0.07 m here), but the capsule's penetration
    depth must push the whole segment out through one face (−0.11 m, coal's). Rows built on the
    kernel's let a Gen3 forearm deep in a wall go deeper (``wmm-qp verify --scene
    configs/scenes/cluttered.toml --samples 2000``: 5 collisions, with daqp and with osqp). Two
    capsules against a wall through the obstacles' pass the search runs (``solid_pass``, its tables
    packed as the search packs them): the one whose segment is inside is left to coal, the other is
    the kernel's, exact."""
    import coal
    import pinocchio as pin

    from wmm_qp.limits._pair_passes import solid_pass
    from wmm_qp.limits.pair_search import ShapeArenas, Table

    along_x = pin.rpy.rpyToMatrix(0.0, math.pi / 2, 0.0)
    capsule, wall = coal.Capsule(0.02, 0.08), coal.Box(0.1, 2.0, 2.0)  # segment x in ±0.04, wall x in ±0.05
    A, B = Table(2), Table(1)
    A.set(0, capsule, pin.SE3(along_x, np.zeros(3)), np.zeros(3))  # the segment inside the wall
    A.set(1, capsule, pin.SE3(along_x, np.array([0.1, 0.0, 0.0])), np.zeros(3))  # only its radius inside
    B.set(0, wall, pin.SE3.Identity(), np.zeros(3))
    a, b = ShapeArenas(A, warm_rows=2), ShapeArenas(B)
    d, P, Q, N = np.empty(2), np.empty((2, 3)), np.empty((2, 3)), np.empty((2, 3))
    ok, body, other = np.ones(2, dtype=np.bool_), np.empty(2, dtype=np.int64), np.empty(2, dtype=np.int64)
    n = solid_pass(a.F, a.I, a.L, A.centre, np.full(2, 0.06), b.F, b.I, b.L, B.kind, B.c, B.R, B.h, B.centre,
                   np.full(1, math.inf), np.ones((1, 2), dtype=np.bool_), np.zeros(1, dtype=np.int64), 0.15, 0.03,
                   d, P, Q, N, ok, body, other, np.empty(2), 0, a.ow, a.ws, a.wi)
    assert n == 2 and body.tolist() == [0, 1] and other.tolist() == [-2, -2]
    assert not ok[0] and ok[1]
    assert d[0] == pytest.approx(-0.07)  # what the kernel would have used
    req = coal.DistanceRequest()
    deep = coal.distance(capsule, coal.Transform3s(along_x, np.zeros(3)), wall, coal.Transform3s(), req,
                         coal.DistanceResult())
    assert deep == pytest.approx(-0.11, abs=1e-6)
    assert d[1] == pytest.approx(-0.01)  # exact: the segment outside


def test_the_collision_bench_times_both_controllers_with_rows_active() -> None:
    """``wmm-qp bench --only collisions`` on a short run: both controllers timed on the same
    states, and the scene really puts rows in the QP (no timing asserted)."""
    from wmm_qp_tools.bench import collision

    r = collision.run(w.load_robot_config(), w.load_controller_config(), 300, 60.0)
    assert r["with_rows"]["n"] == r["without_rows"]["n"] > 0
    assert r["rows"]["p50"] >= 4  # the arm's self pairs and the ball beside the circle
    assert r["monitored"]["obstacles"] == 5


_FIRST_OBSTACLE = """
import sys
import numpy as np
from numba.core.dispatcher import Dispatcher
import wmm_qp as w
from wmm_qp.scene import obstacles_from_tables

def signatures():
    return {f"{m}.{k}": len(f.signatures) for m, mod in list(sys.modules.items()) if m.startswith("wmm_qp")
            for k, f in vars(mod).items() if isinstance(f, Dispatcher)}

cfg = w.load_controller_config().with_(collision={"enabled": True})
robot = w.load_robot_config()
ctl = w.make_controller("qp", w.WmmModel(robot), cfg)
ctl.warm_up()
before = signatures()
x = ctl.model.ee_position(np.zeros(3), robot.arm.start)
ctl.set_obstacles(list(obstacles_from_tables("test", [
    {"id": "ball", "kind": "sphere", "radius": 0.05, "xyz": list(x + [0.0, 0.12, 0.0]), "velocity": [0.0, -0.05, 0.0]},
    {"id": "crate", "kind": "box", "size": [0.1, 0.1, 0.1], "xyz": list(x + [0.15, 0.0, 0.0])},
    {"id": "ceiling", "kind": "plane", "normal": [0.0, 0.0, 1.0], "offset": float(x[2] + 0.12)}])))
state = w.RobotState(q_base=np.zeros(3), q_arm=robot.arm.start)
for mode in w.Mode:
    ctl.step(state, w.Reference(mode))
new = {k: n - before.get(k, 0) for k, n in signatures().items() if n != before.get(k, 0)}
print("rows", ctl.last_rows.C.shape[0] if ctl.last_rows is not None else 0)
print("compiled after warm-up:", new)
"""


def test_the_first_obstacle_near_the_arm_compiles_nothing_in_the_loop(tmp_path: Path) -> None:
    """After warm_up, a tick among obstacles (moving sphere, box, plane) compiles no kernel: the
    daemon's first tick with a live obstacle once took 5.6 s compiling them, and the ball it was
    avoiding hit the arm meanwhile. In a fresh interpreter (this one has compiled them already);
    without the obstacle warm-up of QpController.warm_up the kernels' signatures grow here."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-P", "-c", _FIRST_OBSTACLE], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    rows = int(out.stdout.split("rows ")[1].split()[0])
    assert rows > 0, out.stdout  # the obstacles were near: their rows were built
    assert "compiled after warm-up: {}" in out.stdout, out.stdout


def test_a_braking_stage_no_solver_solves_commands_the_braking_command_not_a_safe_stop() -> None:
    """The UR5 sampled at its position limits with its forearm inside its base (verify's
    ``at_limit`` case, ~9 rows): the stage with its rows relaxed together has all of them within
    1e-9 m/s of their joint command v_r at a vertex of the box, and DAQP reads it as infeasible.
    v_r meets every row and bound by construction: it is commanded (``saturated``, the pair
    named), not a safe stop (431 of 8,000 commands in the 2,000-sample verify with daqp before
    the braking command was commanded so; docs/results.md)."""
    from wmm_qp.verify import check_command, sample_states

    m = model("ur5_omni.toml")
    cfg = w.load_controller_config().with_(collision={"enabled": True}, qp={"solver": "daqp"})
    ctl = w.make_controller("qp", m, cfg)
    scene = load_scene(default_config_dir() / "scenes" / "cluttered.toml")
    ctl.set_scene(scene)  # type: ignore[attr-defined]
    p = cfg.collision
    judge = CollisionJudge(m, scene, p.safety_distance, p.floor_margin)
    braking, statuses = 0, set()
    for s in sample_states(m, 12, 0, tuple(w.Mode), judge=judge, influence=p.influence_distance):
        cmd = ctl.step(s.state, s.reference)
        statuses.add(cmd.status.value)
        braking += "the rows' joint command" in cmd.reason
        assert sum(check_command(m.config, ctl.dt, s.state, cmd, model=m, collision=judge).values()) == 0, s.case
    assert braking >= 4, braking  # sample 11, at its limits, in every mode
    assert "safe_stop" not in statuses, statuses
    assert ctl.braking_stages == braking  # type: ignore[attr-defined]


def test_rows_relaxed_together_slow_an_approach_the_braking_command_keeps() -> None:
    """A pair the braking command v₀ = clip(0, lb, ub) keeps approaching (one joint slowing
    towards 0 moves it apart, the other closer: C v₀ = −0.3 m/s) but the box can approach it less
    (C v = −0.1 at a vertex). Relaxed together, the row admits no faster approach than that;
    relaxed to v₀ (before), TIAGo's hand kept approaching its torso column at the braking
    command's rate, into contact."""
    from wmm_qp.limits.rows import Rows

    lb, ub = np.array([0.4, -0.9]), np.array([0.6, -0.7])
    rows = Rows(C=np.array([[1.0, 1.0]]), l=np.array([-0.1]), damper=np.array([0.5]))
    v = rows.relax_together(lb, ub)
    assert (v >= lb).all() and (v <= ub).all()
    assert rows.C @ np.clip(0.0, lb, ub) == pytest.approx([-0.3])  # what v₀ does
    assert rows.C @ v == pytest.approx([-0.1], abs=1e-6) and rows.l_brake == pytest.approx([-0.1], abs=1e-6)
    assert (rows.C @ v >= rows.l_brake).all()


@pytest.mark.parametrize("seed", range(20))
def test_rows_relaxed_together_admit_their_command_and_come_nearer_than_braking(seed: int) -> None:
    """Random rows and boxes: the joint command is inside the box, every relaxed row admits it
    (the stage is feasible), no row is asked more than its damper nor admits less than relaxed
    to the braking command v₀ (what verify's collision rule asks of a pair inside d_s), and the
    approaches it leaves (rates below min(damper, 0)) are no larger, in squares, than v₀'s; with
    EE box rows that admit v₀, they admit the joint command too."""
    from wmm_qp.limits.rows import Rows

    rng = np.random.default_rng(seed)
    n, m = 10, int(rng.integers(1, 12))
    mid = rng.normal(size=n)
    lb, ub = mid - rng.uniform(0.0, 0.2, n), mid + rng.uniform(0.0, 0.2, n)
    C = rng.normal(size=(m, n)) * 0.3
    damper = rng.normal(size=m) * 0.3
    rows = Rows(C=C, l=damper.copy(), damper=damper)
    v0 = np.clip(0.0, lb, ub)
    Cb = rng.normal(size=(2, n))
    lbox, ubox = Cb @ v0 - rng.uniform(0, 0.05, 2), Cb @ v0 + rng.uniform(0, 0.05, 2)
    for box in (False, True):
        v = rows.relax_together(lb, ub, *((Cb, lbox, ubox) if box else ()))
        assert (v >= lb - 1e-15).all() and (v <= ub + 1e-15).all()
        assert (C @ v >= rows.l_brake).all() and (rows.l_brake <= damper).all()
        assert (rows.l_brake >= np.minimum(C @ v0, damper) - 2e-9).all()  # never below the braking relaxation
        if box:
            assert (Cb @ v >= lbox - 1e-12).all() and (Cb @ v <= ubox + 1e-12).all()
        else:
            short = lambda x: float(np.sum(np.maximum(0.0, np.minimum(damper, 0.0) - C @ x) ** 2))  # noqa: E731
            assert short(v) <= short(v0) + 1e-12


def test_the_row_merge_keeps_the_most_restrictive_of_parallel_rows_of_one_pair_of_links() -> None:
    """``_distinct_rows`` (compiled, by index) against the rule written with numpy: of rows of the
    same key (pair of links) whose directions agree within cos > PARALLEL, only the one with the
    largest l/|C| stays, in the order the rows came; rows of other keys, or apart in direction,
    all stay. Random rows with near-copies (parallel, scaled, anti-parallel) under shared keys."""
    from wmm_qp.limits.collision import PARALLEL, _distinct_rows

    def reference(C: np.ndarray, l: np.ndarray, keys: np.ndarray) -> list[int]:
        keep: list[int] = []
        for k in range(C.shape[0]):
            for i, j in enumerate(keep):
                nj, nk = np.linalg.norm(C[j]) + 1e-300, np.linalg.norm(C[k]) + 1e-300
                if keys[j] == keys[k] and float(C[j] @ C[k]) > PARALLEL * nj * nk:
                    if l[k] / nk > l[j] / nj:
                        keep[i] = k
                    break
            else:
                keep.append(k)
        return keep

    rng = np.random.default_rng(7)
    merged = 0
    for _ in range(200):
        base = rng.normal(size=(6, 9))
        C = np.vstack([base, base[rng.integers(0, 6, 10)] * rng.choice([0.5, 2.0, -1.0], size=(10, 1))
                       + 1e-9 * rng.normal(size=(10, 9))])
        l = rng.normal(size=16)
        keys = rng.integers(0, 3, 16)
        got = _distinct_rows(C, l, keys).tolist()
        assert got == reference(C, l, keys)
        merged += 16 - len(got)
    assert merged > 200  # the parallel copies did merge
