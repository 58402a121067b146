"""How near two links of a URDF come anywhere inside the joint limits: the smallest distance between
their collision meshes' convex hulls (which contain the meshes: the meshes are at least as far
apart) over seeded random configurations, then over the same number with each joint in turn at
each of its limits (a folded elbow is where links meet). The evidence behind a robot file's
``[collision] exclude`` of a pair its primitive shapes bring inside d_s but its links never near.

    python benchmarks/collision/pair_reach.py \\
        package://example-robot-data/robots/panda_description/urdf/panda.urdf panda_link3 panda_link5 \\
        [--samples 20000] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from wmm_qp.config import ConfigError
from wmm_qp.model.collision import convex_hull
from wmm_qp.urdf import package_dirs, resolve_urdf


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("urdf", help="a URDF path or package:// URL (its <collision> meshes or primitives)")
    ap.add_argument("link_a")
    ap.add_argument("link_b")
    ap.add_argument("--samples", type=int, default=20000, help="random configurations (default 20000)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    try:
        urdf = resolve_urdf(Path("<command line>"), a.urdf, "urdf")
    except ConfigError as e:  # one line, never a traceback
        print(f"pair_reach: {e}", file=sys.stderr)
        return 2
    model = pin.buildModelFromUrdf(str(urdf))
    geom = pin.buildGeomFromUrdf(model, str(urdf), pin.COLLISION, package_dirs=package_dirs(urdf))

    def on(link: str) -> list[int]:
        return [i for i, g in enumerate(geom.geometryObjects) if model.frames[g.parentFrame].name == link]

    ia, ib = on(a.link_a), on(a.link_b)
    if not ia or not ib:
        missing = a.link_a if not ia else a.link_b
        print(f"pair_reach: {urdf} has no collision element on link {missing!r}", file=sys.stderr)
        return 2
    shapes = {}
    for i in ia + ib:
        g = geom.geometryObjects[i].geometry
        shapes[i] = convex_hull(g) if isinstance(g, coal.BVHModelBase) else g
    data, gdata = model.createData(), pin.GeometryData(geom)
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    lo, hi = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    lo[~np.isfinite(lo)], hi[~np.isfinite(hi)] = -np.pi, np.pi
    rng = np.random.default_rng(a.seed)

    def nearest(q: np.ndarray) -> float:
        pin.updateGeometryPlacements(model, data, geom, gdata, q)
        d = np.inf
        for i in ia:
            for j in ib:
                res.clear()
                Ti = coal.Transform3s(gdata.oMg[i].rotation, gdata.oMg[i].translation)
                Tj = coal.Transform3s(gdata.oMg[j].rotation, gdata.oMg[j].translation)
                d = min(d, coal.distance(shapes[i], Ti, shapes[j], Tj, req, res))
        return float(d)

    best, where = np.inf, ""
    for k in range(a.samples):
        d = nearest(lo + (hi - lo) * rng.random(model.nq))
        if d < best:
            best, where = d, "random"
        if k % 5000 == 4999:
            print(f"  random: {k + 1}/{a.samples}, nearest {best:.4f} m", file=sys.stderr, flush=True)
    per = max(1, a.samples // (2 * model.nq))
    for v in range(model.nq):
        for bound in (lo[v], hi[v]):
            for _ in range(per):
                q = lo + (hi - lo) * rng.random(model.nq)
                q[v] = bound
                d = nearest(q)
                if d < best:
                    best, where = d, f"q[{v}] at {bound:+.4f}"
        print(f"  joint {v + 1}/{model.nq} at its limits, nearest {best:.4f} m", file=sys.stderr, flush=True)
    print(f"{a.link_a}/{a.link_b}: nearest {best:.4f} m (hulls of their collision elements; {a.samples} random "
          f"configurations and {2 * per * model.nq} with one joint at a limit; the nearest: {where})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
