"""``wmm-qp acl init DIR``: per-role Zenoh credentials and ACL configs, with fresh secrets."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "write per-role Zenoh credentials with fresh secrets and their ACL configs (acl init DIR)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="acl_command", metavar="ACTION", required=True)
    p = sub.add_parser("init", help="write DIR/{sim,daemon,embedded,operator,viewer}/: each role's config and "
                                    "only its own credentials (random secrets, files 0600)",
                       description="Write DIR/{sim,daemon,embedded,operator,viewer}/: each role's Zenoh config "
                                   "(from configs/zenoh/acl_*.json5) and only its own credentials "
                                   "(random secrets, files 0600, folders 0700); embedded is the one "
                                   "process of wmm-qp sim --embedded, in place of the sim and the daemon. "
                                   "Never overwrites.")
    p.add_argument("dir", type=Path, metavar="DIR", help="a new (or empty) folder")
    p.add_argument("--templates", type=Path, metavar="FOLDER",
                   help="folder of the acl_*.json5 templates (default: configs/zenoh)")


def run(args: argparse.Namespace) -> int:
    from ..acl import ROLES, SIM_SOCKET, init

    written = init(args.dir, args.templates)
    root = Path(args.dir)
    print(f"wrote {root}/ (mode 0700): one folder per role; give each role its own folder only")
    for r in ROLES:
        files = ", ".join(p.name for p in written[r.folder])
        holds = f"  (checks {', '.join(r.admits)})" if r.admits else ""
        print(f"  {r.folder + '/':10} {files}{holds}")
    run = {r.folder: f"  {r.command} --zenoh-config {root / r.folder / r.config}" for r in ROLES}
    print(f"the sim and the daemon share {root / SIM_SOCKET} (the sim creates it); run:")
    print("\n".join(run.pop(f) for f in ("sim", "daemon")))
    print("or, in their place, the one embedded process:")
    print(run.pop("embedded"))
    print("and the clients:")
    print("\n".join(run.values()))
    return 0
