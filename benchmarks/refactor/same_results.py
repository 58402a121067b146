"""Prove that a change left docs/results.md's figures alone: its deterministic runs in two trees, JSON compared.

    python benchmarks/refactor/same_results.py --before DIR --after DIR [--only NAME ...] [--out F.json]
        [--jobs 2] [--recheck 2] [--timeout S] [--fail-fast] [--solver NAME] [--list]

Runs every command of :data:`results_runs.RUNS` (docs/results.md's in-process runs, ``--list``
prints them; ``--only`` takes names or shell patterns such as ``circle_*``) once in each tree and
compares the two JSON objects (:mod:`json_diff`: every number within 1e-9, absolute or relative;
strings, booleans and keys equal; only the timing keys of :data:`json_diff.SKIPPED_KEYS`
skipped — there are none today). The exit codes must agree too (``verify`` exits 1 on a
violation). The realtime runs and the others of :data:`results_runs.EXCLUDED` are not repeated,
and the report says why.

Each tree runs its own source with this interpreter's packages: ``PYTHONPATH`` is the tree's
package folders (``[tool.setuptools.packages.find] where`` of its pyproject.toml: ``.``, ``sim``,
``service``), checked before anything runs by importing ``wmm_qp``, ``wmm_qp_sim`` and
``wmm_qp_service`` from it; ``wmm-qp`` is the tree's own entry point (``[project.scripts]``). Each
command runs in a fresh temporary directory (no ``configs/`` there, so each tree reads its own),
without ``WMM_QP_CONFIG_DIR`` and with ``PYTHONHASHSEED=0`` (both trees alike). Paths of the tree
and of the temporary directory in the JSON's strings read ``<tree>`` and ``<cwd>``. ``--jobs 2``
(the default) runs a command in both trees at once, then the next one.

Run-to-run noise: some runs do not repeat to 1e-9 even in one tree. Their last bits depend on where
the process's memory lies: with address randomisation off (``setarch -R``) a tree repeats its runs
exactly, but the same code in another folder gives other bits, and with it on the qp circle's
``base_velocity.vx.max`` took 0.0039083655146607875 and 0.003908367681559331 m/s in two runs of
one tree (2.2e-9 apart). So each command whose JSON differs is run ``--recheck`` more times in the
before tree alone, and is "noisy", "partly noisy" or "not noisy" as those reruns differ from the
before tree's first run at all, some or none of the paths where the after tree differs; the FAIL
line counts them and names the first command that is not noisy (else partly, else noisy). Two
reruns can miss noise: "not noisy" is evidence, not proof. The verdict itself stays the 1e-9
comparison.

Progress: one line per command on stderr. Verdict: ``PASS n commands equal`` or ``FAIL ...``
naming the first command that differs, its first differing JSON path and both values, on stdout;
exit 0 (PASS), 1 (FAIL), 2 (bad arguments: one line). ``--out F.json``: every command's result
(equal or its differences, with the largest absolute and relative difference, the numbers
compared, both trees' times), the skipped keys and the excluded runs with why; rewritten after
every command (verdict ``RUNNING`` until the end), so that a run cut short leaves what it compared.
"""

from __future__ import annotations

import argparse
import dataclasses
import fnmatch
import json
import os
import subprocess
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from json_diff import SKIPPED_KEYS, TOL, Difference, count_numbers, differences, key_names, max_deviation
from results_runs import EXCLUDED, RUNS, Run

PACKAGES = ("wmm_qp", "wmm_qp_sim", "wmm_qp_service")
SHOWN_DIFFERENCES = 20  # per command in --out


class UsageError(Exception):
    """Bad arguments or a tree this tool cannot run: one line, exit 2."""


