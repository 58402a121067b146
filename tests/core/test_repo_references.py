"""Every test the repository names exists: README.md, docs/, benchmarks/ and the code's comments and
docstrings name tests by their path from the repository's root (``tests/<layer>/<file>.py``,
optionally ``::<test>``). A test file moved or renamed, or a test renamed, without its mentions
fails here, naming the file, the line and the path; so does a test file named without its folder."""

from __future__ import annotations

import io
import re
import tokenize
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ("README.md", "docs", "benchmarks", "examples", "tools", "wmm_qp", "sim", "service", "tests")
SUFFIXES = {".md", ".py"}
PATH = re.compile(r"(?<![\w/.-])(tests/[\w/]+\.py)(?:::(\w+))?")  # a path from the root, a test after ::
BARE = re.compile(r"(?<![\w/.-])(test_\w+\.py)")  # a test file's name without its folder
STATEMENT_START = {tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT, tokenize.ENCODING}


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


def _prose(path: Path) -> Iterator[tuple[int, str]]:
    """(line number, text) of what a reader reads: every line of a Markdown file; of a Python file
    its comments and docstrings (a string that is a statement of its own), not its data (a test's
    fake tree may name any path)."""
    text = path.read_text(encoding="utf-8")
    if path.suffix != ".py":
        yield from enumerate(text.splitlines(), 1)
        return
    before = tokenize.NEWLINE
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            yield tok.start[0], tok.string
        elif tok.type == tokenize.STRING and before in STATEMENT_START:
            for k, line in enumerate(tok.string.splitlines()):
                yield tok.start[0] + k, line
        if tok.type not in (tokenize.NL, tokenize.COMMENT):
            before = tok.type


def dangling(root: Path) -> list[str]:
    """``file:line: what`` for every test path under ``root``'s texts that names nothing."""
    bad = []
    for f in _texts(root):
        for n, line in _prose(f):
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
    tests = tmp_path / "tests" / "core"
    tests.mkdir(parents=True)
    (tests / "test_here.py").write_text("def test_one() -> None:\n    pass\n")
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text(
        "`tests/core/test_here.py::test_one` is fine, so is `tests/core/test_here.py`.\n"
        "`tests/test_here.py` moved; `tests/core/test_here.py::test_two` was renamed; `test_here.py` has no folder.\n")
    (tests / "test_other.py").write_text(
        '"""The docstring names tests/test_gone.py."""\n\n'
        'FAKE_TREE = {"tests/test_data.py": ""}  # a comment names tests/test_old.py\n')
    assert dangling(tmp_path) == [
        "docs/a.md:2: tests/test_here.py does not exist",
        "docs/a.md:2: tests/core/test_here.py has no test test_two",
        "docs/a.md:2: test_here.py without its folder (tests/<layer>/test_here.py)",
        "tests/core/test_other.py:1: tests/test_gone.py does not exist",
        "tests/core/test_other.py:3: tests/test_old.py does not exist",
    ]
