"""Table I for one circle radius, every controller, and the comparison figure.

Runs exactly what ``wmm-qp experiment circle --radius R --controller C [--wheel-units rim]
--json --plots DIR`` runs, for C = traditional (J⁺ in rad/s and in rim speeds), paper and qp
(default configs, slip on, seed of ``configs/sim.toml``), writes each run's JSON
(``circle[_r<cm>]_<tag>.json``, the CLI's object) to ``--json-dir``, the per-run figures and
``circle_compare[_r<cm>].png`` to ``--plots``, and prints Table I in Markdown with the ratios
qp / traditional next to the paper's.

    python -m wmm_qp_tools.experiments.circle_table --radius 0.5 \\
        --json-dir benchmarks/results/experiments --plots docs/img

``--jobs 2`` runs two configurations at a time (separate processes; the figures are the same).
``--from-json DIR`` prints the table of the JSON files already in DIR (no run).
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from wmm_qp_tools.experiments.circle import DEFAULT_DURATION, RADIUS, circle_metrics, plot_tag, run_circle
from wmm_qp_tools.experiments.setup import make_setup
from wmm_qp_tools.experiments.trace import Trace

RUNS = (("traditional", "rad"), ("traditional", "rim"), ("paper", "rad"), ("qp", "rad"))
# Table I of the paper: (proposed, traditional); RMS ratios 65.12 %, 45.77 %, 6.94 %
PAPER = {
    "vx": (2.8e-2, 1.68e-2, 3.91e-2, 2.58e-2),  # max, RMS proposed; max, RMS traditional [m/s]
    "vy": (1.72e-2, 0.65e-2, 2.38e-2, 1.42e-2),
    "wz": (0.0917, 0.035, 0.882, 0.504),  # [rad/s]
    "ee_x": (2.71e-2, 7.25e-2),  # max EE error [m] proposed, traditional
    "ee_y": (1.88e-2, 2.71e-2),
}


def run_one(controller: str, wheel_units: str, radius: float, duration: float) -> tuple[dict[str, Any], Trace]:
    """One run, the CLI's JSON object and the trace."""
    s = make_setup(controller, wheel_units=wheel_units)
    tr = run_circle(s, duration, progress=False, radius=radius)
    result: dict[str, Any] = {"experiment": "circle", "robot": s.robot.name, "task": s.ctl_cfg.task.kind,
                              "controller": controller}  # fmt: skip
    if controller == "qp":
        result["solver"] = None
    if controller == "traditional":
        result["wheel_units"] = wheel_units
    result["radius"] = radius
    result |= {"duration": float(tr.t[-1] + s.ctl_cfg.dt), **circle_metrics(tr)}
    result["controller_reasons"] = dict(tr.reasons)
    tr.sim = None  # not picklable across processes, not needed
    return result, tr


def label(controller: str, wheel_units: str) -> str:
    return f"{controller} ({wheel_units})" if controller == "traditional" else controller