@dataclass(frozen=True)
class Tree:
    """A source tree of wmm-qp, as its pyproject.toml lays it out.

    Attributes:
        root: the tree's root (resolved).
        pythonpath: the folders that hold its packages.
        entry: ``module:function`` of its ``wmm-qp`` script.
    """

    root: Path
    pythonpath: tuple[Path, ...]
    entry: str

    @classmethod
    def load(cls, flag: str, path: Path) -> Tree:
        """Read ``path/pyproject.toml``; raises :class:`UsageError` naming ``flag`` if it is no wmm-qp tree."""
        root = path.resolve()
        project = root / "pyproject.toml"
        if not project.is_file():
            raise UsageError(f"{flag} {path}: not a source tree of wmm-qp (no pyproject.toml)")
        try:
            data = tomllib.loads(project.read_text())
            where = data["tool"]["setuptools"]["packages"]["find"]["where"]
            entry = data["project"]["scripts"]["wmm-qp"]
        except (tomllib.TOMLDecodeError, KeyError, TypeError) as e:
            raise UsageError(f"{flag} {path}: pyproject.toml has no [tool.setuptools.packages.find] where "
                             f"or [project.scripts] wmm-qp ({e})") from None  # fmt: skip
        return cls(root, tuple(root / w for w in where), str(entry))

    def env(self) -> dict[str, str]:
        """The environment of this tree's commands."""
        env = dict(os.environ)
        env.pop("WMM_QP_CONFIG_DIR", None)
        env["PYTHONPATH"] = os.pathsep.join(str(p) for p in self.pythonpath)
        env["PYTHONHASHSEED"] = "0"
        return env

    def argv(self, run: Run, python: str) -> list[str]:
        """The interpreter's argv for ``run`` in this tree."""
        args = [a.replace("{tree}", str(self.root)) for a in run.argv]
        if args[0] == "wmm-qp":
            module, func = self.entry.split(":")
            boot = f"import sys; sys.argv[0] = 'wmm-qp'; from {module} import {func}; raise SystemExit({func}())"
            return [python, "-c", boot, *args[1:]]
        if args[0] == "-m" and args[1].startswith("wmm_qp_tools.") and not any(
                (d / "wmm_qp_tools").is_dir() for d in self.pythonpath):
            # a tree from before the tools left the runtime: its experiments were wmm_qp_service's
            args[1] = "wmm_qp_service." + args[1].removeprefix("wmm_qp_tools.")
        return [python, *args]

    def check_imports(self, flag: str, python: str) -> None:
        """Import the packages in this tree's environment; raises :class:`UsageError` unless all are its own."""
        code = "import json, " + ", ".join(PACKAGES) + "; print(json.dumps([" + ", ".join(
            f"{p}.__file__" for p in PACKAGES) + "]))"  # fmt: skip
        with tempfile.TemporaryDirectory(prefix="same-results-") as cwd:
            p = subprocess.run([python, "-c", code], cwd=cwd, env=self.env(), capture_output=True, text=True)
        if p.returncode != 0:
            last = (p.stderr.strip().splitlines() or ["?"])[-1]
            raise UsageError(f"{flag} {self.root}: its packages do not import ({last})")
        for name, file in zip(PACKAGES, json.loads(p.stdout), strict=True):
            if not Path(file).resolve().is_relative_to(self.root):
                raise UsageError(f"{flag} {self.root}: {name} imports from {file}, outside the tree")


@dataclass
class Output:
    """One command's run in one tree."""

    rc: int
    doc: Any = None  # the parsed JSON (None: stdout was not JSON)
    error: str = ""  # why there is no JSON
    seconds: float = 0.0


def _normalise(x: Any, subs: list[tuple[str, str]]) -> Any:
    if isinstance(x, str):
        for old, new in subs:
            x = x.replace(old, new)
        return x
    if isinstance(x, dict):
        return {_normalise(k, subs): _normalise(v, subs) for k, v in x.items()}
    if isinstance(x, list):
        return [_normalise(v, subs) for v in x]
    return x


def run_in(tree: Tree, run: Run, python: str, timeout: float) -> Output:
    """Run ``run`` in ``tree`` (a fresh temporary working directory); its exit code and JSON."""
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="same-results-") as cwd:
        try:
            p = subprocess.run(tree.argv(run, python), cwd=cwd, env=tree.env(), capture_output=True, text=True,
                               timeout=timeout)  # fmt: skip
        except subprocess.TimeoutExpired:
            return Output(-1, error=f"timed out after {timeout:g} s", seconds=time.monotonic() - t0)
        out = Output(p.returncode, seconds=time.monotonic() - t0)
        try:
            doc = json.loads(p.stdout)
        except json.JSONDecodeError:
            last = (p.stderr.strip().splitlines() or ["(nothing on stderr)"])[-1]
            out.error = f"exit {p.returncode}, no JSON on stdout: {last}"
            return out
        subs = [(str(tree.root), "<tree>"), (cwd, "<cwd>"), (str(Path(cwd).resolve()), "<cwd>")]
        out.doc = _normalise(doc, subs)
    return out


