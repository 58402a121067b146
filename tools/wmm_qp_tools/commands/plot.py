"""``wmm-qp plot FILE.mcap --out DIR``: a recording's figures (:mod:`wmm_qp_tools.recording_plots`)."""

from __future__ import annotations

import argparse
import sys

HELP = "plot a recording: joints against their limits, wheels, EE, DM, tick time, modes and faults"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE.mcap", help="a recording (wmm-qp serve --record or wmm-qp record)")
    parser.add_argument("--out", metavar="DIR", default="plots", help="where the PNGs go (default: ./plots)")


def run(args: argparse.Namespace) -> int:
    from wmm_qp_service.recording import RecordingError, RecordingUnavailable, require

    require()
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise RecordingUnavailable("matplotlib", "plots") from None
    from wmm_qp_tools.recording_plots import load, plot

    def progress(n: int) -> None:
        print(f"wmm-qp plot: read {n} messages …", file=sys.stderr, flush=True)

    s = load(args.file, progress)
    if s.error is not None and not s.raw:
        raise RecordingError(s.error)  # nothing readable: one line, exit 2
    if s.error is not None:
        print(f"wmm-qp plot: error: {s.error}; plotting what was read before it", file=sys.stderr, flush=True)
    files = plot(s, args.out)
    if not files:
        print(f"wmm-qp plot: error: {args.file}: nothing to plot", file=sys.stderr)
        return 2
    print(f"wmm-qp plot: {', '.join(str(f) for f in files)}")
    return 1 if s.error is not None else 0
