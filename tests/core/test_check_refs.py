"""The reference check (``tools/check_refs.py``): a file that names a tracker's issue, a house-notes
file that does not ship or a folder of the machine fails, naming the file and line; a clean tree
passes; the real repository passes.

The references below are written as f-strings (``f"issue {12}"``) so that this file itself holds
none: the check reads every tracked file, its own test included."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "check_refs.py"
GIT = shutil.which("git")


def check(root: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(TOOL), "--root", str(root), *extra], capture_output=True, text=True,
                          timeout=120, check=False)


def repo(tmp_path: Path, files: dict[str, str | bytes]) -> Path:
    """A git repository holding ``files`` (added, not committed: ``git ls-files`` lists them)."""
    if GIT is None:
        pytest.skip("git is not installed: the check lists a repository's files with git ls-files")
    root = tmp_path / "repo"
    root.mkdir(parents=True)
    subprocess.run([GIT, "init", "-q", str(root)], check=True, timeout=60)
    for name, body in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(body, bytes):
            path.write_bytes(body)
        else:
            path.write_text(body, encoding="utf-8")
    subprocess.run([GIT, "-C", str(root), "add", "-A"], check=True, timeout=60)
    return root


CLEAN = (
    "# A page\n\nThe wait (docs/design.md), the tissue 5 of a paper, an issue the controller solves,\n"
    "`.venv/bin/python benchmarks/reliability/fuzz.py`, commit `e8735ee`, ../sim.sock.\n"
)


@pytest.mark.parametrize(("line", "what"), [
    (f"Sections 1-5 (issue {12}).", "an issue number"),
    (f"# Benchmarks (Issues {6} and {12})", "an issue number"),
    (f"see issue #{3}", "an issue number"),
    (f"raw JSON in `benchmarks/results/issue{15}/`", "an issue number"),
    (f"`faults_1khz_issue{11}.json`", "an issue number"),
    (f"the house style ({'STYLE'}.md)", "a house-notes file that does not ship"),
    (f"as {'DESIGN'}.md says", "a house-notes file that does not ship"),
    (f"read /{'shared'}/notes.txt", "a shared folder outside the repository"),
    (f"/{'work'}/venv/bin/python benchmarks/reliability/faults.py", "a work folder outside the repository"),
])
def test_a_reference_outside_fails_naming_file_and_line(tmp_path: Path, line: str, what: str) -> None:
    root = repo(tmp_path, {"README.md": CLEAN, "docs/page.md": f"first line\n{line}\nlast line\n"})
    r = check(root)
    assert r.returncode == 1, r.stdout + r.stderr
    found = [s for s in r.stdout.splitlines() if not s.startswith("references:")]
    assert found == [f"docs/page.md:2: {line} ({what})"]
    assert r.stdout.splitlines()[-1].startswith("references: FAIL: 1 line(s)")


def test_a_clean_tree_passes(tmp_path: Path) -> None:
    root = repo(tmp_path, {"README.md": CLEAN, "pkg/mod.py": '"""Docs in docs/design.md."""\n'})
    r = check(root)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("references: OK: 2 files")


def test_raw_data_keeps_its_run_paths_but_not_issue_numbers(tmp_path: Path) -> None:
    run_path = f'{{"robot_file": "/{"work"}/main/configs/robots/gen3_mecanum.toml"}}\n'
    root = repo(tmp_path, {"benchmarks/results/e2e.json": run_path, "benchmarks/results/bench.log": run_path})
    assert check(root).returncode == 0
    (root / "benchmarks/results/e2e.json").write_text(f'{{"note": "issue{15}"}}\n', encoding="utf-8")
    r = check(root)
    assert r.returncode == 1 and "benchmarks/results/e2e.json:1:" in r.stdout
    # the same path in a script or a page is not raw data
    root2 = repo(tmp_path / "b", {"benchmarks/faults.py": run_path})
    assert check(root2).returncode == 1


def test_binary_files_and_untracked_files_are_not_read(tmp_path: Path) -> None:
    root = repo(tmp_path, {"README.md": CLEAN, "img/plot.png": b"\x89PNG\0" + f"issue {12}".encode()})
    (root / "notes.txt").write_text(f"issue {12}\n", encoding="utf-8")  # not tracked
    r = check(root)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("references: OK: 1 files")


def test_exclude_leaves_a_folder_out(tmp_path: Path) -> None:
    root = repo(tmp_path, {"README.md": CLEAN, "tests/test_x.py": f"# issue {12}\n", "testsuite.md": CLEAN})
    assert check(root).returncode == 1
    r = check(root, "--exclude", "tests")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "leaving out tests" in r.stdout


def test_without_git_every_file_but_hidden_folders_is_read(tmp_path: Path) -> None:
    root = tmp_path / "plain"
    (root / "docs").mkdir(parents=True)
    (root / ".venv").mkdir()
    (root / ".venv" / "x.py").write_text(f"# issue {12}\n", encoding="utf-8")
    (root / "docs" / "a.md").write_text(CLEAN, encoding="utf-8")
    assert check(root).returncode == 0
    (root / "docs" / "b.md").write_text(f"(issue {13})\n", encoding="utf-8")
    r = check(root)
    assert r.returncode == 1 and "docs/b.md:1:" in r.stdout


def test_a_root_that_is_not_a_folder_is_one_line_exit_2(tmp_path: Path) -> None:
    r = check(tmp_path / "missing")
    assert r.returncode == 2
    assert r.stdout == "" and r.stderr.count("\n") == 1 and "--root" in r.stderr


def test_the_real_repository_points_nowhere_outside() -> None:
    """Every tracked file, the tests included."""
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    r = check(ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