@dataclass
class Verdict:
    """The comparison of one command."""

    run: Run
    before: Output
    after: Output
    diffs: list[Difference] = field(default_factory=list)
    numbers: int = 0
    reruns: list[Output] = field(default_factory=list)  # the before tree's command again (--recheck)

    @property
    def equal(self) -> bool:
        return not self.diffs and not self.before.error and not self.after.error

    def rerun_values(self) -> dict[str, list[Any]]:
        """Path → the values of the before tree's reruns where they differ from its first run."""
        values: dict[str, list[Any]] = {}
        for o in self.reruns:
            if o.doc is not None:
                for d in differences(self.before.doc, o.doc):
                    values.setdefault(d.path, []).append(d.after)
        return values

    def noisy_share(self) -> tuple[int, int]:
        """(how many of the differing paths also differ between runs of the before tree alone, how many differ)."""
        paths = {d.path for d in self.diffs}
        return len(paths & set(self.rerun_values())), len(paths)

    @property
    def noise(self) -> str:
        """What the reruns say: "unchecked" (none), "noisy" (the before tree differs from itself at every
        differing path), "partly noisy" (at some) or "not noisy" (at none: the change's doing)."""
        if not self.reruns or not self.diffs:
            return "unchecked"
        k, n = self.noisy_share()
        return "noisy" if k == n else "partly noisy" if k else "not noisy"

    def reason(self) -> str:
        """Why it is not equal (first cause), "" if it is."""
        for side, o in (("before", self.before), ("after", self.after)):
            if o.error:
                return f"{self.run.name}: the {side} tree's command failed: {o.error}"
        if not self.diffs:
            return ""
        more = f" (and {len(self.diffs) - 1} more)" if len(self.diffs) > 1 else ""
        line = f"{self.run.name}: {self.diffs[0]}{more}"
        if not self.reruns:
            return line
        k, n = self.noisy_share()
        if again := self.rerun_values().get(self.diffs[0].path):
            here = f"noisy here: a rerun of the before tree gave {again[0]!r}"
        else:
            here = f"the before tree gave this value again in {len(self.reruns)} reruns"
        return f"{line} [{here}; {self.noise}: the before tree differs from itself at {k} of {n} differing paths]"

    def report(self) -> dict[str, Any]:
        a, r = max_deviation(self.diffs)
        return {"name": self.run.name, "section": self.run.section, "command": self.run.command(),
                "note": self.run.note, "equal": self.equal, "reason": self.reason(), "numbers_compared": self.numbers,
                "differences": len(self.diffs), "max_abs_diff": a, "max_rel_diff": r,
                "first_differences": [{"path": d.path, "before": d.before, "after": d.after}
                                      for d in self.diffs[:SHOWN_DIFFERENCES]],
                "exit_code": {"before": self.before.rc, "after": self.after.rc},
                "recheck": {"reruns": len(self.reruns), "noise": self.noise,
                            "noisy_paths": self.noisy_share()[0],
                            "before_rerun_values": dict(list(self.rerun_values().items())[:SHOWN_DIFFERENCES])},
                "seconds": {"before": round(self.before.seconds, 1),
                            "after": round(self.after.seconds, 1)}}  # fmt: skip


def judge(run: Run, before: Output, after: Output) -> Verdict:
    """Compare one command's two outputs (exit codes, then the JSON)."""
    v = Verdict(run, before, after)
    if before.error or after.error:
        return v
    if before.rc != after.rc:
        v.diffs.append(Difference("<exit code>", before.rc, after.rc))
    v.diffs += differences(before.doc, after.doc)
    v.numbers = count_numbers(before.doc)
    return v


