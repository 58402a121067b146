"""Every test the repository names exists: README.md, docs/, benchmarks/ and the code's docstrings
name tests by their path from the repository's root (``tests/<layer>/<file>.py``, optionally
``::<test>``). A test file moved or renamed, or a test renamed, without its mentions fails here,
naming the file, the line and the path; so does a test file named without its folder."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ("README.md", "docs", "benchmarks", "examples", "tools", "wmm_qp", "sim", "service", "tests")
SUFFIXES = {".md", ".py"}
PATH = re.compile(r"(?<![\w/.-])(tests/[\w/]+\.py)(?:::(\w+))?")  # a path from the root, a test after ::
BARE = re.compile(r"(?<![\w/.-])(test_\w+\.py)")  # a test file's name without its folder


def _texts(root: Path) -> list[Path]:
    out: list[Path] = []
    for name in SOURCES:
        p = root / name
        if p.is_file():
            out.append(p)
        elif p.is_dir():
            out += sorted(f for f in p.rglob("*") if f.suffix in SUFFIXES and f.is_file()
                          and not any(part.startswith(".") or part == "__pycache__" for part in f.parts))
    return out


def dangling(root: Path) -> list[str]:
    """``file:line: what`` for every test path under ``root``'s texts that names nothing."""
    bad = []
    for f in _texts(root):
        for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            where = f"{f.relative_to(root)}:{n}"
            for m in PATH.finditer(line):
                path, test = m.group(1), m.group(2)
                target = root / path
                if not target.is_file():
                    bad.append(f"{where}: {path} does not exist")
                elif test and not re.search(rf"^\s*(?:async\s+)?def {test}\(", target.read_text(encoding="utf-8"),
                                            re.MULTILINE):
                    bad.append(f"{where}: {path} has no test {test}")
            for m in BARE.finditer(line):
                bad.append(f"{where}: {m.group(1)} without its folder (tests/<layer>/{m.group(1)})")
    return bad


def test_every_test_path_the_repository_names_exists() -> None:
    bad = dangling(ROOT)
    assert not bad, "\n".join(bad)


def test_a_moved_test_file_a_renamed_test_and_a_bare_name_are_reported(tmp_path: Path) -> None:
    name = "test_" + "here.py"  # spelled in two parts: this file's own text names no test file
    tests = tmp_path / "tests" / "core"
    tests.mkdir(parents=True)
    (tests / name).write_text("def test_one() -> None:\n    pass\n")
    (tmp_path / "docs").mkdir()
    old, here = f"tests/{name}", f"tests/core/{name}"
    (tmp_path / "docs" / "a.md").write_text(
        f"`{here}::test_one` is fine, so is `{here}`.\n"
        f"`{old}` moved; `{here}::test_two` was renamed; `{name}` has no folder.\n")
    assert dangling(tmp_path) == [
        f"docs/a.md:2: {old} does not exist",
        f"docs/a.md:2: {here} has no test test_two",
        f"docs/a.md:2: {name} without its folder (tests/<layer>/{name})",
    ]
