"""Nothing in the repository points outside it: ``python tools/check_refs.py``.

A reader has the repository and nothing else: no issue tracker, no notes kept beside it, no
machine it was written on. So no tracked text file may hold

- a tracker's issue number: the word issue or issues followed by a number, with or without a
  space, ``#``, ``-`` or ``_`` between them (so a file or folder named after one counts too);
  say what the work was instead, and give a commit hash where a point in history is meant;
- the name of a house-notes file that does not ship: the upper-case ``DESIGN`` or ``STYLE``
  followed by ``.md`` (``docs/design.md`` is the repository's own);
- a path into the machine's shared folders or work folders (a ``shared`` or ``work`` directory
  right under the root), e.g. a virtual environment's interpreter there; write the repository's
  own ``.venv/bin/python`` or a path relative to the repository.

Raw data that a tool wrote (``*.json`` and ``*.log`` under ``benchmarks/``) keeps the absolute
paths of the run it records: the work-folder rule does not apply to it, every other rule does.

The files are those ``git ls-files`` lists (without git: every file under the root but hidden
folders, caches and build output); a binary file (a NUL byte, or not UTF-8) is skipped. Each
finding is one line ``path:line: text (what)``; the exit code is 0 when there is none, 1 when
there is one, 2 for bad usage.

Usage:
    python tools/check_refs.py [--root DIR] [--exclude PATH ...]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath


@dataclass(frozen=True)
class Rule:
    """One kind of reference that points outside the repository.

    Attributes:
        what: what a match is, as the message names it.
        pattern: the text it matches.
        in_raw_data: whether it applies to raw data a tool wrote (:func:`is_raw_data`).
    """

    what: str
    pattern: re.Pattern[str]
    in_raw_data: bool = True


RULES: tuple[Rule, ...] = (
    Rule("an issue number", re.compile(r"(?<![a-z])issues?[ _#-]?#?\d+", re.IGNORECASE)),
    Rule("a house-notes file that does not ship", re.compile(r"\b(?:DESIGN|STYLE)\.md\b")),
    Rule("a shared folder outside the repository", re.compile(r"/(?:shared)/")),
    Rule("a work folder outside the repository", re.compile(r"/(?:work)/"), in_raw_data=False),
)
"""Every rule, checked on every line."""
SKIP_DIRS = {"__pycache__", "build", "dist", "node_modules"}
"""Folders the walk without git leaves out (besides hidden ones and ``*.egg-info``)."""
EXCERPT = 60
"""Characters of context on either side of a match in a long line."""


@dataclass(frozen=True)
class Finding:
    """One reference that points outside.

    Attributes:
        path: the file, relative to the root (``/``-separated).
        line: its line, from 1.
        text: the line (around the match when it is long).
        rule: the rule it breaks.
    """

    path: str
    line: int
    text: str
    rule: Rule

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.text} ({self.rule.what})"


def is_raw_data(path: str) -> bool:
    """Whether ``path`` (relative, ``/``-separated) is raw output a tool wrote: a JSON or log file
    under ``benchmarks/``."""
    p = PurePosixPath(path)
    return p.parts[:1] == ("benchmarks",) and p.suffix in (".json", ".log")


def tracked_files(root: Path) -> list[str]:
    """The files to read, relative to ``root``: git's tracked files, or a walk without git."""
    try:
        r = subprocess.run(["git", "-C", str(root), "ls-files", "-z"], capture_output=True, timeout=60,
                           check=False)
    except OSError:
        r = None
    if r is not None and r.returncode == 0:
        return sorted(p for p in r.stdout.decode("utf-8", "surrogateescape").split("\0") if p)
    out = []
    for path in root.rglob("*"):
        rel = path.relative_to(root)
        if any(part.startswith(".") or part in SKIP_DIRS or part.endswith(".egg-info") for part in rel.parts[:-1]):
            continue
        if path.is_file() and not rel.name.startswith("."):
            out.append(rel.as_posix())
    return sorted(out)


def excerpt(line: str, start: int, end: int) -> str:
    """The line, or the part of it around ``line[start:end]`` when it is long."""
    if len(line) <= 2 * EXCERPT + 40:
        return line.strip()
    a, b = max(0, start - EXCERPT), min(len(line), end + EXCERPT)
    return ("…" if a > 0 else "") + line[a:b] + ("…" if b < len(line) else "")


def findings_in(path: str, text: str) -> Iterator[Finding]:
    """Every reference that points outside in one file's text (``path`` decides the raw-data rule)."""
    rules = [r for r in RULES if r.in_raw_data or not is_raw_data(path)]
    for n, line in enumerate(text.splitlines(), start=1):
        for rule in rules:
            m = rule.pattern.search(line)
            if m:
                yield Finding(path, n, excerpt(line, m.start(), m.end()), rule)


def read_text(path: Path) -> str | None:
    """The file's text, or None for a binary file (a NUL byte, or not UTF-8) or one that is gone."""
    try:
        data = path.read_bytes()
    except (FileNotFoundError, IsADirectoryError):
        return None
    if b"\0" in data:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


def excluded(path: str, exclude: list[str]) -> bool:
    """Whether ``path`` is one of ``exclude`` or lies under one of them."""
    return any(path == e or path.startswith(e + "/") for e in exclude)


def check(root: Path, exclude: list[str] | None = None) -> tuple[list[Finding], int]:
    """Check every tracked text file under ``root`` but those under ``exclude`` (relative paths).

    Returns:
        the findings, in file and line order, and the number of text files read.
    """
    ex = [e.strip("/") for e in exclude or []]
    out: list[Finding] = []
    files = 0
    for rel in tracked_files(root):
        if excluded(rel, ex):
            continue
        text = read_text(root / rel)
        if text is None:
            continue
        files += 1
        out.extend(findings_in(rel, text))
    return out, files


def main(argv: list[str] | None = None) -> int:
    """Print each reference that points outside the repository; 0: none, 1: some, 2: bad usage."""
    p = argparse.ArgumentParser(prog="check_refs.py", description=__doc__.split("\n")[0])
    p.add_argument("--root", type=Path, default=Path(__file__).resolve().parent.parent,
                   help="the repository root (default: this script's repository)")
    p.add_argument("--exclude", action="append", default=[], metavar="PATH",
                   help="a file or folder relative to the root to leave out (repeatable; for a local look, "
                        "CI leaves nothing out)")
    args = p.parse_args(argv)
    if not args.root.is_dir():
        print(f"check_refs.py: error: --root {args.root}: not a directory (give the repository root)",
              file=sys.stderr)
        return 2
    found, files = check(args.root, args.exclude)
    for f in found:
        print(f)
    left_out = f", leaving out {', '.join(args.exclude)}" if args.exclude else ""
    if found:
        print(f"references: FAIL: {len(found)} line(s) point outside the repository ({files} files{left_out})")
        return 1
    print(f"references: OK: {files} files, nothing points outside the repository{left_out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
