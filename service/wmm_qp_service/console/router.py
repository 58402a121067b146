"""A Zenoh router for remote operators: ``python -m wmm_qp_service.console.router --zenoh-config FILE``.

A zenoh-python session in **router** mode (Zenoh's own routing, no relay of ours) on the robot's
computer: it listens on a TLS endpoint for consoles, checks their user names and passwords
(``usrpwd``) and applies its ACL — an ``operator`` may put ``setpoint`` and ``mode``, a ``viewer``
nothing — and reaches the robot stacks on their loopback endpoints as the stacks' ``operator``
(``configs/zenoh/router_tls.json5``, docs/console.md "Remote operation"). It prints one line when
it is up and runs until SIGINT or SIGTERM.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from wmm_qp import ConfigError


def router_config(path: Path, connect: list[str] | None = None) -> object:
    """The router's Zenoh config: the file, its credentials resolved and checked like every
    wmm-qp session's (:mod:`wmm_qp_service.acl`), mode forced to ``router``, ``connect`` added.

    Raises:
        ConfigError: not a Zenoh config, a missing or placeholder credential.
    """
    import zenoh

    from ..acl import apply_credentials, file_endpoints

    if not path.is_file():
        raise ConfigError(path, "", "no such file")
    try:
        zc = zenoh.Config.from_file(str(path))
    except Exception as e:  # zenoh.ZError
        raise ConfigError(path, "", f"not a valid Zenoh config: {str(e).splitlines()[0][:200]}") from None
    apply_credentials(zc, path)
    listen, file_connect = file_endpoints(zc, path)
    zc.insert_json5("mode", json.dumps("router"))
    zc.insert_json5("connect/endpoints", json.dumps(list(dict.fromkeys([*file_connect, *(connect or [])]))))
    for key in ("root_ca_certificate", "listen_certificate", "listen_private_key"):  # relative to the file
        v = json.loads(zc.get_json(f"transport/link/tls/{key}"))
        if isinstance(v, str) and not Path(v).is_absolute():
            zc.insert_json5(f"transport/link/tls/{key}", json.dumps(str((path.parent / v).resolve())))
    if not listen:
        raise ConfigError(path, "listen.endpoints", "a router for remote consoles listens somewhere (tls/ADDR:PORT)")
    return zc


def main(argv: list[str] | None = None) -> int:
    import zenoh

    from ..cli_common import stop_on_signals

    p = argparse.ArgumentParser(prog="python -m wmm_qp_service.console.router", description=__doc__.splitlines()[0])
    p.add_argument("--zenoh-config", type=Path, required=True, metavar="JSON5", help="the router's config")
    p.add_argument("--connect", action="append", default=[], metavar="EP",
                   help="a robot stack's endpoint to reach (its sim's and its daemon's; repeat)")
    args = p.parse_args(argv)
    try:
        zc = router_config(args.zenoh_config, args.connect)
    except ConfigError as e:
        print(f"router: error: {e}", file=sys.stderr)
        return 2
    zenoh.init_log_from_env_or("error")
    stop = stop_on_signals()
    try:
        session = zenoh.open(zc)  # type: ignore[arg-type]
    except Exception as e:  # zenoh.ZError: e.g. the listen address is not here
        print(f"router: error: {str(e).splitlines()[0][:300]}", file=sys.stderr)
        return 2
    with session:
        print(f"router: {session.zid()} up", flush=True)
        stop.wait()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