def table(results: dict[str, dict[str, Any]]) -> str:
    """Table I in Markdown: the paper's columns, ours, and qp / traditional ratios."""
    names = list(results)
    hdr = "| metric | paper proposed | paper traditional | " + " | ".join(f"ours {n}" for n in names) + " |"
    lines = [hdr, "|" + "---|" * (3 + len(names))]

    def cell(r: dict[str, Any], key: str) -> str:
        bv = r["base_velocity"]
        if key in ("vx", "vy"):
            return f"{bv[key]['max'] * 100:.3g} / {bv[key]['rms'] * 100:.3g}"
        if key == "wz":
            return f"{bv[key]['max']:.3g} / {bv[key]['rms']:.3g}"
        if key == "ee":
            return f"{r['ee_error_max']['x'] * 100:.3g} / {r['ee_error_max']['y'] * 100:.3g}"
        if key == "window":
            w = r["base_motion_window"]
            return "never" if w is None else f"{w[0]:.2f}–{w[1]:.2f}"
        if key == "ebi":
            e = r["base_error_integral"]
            return f"{e['x']:.3g} / {e['y']:.3g}"
        v = {k: n for k, n in r["violations"].items() if n}
        return "0" if not v else ", ".join(f"{n} {k}" for k, n in v.items())

    p = PAPER
    rows = [
        ("v_xb max / RMS [cm/s]", "vx", f"{p['vx'][0] * 100:.3g} / {p['vx'][1] * 100:.3g}",
         f"{p['vx'][2] * 100:.3g} / {p['vx'][3] * 100:.3g}"),
        ("v_yb max / RMS [cm/s]", "vy", f"{p['vy'][0] * 100:.3g} / {p['vy'][1] * 100:.3g}",
         f"{p['vy'][2] * 100:.3g} / {p['vy'][3] * 100:.3g}"),
        ("θ̇_b max / RMS [rad/s]", "wz", f"{p['wz'][0]} / {p['wz'][1]}", f"{p['wz'][2]} / {p['wz'][3]}"),
        ("EE error max x / y [cm]", "ee", "2.71 / 1.88", "7.25 / 2.71"),
        ("base motion window [s]", "window", "7.15–20.35", "always"),
        ("∫‖e_b‖ dt x / y [m·s]", "ebi", "0.0053 / 0.0049", "0.0379 / 0.0109"),
        ("referee violations", "viol", "–", "–"),
    ]  # fmt: skip
    for title, key, pp, pt in rows:
        lines.append(f"| {title} | {pp} | {pt} | " + " | ".join(cell(results[n], key) for n in names) + " |")
    out = "\n".join(lines)
    if "qp" in results:
        out += (
            "\n\n| qp / traditional | paper | "
            + " | ".join(f"ours, vs {n}" for n in names if n.startswith("traditional"))
            + " |\n|---|---|"
            + "---|" * sum(n.startswith("traditional") for n in names)
        )
        q = results["qp"]
        for key, title, paper_ratio in (
            ("vx", "RMS v_xb", p["vx"][1] / p["vx"][3]),
            ("vy", "RMS v_yb", p["vy"][1] / p["vy"][3]),
            ("wz", "RMS θ̇_b", p["wz"][1] / p["wz"][3]),
        ):
            cells = [
                _pct(q["base_velocity"][key]["rms"], results[n]["base_velocity"][key]["rms"])
                for n in names
                if n.startswith("traditional")
            ]
            out += f"\n| {title} | {paper_ratio * 100:.1f} % | " + " | ".join(cells) + " |"
        for ax, title, pr in (("x", "max EE error x", 2.71 / 7.25), ("y", "max EE error y", 1.88 / 2.71)):
            trad = [n for n in names if n.startswith("traditional")]
            cells = [_pct(q["ee_error_max"][ax], results[n]["ee_error_max"][ax]) for n in trad]
            out += f"\n| {title} | {pr * 100:.1f} % | " + " | ".join(cells) + " |"
    return out


def _pct(a: float, b: float) -> str:
    return f"{100 * a / b:.1f} %" if b > 0 else "–"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m wmm_qp_tools.experiments.circle_table")
    ap.add_argument("--radius", type=float, default=RADIUS)
    ap.add_argument("--duration", type=float, default=DEFAULT_DURATION)
    ap.add_argument("--json-dir", type=Path, default=None)
    ap.add_argument("--plots", type=Path, default=None)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--from-json", type=Path, default=None, help="only print the table of the JSON in this folder")
    a = ap.parse_args(argv)
    if a.plots is not None:  # before the runs, not after: a missing matplotlib must not cost them
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            print("circle_table: --plots needs matplotlib: pip install 'wmm-qp[plots]'", file=sys.stderr)
            return 2
    if a.from_json is not None:
        print(table({label(c, w): json.loads((a.from_json / f"circle_{plot_tag(c, a.radius, w)}.json").read_text())
                     for c, w in RUNS}))  # fmt: skip
        return 0
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        futures = {label(c, w): pool.submit(run_one, c, w, a.radius, a.duration) for c, w in RUNS}
        done = {n: f.result() for n, f in futures.items()}
    results = {n: r for n, (r, _) in done.items()}
    if a.json_dir is not None:
        a.json_dir.mkdir(parents=True, exist_ok=True)
        for (c, w), n in zip(RUNS, results, strict=True):
            path = a.json_dir / f"circle_{plot_tag(c, a.radius, w)}.json"
            path.write_text(json.dumps(results[n]) + "\n")
    if a.plots is not None:
        from wmm_qp_tools.experiments.plots import plot_circle, plot_circle_comparison

        a.plots.mkdir(parents=True, exist_ok=True)
        for (c, w), n in zip(RUNS, results, strict=True):
            plot_circle(done[n][1], a.plots, plot_tag(c, a.radius, w))
        plot_circle_comparison({n: tr for n, (_, tr) in done.items()}, a.plots, plot_tag("all", a.radius))
    print(table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
