"""``wmm-qp replay FILE.mcap``: re-run the controller on a recording and compare its commands.

The recording's own controller config by default (0 differing commands: the same code reproduces
every command bit for bit); ``--controller-config F`` replays another one at the recording's rate,
to try a fix on a recorded incident (docs/recording.md "Replay"). A truncated or damaged file: one
line on stderr saying where reading stopped, and the readable part replayed.

Exit status: 0 every command the same, 1 some differ or the file is damaged, 2 a usage error or
nothing replayable.
"""

from __future__ import annotations

import argparse
import sys

import msgspec

HELP = "re-run the controller on a recording (serve --record) and report the first command that differs"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = ("exit status: 0 every command the same, 1 some differ or the file is damaged (one line on stderr, "
                     "the readable part replayed), 2 bad input or nothing replayable")
    parser.add_argument("file", metavar="FILE.mcap", help="a recording of wmm-qp serve --record (its rotated "
                                                         "files FILE.001.mcap, … follow)")
    parser.add_argument("--controller-config", metavar="TOML",
                        help="replay this controller config instead of the recorded one (at the recording's rate)")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object: ticks, differing, first_difference {tick, max_abs_delta}, …")


def run(args: argparse.Namespace) -> int:
    from wmm_qp_service.recording import require
    from wmm_qp_service.recording.replay import replay

    require()

    def progress(n: int) -> None:
        print(f"wmm-qp replay: read {n} ticks …", file=sys.stderr, flush=True)

    rep = replay(args.file, args.controller_config, progress)
    if rep.error is not None:
        print(f"wmm-qp replay: error: {rep.error}; replaying the {rep.ticks_read} ticks read before it",
              file=sys.stderr, flush=True)
    if args.json:
        print(msgspec.json.encode(rep).decode())
    else:
        first = rep.first_difference
        where = (f"; the first at tick {first['tick']:.0f} (max |Δ| {first['max_abs_delta']:.3g}), "
                 f"max |Δ| {rep.max_abs_delta:.3g} overall" if first is not None else "")
        build = f", proxsuite build {rep.proxsuite_build}" if rep.proxsuite_build else ""
        print(f"wmm-qp replay: {rep.ticks} commands replayed ({rep.ticks_read} ticks read, {rep.config} config, "
              f"solver {rep.solver}{build}): {rep.differing} differ{where}")
        if rep.proxsuite_recorded and rep.proxsuite_build and rep.proxsuite_recorded != rep.proxsuite_build:
            print(f"wmm-qp replay: note: recorded with proxsuite's {rep.proxsuite_recorded}, replayed with its "
                  f"{rep.proxsuite_build}: their last bits may differ", file=sys.stderr)
    return 1 if rep.differing or rep.error is not None else 0
