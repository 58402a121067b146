"""Reading a recording back: its metadata and its messages, as far as the file is readable.

A recording cut short (a host killed with its writer, a full disk, a copy that stopped) or
damaged (a chunk whose bytes changed) is read up to the first record that cannot be read: the
messages before it are returned and :attr:`RecordingReader.error` says, in one line, where and why
reading stopped. A recording rotated into several files (``--split-size``, ``--split-time``) is
read as one: the files that follow ``FILE.mcap`` (``FILE.001.mcap``, …) with the same
``recording_id``.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec

from . import RecordingError, require


def split_name(path: Path, k: int) -> Path:
    """The ``k``-th file of a rotated recording (``k`` = 0: ``path`` itself)."""
    return path if k == 0 else path.with_name(f"{path.stem}.{k:03d}{path.suffix}")


class RecordingReader:
    """The messages of one recording file, in file order.

    Args:
        path: an MCAP file.

    Attributes:
        meta: the ``wmm_qp`` metadata ({} until read, or when the file has none).
        end: the ``wmm_qp_end`` metadata (None: the file ends without it, cut short).
        error: why reading stopped before the file's end, one line (None: read to its end).
        messages_read: messages read so far.
    """

    def __init__(self, path: str | Path) -> None:
        require()
        self.path = Path(path)
        if not self.path.is_file():
            raise RecordingError(f"{self.path}: no such file")
        self.meta: dict[str, str] = {}
        self.end: dict[str, str] | None = None
        self.error: str | None = None
        self.messages_read = 0

    def messages(self, topics: set[str] | None = None) -> Iterator[tuple[str, int, bytes]]:
        """(topic, log time [ns], payload) of each message on ``topics`` (None: every topic)."""
        from mcap.records import Channel, DataEnd, Footer, Message, Metadata
        from mcap.stream_reader import StreamReader

        channels: dict[int, str] = {}
        done = False
        with open(self.path, "rb") as f:
            try:
                for rec in StreamReader(f, validate_crcs=True).records:
                    if isinstance(rec, Message):
                        topic = channels.get(rec.channel_id, "")
                        self.messages_read += 1
                        if topics is None or topic in topics:
                            yield topic, rec.log_time, rec.data
                    elif isinstance(rec, Channel):
                        channels[rec.id] = rec.topic
                    elif isinstance(rec, Metadata):
                        if rec.name == "wmm_qp":
                            self.meta = dict(rec.metadata)
                        elif rec.name == "wmm_qp_end":
                            self.end = dict(rec.metadata)
                    elif isinstance(rec, (DataEnd, Footer)):
                        done = True
            except Exception as e:
                what = str(e).splitlines()[0] if str(e) else ""
                self.error = (f"{self.path}: unreadable after {self.messages_read} messages at byte {f.tell()} "
                              f"of {self.path.stat().st_size} ({type(e).__name__}{': ' + what if what else ''})")
                return
        if not done:
            self.error = f"{self.path}: cut short after {self.messages_read} messages (no end of data)"


def chain(path: str | Path) -> list[Path]:
    """``path`` and the rotated files that follow it (the same recording)."""
    path = Path(path)
    files, k = [path], 1
    while split_name(path, k).is_file():
        files.append(split_name(path, k))
        k += 1
    return files


def read_json(data: bytes) -> Any:
    """A JSON channel's payload."""
    return msgspec.json.decode(data)
