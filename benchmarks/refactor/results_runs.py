"""The deterministic runs of docs/results.md that :mod:`same_results` repeats in two trees.

Each :class:`Run` is one command of docs/results.md as written there, minus the outputs that are
not its JSON (``--plots``, ``--frames``, ``--log``, ``--json-dir``), with the repository's files
given as ``{tree}/...`` (each tree reads its own ``configs/``). Where a run differs from the
document's command otherwise, ``note`` says how and why. :data:`EXCLUDED` lists the runs of the
document that are not repeated, each with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass

ROBOTS = ("gen3_mecanum", "panda_diffdrive", "ur5_omni", "tiago")
"""The shipped robot files the document runs (``configs/robots/<name>.toml``; fr3 only in demos)."""

SOLVERS = ("proxsuite", "osqp", "daqp")
CONTROLLERS = ("traditional", "paper", "qp")
VERIFY_SAMPLES = 200
"""Samples of the verify runs whose document command says 2000 (see :func:`_verify_runs`)."""


@dataclass(frozen=True)
class Run:
    """One command, run the same way in both trees.

    Attributes:
        name: unique, for ``--only`` and the report.
        section: where docs/results.md shows it (e.g. ``"§1"``).
        argv: after the interpreter: ``["wmm-qp", ...]`` runs the CLI (the ``wmm-qp`` entry point
            of the tree's pyproject.toml), ``["-m", MODULE, ...]`` a module; ``{tree}`` stands for
            the tree's root.
        note: how it differs from the document's command, if it does ("" otherwise).
    """

    name: str
    section: str
    argv: tuple[str, ...]
    note: str = ""

    def command(self) -> str:
        """The command as a reader would type it in the tree's root."""
        head = ("python",) if self.argv[0] == "-m" else ()
        return " ".join(a.replace("{tree}/", "") for a in (*head, *self.argv))


def _robot(name: str) -> tuple[str, str]:
    return ("--robot-config", f"{{tree}}/configs/robots/{name}.toml")


def _scene(name: str) -> tuple[str, str]:
    return ("--scene", f"{{tree}}/configs/scenes/{name}.toml")


def _experiment_runs() -> list[Run]:
    runs: list[Run] = []
    exp = ("wmm-qp", "experiment")
    # §1 Table I: the paper's 0.25 m circle per controller (+ the traditional one in rim speeds)
    for c in CONTROLLERS:
        runs.append(Run(f"circle_{c}", "§1", (*exp, "circle", "--controller", c, "--json")))
    runs.append(Run("circle_traditional_rim", "§1",
                    (*exp, "circle", "--controller", "traditional", "--wheel-units", "rim", "--json")))  # fmt: skip
    # §1.1 the large circles: what circle_table runs, one command each
    for r, tag in (("1.7", "r170"), ("1.0", "r100")):
        for c in CONTROLLERS:
            runs.append(Run(f"circle_{tag}_{c}", "§1.1", (*exp, "circle", "--radius", r, "--controller", c, "--json"),
                            "one of the runs of experiments.circle_table --radius " + r))  # fmt: skip
        rim = ("--controller", "traditional", "--wheel-units", "rim")
        runs.append(Run(f"circle_{tag}_traditional_rim", "§1.1", (*exp, "circle", "--radius", r, *rim, "--json"),
                        "one of the runs of experiments.circle_table --radius " + r))  # fmt: skip
    # §2 DM along x and z per controller; the 80 s eq. (19) run
    for d in ("x", "z"):
        for c in CONTROLLERS:
            runs.append(Run(f"dm{d}_{c}", "§2", (*exp, "dm", "--controller", c, "--direction", d, "--json")))
    runs.append(Run("dmz80_qp", "§2", (*exp, "dm", "--controller", "qp", "--direction", "z", "--duration", "80",
                                       "--json")))  # fmt: skip
    # §3 the box push per controller
    for c in CONTROLLERS:
        runs.append(Run(f"push_{c}", "§3", (*exp, "push", "--controller", c, "--json")))
    # §5 every other shipped robot: circle (position and pose task), dm along x and z
    for rb in ROBOTS[1:]:
        runs.append(Run(f"circle_{rb}", "§5", (*exp, "circle", *_robot(rb), "--json")))
        runs.append(Run(f"circle_{rb}_pose", "§5", (*exp, "circle", *_robot(rb), "--task", "pose", "--json")))
        runs.append(Run(f"dmx_{rb}", "§5", (*exp, "dm", *_robot(rb), "--json")))
        runs.append(Run(f"dmz_{rb}", "§5", (*exp, "dm", *_robot(rb), "--direction", "z", "--json")))
    # §6 every shipped robot with the default scene's collision rows; the Gen3 with DAQP
    for rb in ROBOTS:
        for e in ("circle", "dm"):
            runs.append(Run(f"{e}_{rb}_scene", "§6", (*exp, e, *_robot(rb), *_scene("default"), "--json")))
    runs.append(Run("circle_qp_daqp", "§6", (*exp, "circle", "--solver", "daqp", "--json")))
    runs.append(Run("dmz_qp_daqp", "§6", (*exp, "dm", "--direction", "z", "--solver", "daqp", "--json")))
    # §7 on the MuJoCo plant
    phys = ("--physics", "mujoco")
    runs.append(Run("circle_mujoco", "§7.3", (*exp, "circle", *phys, "--json")))
    runs.append(Run("circle_r100_mujoco", "§7.3", (*exp, "circle", "--radius", "1.0", *phys, "--json")))
    runs.append(Run("dmx_mujoco", "§7.3", (*exp, "dm", *phys, "--json")))
    runs.append(Run("dmz_mujoco", "§7.3", (*exp, "dm", "--direction", "z", *phys, "--json")))
    return runs


def _offline_runs() -> list[Run]:
    """The arm-only reach (§1.1) and the best reachable DM (§2): ``python -m`` modules."""
    reach = ("-m", "wmm_qp_tools.experiments.arm_reach")
    runs = [Run(f"arm_reach_r{r.replace('.', '')}", "§1.1", (*reach, "--radius", r, "--json"))
            for r in ("0.2", "0.25", "0.3", "0.325", "0.6", "0.753", "0.764")]  # fmt: skip
    runs.append(Run("arm_reach_bisection", "§1.1", (*reach, "--lo", "0.6", "--hi", "0.775", "--resolution", "0.02",
                                                    "--no-check-ends", "--json")))  # fmt: skip
    runs.append(Run("arm_reach_kinematic_bound", "§1.1", (*reach, "--kinematic-bound", "--json")))
    opt = ("-m", "wmm_qp_tools.experiments.dm_optimum")
    runs.append(Run("dm_optimum_x", "§2", (*opt, "--direction", "x", "--starts", "100", "--json")))
    runs.append(Run("dm_optimum_z", "§2", (*opt, "--direction", "z", "--z", "0.48279", "--starts", "100", "--json")))
    return runs


def _verify_runs() -> list[Run]:
    """``wmm-qp verify`` (§5, §6). §6's 200-sample runs as written; the 2000-sample matrices of §5
    with :data:`VERIFY_SAMPLES` samples: the same seed, the same draw of cases and modes, the same
    code paths, at a tenth of the time (24 + 14 runs of up to 137 s each in the document)."""
    runs: list[Run] = []
    v = ("wmm-qp", "verify")
    n = str(VERIFY_SAMPLES)
    less = f"--samples {n} instead of the document's 2000 (time)"
    for rb in ROBOTS:
        runs.append(Run(f"verify_{rb}", "§6", (*v, *_robot(rb), "--samples", "200", "--json")))
    for rb in ROBOTS:
        for s in SOLVERS:
            for t in ("position", "pose"):
                if (s, t) == ("proxsuite", "position"):
                    continue  # the config's solver and task: verify_<robot> above is that command
                argv = (*v, *_robot(rb), "--solver", s, "--task", t, "--samples", n, "--json")
                runs.append(Run(f"verify_{rb}_{s}_{t}", "§5", argv, less))
    for rb in ROBOTS:
        for s in SOLVERS:
            argv = (*v, *_robot(rb), *_scene("cluttered"), "--solver", s, "--samples", n, "--json")
            runs.append(Run(f"verify_{rb}_cluttered_{s}", "§5", argv, less))
    for c in ("paper", "traditional"):
        runs.append(Run(f"verify_gen3_mecanum_cluttered_{c}", "§5",
                        (*v, *_robot("gen3_mecanum"), *_scene("cluttered"), "--controller", c, "--samples", n,
                         "--json"), less))  # fmt: skip
    return runs


RUNS: tuple[Run, ...] = tuple(_experiment_runs() + _offline_runs() + _verify_runs())

EXCLUDED: tuple[tuple[str, str], ...] = (
    (
        "wmm-qp experiment circle|dm|push --realtime ... (§1, §2, §4)",
        "realtime: the daemon and the sim over Zenoh in real time; the figures depend on the machine's timing "
        "and load, run to run",
    ),
    (
        "wmm-qp demo ... (§6, §7.4), wmm-qp soak ... (§7.4)",
        "realtime: processes over Zenoh, deadline misses and faults depend on the machine's load",
    ),
    (
        "wmm-qp experiment push --physics mujoco --json (§7.1)",
        "not deterministic to 1e-9: two runs of the same code (two worktrees of 11f4f79) gave "
        "without_dm.max_abs_torque[2] = 30.32377551174574 and 30.323775469845394 N·m (4.2e-8, 1.4e-9 relative; "
        "the other 50 numbers equal); docs/results.md §7 saw 3e-8 N·m between runs",
    ),
    (
        "wmm-qp experiment push --physics mujoco --max-mass [--robot-config ...] (§7.2)",
        "a bisection on the mass, 14 pushes per robot (its JSON's trials), each as nondeterministic as the push",
    ),
    ("python -m wmm_qp_tools.experiments.latency_check 0|1 (§4)", "prints text, no JSON"),
    (
        "python -m wmm_qp_tools.experiments.circle_table --radius R ... (§1.1)",
        "runs exactly the circle_r170_* and circle_r100_* commands (included) and prints a Markdown table",
    ),
    ("--plots DIR, --frames DIR, --log FILE.csv, --json-dir DIR", "PNG and CSV outputs, not the JSON: left off"),
)
"""Runs of docs/results.md not repeated → why."""