def select(patterns: list[str] | None) -> list[Run]:
    """The runs ``--only`` names (names or shell patterns), in the list's order; all without it."""
    if not patterns:
        return list(RUNS)
    for p in patterns:
        if not any(fnmatch.fnmatchcase(r.name, p) for r in RUNS):
            raise UsageError(f"--only {p}: no such run; --list prints the names (e.g. circle_qp, 'verify_*')")
    return [r for r in RUNS if any(fnmatch.fnmatchcase(r.name, p) for p in patterns)]


def compare_trees(before: Tree, after: Tree, runs: list[Run], jobs: int, timeout: float, fail_fast: bool,
                  recheck: int = 0, python: str = sys.executable,
                  progress: Callable[[list[Verdict]], None] | None = None) -> list[Verdict]:  # fmt: skip
    """Run each command in both trees (``jobs`` at a time, in list order) and judge it as both finish;
    then run each command whose JSON differs ``recheck`` times more in the before tree (is it noise?).
    ``progress`` is called with the verdicts so far after each command and each recheck."""
    verdicts: list[Verdict] = []
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        pending: list[tuple[Run, Future[Output], Future[Output]]] = [
            (r, pool.submit(run_in, before, r, python, timeout), pool.submit(run_in, after, r, python, timeout))
            for r in runs
        ]
        for k, (r, fb, fa) in enumerate(pending):
            v = judge(r, fb.result(), fa.result())
            verdicts.append(v)
            what = f"equal ({v.numbers} numbers)" if v.equal else "DIFFERS: " + v.reason()
            print(f"[{k + 1}/{len(runs)}] {r.name}: {what}; {v.before.seconds:.0f} s / {v.after.seconds:.0f} s",
                  file=sys.stderr, flush=True)  # fmt: skip
            if progress is not None:
                progress(verdicts)
            if fail_fast and not v.equal:
                for _, b, a in pending[k + 1 :]:
                    b.cancel()
                    a.cancel()
                break
        if recheck > 0:
            again = [(v, [pool.submit(run_in, before, v.run, python, timeout) for _ in range(recheck)])
                     for v in verdicts if v.diffs and not v.before.error and not v.after.error]  # fmt: skip
            for v, futures in again:
                v.reruns = [f.result() for f in futures]
                k, n = v.noisy_share()
                print(f"[recheck] {v.run.name}: {recheck} more runs in the before tree: {v.noise}, it differs from "
                      f"itself at {k} of the {n} differing paths", file=sys.stderr, flush=True)  # fmt: skip
                if progress is not None:
                    progress(verdicts)
    return verdicts


def verdict_line(verdicts: list[Verdict], total: int) -> str:
    """``PASS n commands equal`` or ``FAIL k of n commands differ; first: ...``."""
    bad = [v for v in verdicts if not v.equal]
    if not bad and len(verdicts) == total:
        return f"PASS {total} commands equal"
    if not bad:
        return f"FAIL only {len(verdicts)} of {total} commands ran"
    kinds = ("not noisy", "unchecked", "partly noisy", "noisy")  # the first command named: the first kind found
    by = {kind: [v for v in bad if v.noise == kind] for kind in kinds}
    if len(by["unchecked"]) == len(bad):
        return f"FAIL {len(bad)} of {total} commands differ; first: {bad[0].reason()}"
    counts = ", ".join(f"{len(by[kind])} {kind}" for kind in kinds if by[kind])
    kind = next(kind for kind in kinds if by[kind])
    return f"FAIL {len(bad)} of {total} commands differ ({counts}); first {kind}: {by[kind][0].reason()}"


def write_report(path: Path, trees: dict[str, Tree], runs: list[Run], verdicts: list[Verdict], line: str,
                 t0: float, load0: tuple[float, float, float]) -> None:  # fmt: skip
    """The ``--out`` report, replaced whole (written after every command, so a killed run leaves its part)."""
    report = {"verdict": line.split()[0], "verdict_line": line, "before": str(trees["--before"].root),
              "after": str(trees["--after"].root), "tolerance": TOL, "skipped_keys": SKIPPED_KEYS,
              "excluded": [{"command": c, "why": w} for c, w in EXCLUDED], "commands_selected": len(runs),
              "wall_s": round(time.monotonic() - t0, 1), "loadavg_start": [round(x, 2) for x in load0],
              "loadavg_now": [round(x, 2) for x in os.getloadavg()], "commands": [v.report() for v in verdicts],
              "key_names": sorted(set().union(*(key_names(o.doc) for v in verdicts
                                                for o in (v.before, v.after))))}  # fmt: skip
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(json.dumps(report, indent=1) + "\n")
    tmp.replace(path)


