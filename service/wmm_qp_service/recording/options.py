"""The recording's command-line flags (``--record FILE [--split-size MB] [--split-time S]``), shared
by ``wmm-qp serve`` and ``wmm-qp sim --embedded``."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from wmm_qp.exceptions import WmmQpError


def add_record_arguments(parser: argparse.ArgumentParser) -> None:
    """``--record FILE``, ``--split-size MB``, ``--split-time S``."""
    parser.add_argument("--record", metavar="FILE.mcap",
                        help="record every tick to this MCAP file (ROS 2 message types; docs/recording.md; "
                             "needs pip install 'wmm-qp[record]')")
    parser.add_argument("--split-size", type=float, metavar="MB",
                        help="with --record: start a new file (FILE.001.mcap, …) past this many MB")
    parser.add_argument("--split-time", type=float, metavar="S",
                        help="with --record: start a new file after this many seconds")


def record_options(args: argparse.Namespace, command: str) -> dict[str, Any]:
    """The host's recording keywords (``record``, ``split_size``, ``split_time``).

    Raises:
        RecordingUnavailable: ``--record`` without the ``record`` extra (one line, exit 2).
        WmmQpError: a split flag without ``--record``, or not positive (one line, exit 2).
    """
    from . import BASELINE, load_proxsuite, require

    record, size, period = getattr(args, "record", None), args.split_size, args.split_time
    if record is None:
        if size is not None or period is not None:
            raise WmmQpError("--split-size and --split-time need --record FILE")
        return {}
    for flag, v in (("--split-size", size), ("--split-time", period)):
        if v is not None and not v > 0:
            raise WmmQpError(f"{flag} must be > 0, got {v:g}")
    folder = Path(record).resolve().parent
    if not folder.is_dir() or not os.access(folder, os.W_OK):
        raise WmmQpError(f"--record {record}: {folder} is not a folder this process can write to")
    require()
    load_proxsuite(BASELINE)  # before anything loads proxsuite: a recording that replays bit for bit
    return {"record": record, "split_size": size, "split_time": period}


def report_recording(command: str, summary: dict[str, Any]) -> int:
    """Say where the recording went (stderr); 1 if the writer failed, else 0."""
    if "error" in summary:
        print(f"wmm-qp {command}: recording error: {summary['error']}", file=sys.stderr, flush=True)
        return 1
    files = summary.get("files", [])
    print(f"wmm-qp {command}: recorded {summary.get('ticks', 0)} ticks ({summary.get('dropped', 0)} lost) "
          f"to {', '.join(files)}", file=sys.stderr, flush=True)
    return 0