def on_solver(run: Run, solver: str) -> Run:
    """``run`` on ``solver``: its ``--solver`` replaced, or added to an experiment or verify command
    (the others, which take no solver, unchanged)."""
    argv = list(run.argv)
    if "--solver" in argv:
        argv[argv.index("--solver") + 1] = solver
    elif argv[:2] in (["wmm-qp", "experiment"], ["wmm-qp", "verify"]):
        argv += ["--solver", solver]
    else:
        return run
    return dataclasses.replace(run, name=f"{run.name}@{solver}", argv=tuple(argv))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="same_results.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", type=Path, help="the tree before the change (a git worktree)")
    ap.add_argument("--after", type=Path, help="the tree after it")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run only these (names or patterns; see --list)")
    ap.add_argument("--out", type=Path, default=None, metavar="F.json", help="write the full report here")
    ap.add_argument("--jobs", type=int, default=2, help="processes at a time (default 2: both trees at once)")
    ap.add_argument("--timeout", type=float, default=3600.0, help="[s] per command and tree (default 3600)")
    ap.add_argument("--fail-fast", action="store_true", help="stop at the first command that differs")
    ap.add_argument("--recheck", type=int, default=2, metavar="N",
                    help="run each command that differs N more times in the before tree, to tell run-to-run "
                         "noise from the change (default 2)")  # fmt: skip
    ap.add_argument("--solver", metavar="NAME", default=None,
                    help="run every experiment and verify command on this QP solver (e.g. daqp, which repeats "
                         "itself to the bit: the runs that are noisy on the shipped solver compared exactly)")
    ap.add_argument("--list", action="store_true", help="print the runs and the excluded ones, run nothing")
    args = ap.parse_args(argv)
    try:
        runs = select(args.only)
        if args.solver is not None:
            runs = [on_solver(r, args.solver) for r in runs]
        if args.list:
            for r in runs:
                print(f"{r.name:42s} {r.section:5s} {r.command()}" + (f"  [{r.note}]" if r.note else ""))
            for cmd, why in EXCLUDED:
                print(f"excluded: {cmd}: {why}")
            return 0
        if args.before is None or args.after is None:
            raise UsageError("--before DIR and --after DIR are required (two source trees of wmm-qp)")
        if args.jobs < 1:
            raise UsageError(f"--jobs {args.jobs}: must be at least 1")
        if args.recheck < 0:
            raise UsageError(f"--recheck {args.recheck}: must be 0 or more")
        if args.timeout <= 0:
            raise UsageError(f"--timeout {args.timeout:g}: must be positive")
        trees = {flag: Tree.load(flag, path) for flag, path in (("--before", args.before), ("--after", args.after))}
        for flag, tree in trees.items():
            tree.check_imports(flag, sys.executable)
    except UsageError as e:
        print(f"same_results.py: error: {e}", file=sys.stderr)
        return 2
    t0, load0 = time.monotonic(), os.getloadavg()
    print(f"{len(runs)} commands in {trees['--before'].root} and {trees['--after'].root}, {args.jobs} at a time",
          file=sys.stderr, flush=True)  # fmt: skip

    def save(verdicts: list[Verdict], line: str = "") -> None:
        if args.out is not None:
            line = line or f"RUNNING {len(verdicts)} of {len(runs)} commands compared"
            write_report(args.out, trees, runs, verdicts, line, t0, load0)

    verdicts = compare_trees(trees["--before"], trees["--after"], runs, args.jobs, args.timeout, args.fail_fast,
                             args.recheck, progress=save)  # fmt: skip
    line = verdict_line(verdicts, len(runs))
    save(verdicts, line)
    print(line, flush=True)
    return 0 if line.startswith("PASS") else 1


if __name__ == "__main__":
    raise SystemExit(main())
