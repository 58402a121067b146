"""Per-role credentials of the Zenoh access control (``configs/zenoh/acl_*.json5``).

Zenoh's user-password authentication (zenoh 1.x ``transport.auth.usrpwd``) is one-way: the side
that *accepts* a link checks the connecting side's user name and an HMAC of its password against
its dictionary file; the connecting side checks nothing and needs no dictionary. So each role
holds (:data:`ROLES`):

- its own secret if it connects anywhere (the daemon as ``controller``, ``operator``, ``viewer``),
  in ``<user>.secret``, which its config names as ``password: "file:<user>.secret"``;
- if it listens, a dictionary with the secrets of exactly the users that connect to it (the sim:
  controller, operator, viewer; the daemon: operator, viewer; the embedded process: operator,
  viewer). The checking side needs the password itself (zenoh has no hashed dictionary), so a
  listener is trusted with its clients'.

The sim connects nowhere, so the daemon sees no user name on its link to the sim: the daemon's
ACL names the sim by that link's protocol, a unix socket in DIR (mode 0700) that the daemon
dials — its only unix-socket link, since a config that trusts such links may not listen on one
(:func:`check_listen_endpoints`).

The embedded process (``wmm-qp sim --embedded``: the sim and the daemon's core in one process)
takes the place of both. It connects nowhere — its core writes the command in memory, there is
no sim to dial — so it has no secret and no unix socket: it listens for the operator and the
viewer as the daemon does, and its ACL admits no ``cmd``, ``state`` or ``sim/truth`` from
anyone. A folder is written for it with the others; run either the split pair or it.

Nothing in the repository or the installed package is a working secret: the configs are
templates naming credential files that only ``wmm-qp acl init DIR`` (:func:`init`) writes, with
random secrets. A missing credential file, a placeholder, or a file others may read is a
:class:`~wmm_qp.ConfigError` naming the file.
"""

from __future__ import annotations

import json
import os
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from wmm_qp import ConfigError, default_config_dir

FILE_PREFIX = "file:"
"""A ``password`` of this form names the file that holds the password (relative to the config)."""

UNIXSOCK = "unixsock-stream"
SIM_SOCKET = "sim.sock"
"""The sim's unix socket, in the folder ``acl init`` writes (its configs say ``../sim.sock``)."""

MIN_SECRET = 16
PLACEHOLDERS = ("change-me", "changeme", "replace", "placeholder")
SECRET_BYTES = 32  # secrets.token_urlsafe(32): 43 characters, 256 random bits
SUN_PATH_MAX = 107  # bytes of a unix socket path (Linux sun_path, without the NUL)


@dataclass(frozen=True)
class Role:
    """One process's credential files under ``DIR/<folder>/``.

    Attributes:
        folder: the role's folder (hand a role its folder only).
        config: its Zenoh config, copied from the template of the same name.
        user: the user name it presents when it connects (None: it connects nowhere).
        dictionary: its dictionary file (None: it listens nowhere).
        admits: the users in its dictionary: exactly those who connect to it.
        command: how it is started.
    """

    folder: str
    config: str
    user: str | None
    dictionary: str | None
    admits: tuple[str, ...]
    command: str

    @property
    def secret(self) -> str | None:
        """Its own secret's file name."""
        return f"{self.user}.secret" if self.user else None


ROLES: tuple[Role, ...] = (
    Role("sim", "acl_sim.json5", None, "sim_users.txt", ("controller", "operator", "viewer"), "wmm-qp sim"),
    Role("daemon", "acl_daemon.json5", "controller", "daemon_users.txt", ("operator", "viewer"), "wmm-qp serve"),
    Role("embedded", "acl_embedded.json5", None, "embedded_users.txt", ("operator", "viewer"),
         "wmm-qp sim --embedded"),
    Role("operator", "acl_operator.json5", "operator", None, (), "wmm-qp teleop"),
    Role("viewer", "acl_viewer.json5", "viewer", None, (), "wmm-qp status"),
)


def init(folder: str | Path, templates: str | Path | None = None) -> dict[str, list[Path]]:
    """Write one folder per role with its config and only its own credentials (``wmm-qp acl init``).

    Every secret is fresh (``secrets.token_urlsafe``); credential files are mode 0600, folders
    0700. Existing files are never overwritten.

    Args:
        folder: where to write (must not exist, or be empty).
        templates: the folder of the ``acl_*.json5`` templates (default: ``configs/zenoh``).

    Returns:
        role folder → the files written there.

    Raises:
        ConfigError: the folder is not empty, its path is too long for a unix socket, or a
            template is missing.
    """
    folder = Path(folder)
    src = Path(templates) if templates is not None else default_config_dir() / "zenoh"
    if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise ConfigError(folder, "", "exists and is not empty (acl init never overwrites credentials): "
                                      "choose a new folder")
    sock = Path(os.path.abspath(folder)) / SIM_SOCKET
    if len(os.fsencode(sock)) > SUN_PATH_MAX:
        raise ConfigError(folder, "", f"path too long for the sim's unix socket {sock.name} "
                                      f"({len(os.fsencode(sock))} > {SUN_PATH_MAX} bytes): choose a shorter one")
    texts = {}
    for r in ROLES:
        if not (src / r.config).is_file():
            raise ConfigError(src / r.config, "", "no such template")
        texts[r.config] = (src / r.config).read_text()
    secret = {r.user: secrets.token_urlsafe(SECRET_BYTES) for r in ROLES if r.user}
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    folder.chmod(0o700)
    written: dict[str, list[Path]] = {}
    for r in ROLES:
        d = folder / r.folder
        d.mkdir(mode=0o700)
        d.chmod(0o700)
        files = [_write(d / r.config, texts[r.config], 0o644)]
        if r.user is not None and r.secret is not None:
            files.append(_write(d / r.secret, secret[r.user] + "\n", 0o600))
        if r.dictionary is not None:
            files.append(_write(d / r.dictionary, "".join(f"{u}:{secret[u]}\n" for u in r.admits), 0o600))
        written[r.folder] = files
    return written


def _write(path: Path, text: str, mode: int) -> Path:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    with os.fdopen(fd, "w") as f:
        os.fchmod(f.fileno(), mode)  # exactly this mode, whatever the umask
        f.write(text)
    return path


def _get(zc: zenoh.Config, key: str) -> Any:
    return json.loads(zc.get_json(key))


def _relative(config: Path, name: str) -> Path:
    p = Path(name)
    return p if p.is_absolute() else Path(os.path.abspath(config.parent / p))


def check_secret(value: str, path: Path, key: str = "") -> None:
    """A usable secret: not empty, not a placeholder, at least :data:`MIN_SECRET` characters.

    Raises:
        ConfigError: naming ``path`` (and ``key``), never the value.
    """
    hint = "run `wmm-qp acl init DIR` and use the configs it writes"
    if not value:
        raise ConfigError(path, key, f"empty: no secret ({hint})")
    if any(p in value.lower() for p in PLACEHOLDERS):
        raise ConfigError(path, key, f"a placeholder, not a secret ({hint})")
    if len(value) < MIN_SECRET:
        raise ConfigError(path, key, f"too short to be a secret (< {MIN_SECRET} characters; {hint})")


def _credential_file(path: Path, config: Path) -> str:
    if not path.is_file():
        raise ConfigError(path, "", f"no such credential file (named by {config}; `wmm-qp acl init DIR` "
                                    "writes one per role, with the configs that name it)")
    mode = path.stat().st_mode & 0o777
    if os.name == "posix" and mode & 0o077:
        raise ConfigError(path, "", f"a credential file open to group or others (mode {mode:04o}): chmod 600 it")
    return path.read_text()


def read_secret(path: Path, config: Path) -> str:
    """The secret in a ``<user>.secret`` file (one line)."""
    value = _credential_file(path, config).strip()
    check_secret(value, path)
    return value


def check_dictionary(path: Path, config: Path) -> list[str]:
    """Check a usrpwd dictionary (``user:password`` lines); returns its user names."""
    users = []
    for n, line in enumerate(_credential_file(path, config).splitlines(), 1):
        if not line.strip():
            continue
        user, sep, pwd = line.partition(":")
        if not sep or not user.strip():
            raise ConfigError(path, f"line {n}", "not user:password")
        check_secret(pwd.strip(), path, f"line {n} ({user.strip()})")
        users.append(user.strip())
    return users


def apply_credentials(zc: zenoh.Config, config: Path) -> None:
    """Resolve and check the credentials a Zenoh config names, in place.

    ``password: "file:NAME"`` is replaced by the secret in NAME; a relative ``dictionary_file``
    is made relative to the config file; an inline password must not be a placeholder.

    Raises:
        ConfigError: a missing, unreadable-by-design or placeholder credential (names the file).
    """
    usrpwd = _get(zc, "transport/auth/usrpwd")
    if not isinstance(usrpwd, dict):
        return
    pwd = usrpwd.get("password")
    if isinstance(pwd, str):
        if pwd.startswith(FILE_PREFIX):
            secret = read_secret(_relative(config, pwd.removeprefix(FILE_PREFIX)), config)
            zc.insert_json5("transport/auth/usrpwd/password", json.dumps(secret))
        else:
            check_secret(pwd, config, "transport.auth.usrpwd.password")
    dic = usrpwd.get("dictionary_file")
    if isinstance(dic, str):
        path = _relative(config, dic)
        check_dictionary(path, config)
        zc.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(path)))


def file_endpoints(zc: zenoh.Config, config: Path) -> tuple[list[str], list[str]]:
    """The listen and connect endpoints a Zenoh config file lists (relative unix sockets made
    relative to the file)."""

    def endpoints(key: str) -> list[str]:
        v = _get(zc, key)
        if isinstance(v, dict):  # per-mode lists
            v = v.get("peer")
        return [_resolve_endpoint(e, config) for e in v or []]

    return endpoints("listen/endpoints"), endpoints("connect/endpoints")


def _resolve_endpoint(ep: str, config: Path) -> str:
    proto, _, addr = ep.partition("/")
    if proto != UNIXSOCK or Path(addr).is_absolute():
        return ep
    return f"{UNIXSOCK}/{_relative(config, addr)}"


def check_listen_endpoints(zc: zenoh.Config, config: Path, listen: list[str]) -> None:
    """Refuse to listen on a link protocol the ACL trusts without a user name.

    ``acl_daemon.json5`` names the sim by the protocol of the link the daemon dials to it (a unix
    socket): were the daemon to listen on one, any peer connecting there would be the sim.

    Raises:
        ConfigError: such a listen endpoint.
    """
    acl = _get(zc, "access_control")
    if not isinstance(acl, dict) or not acl.get("enabled"):
        return
    trusted = {p for s in acl.get("subjects") or []
               if not s.get("usernames") and not s.get("cert_common_names")
               for p in s.get("link_protocols") or []}
    for ep in listen:
        proto = ep.partition("/")[0]
        if proto in trusted:
            raise ConfigError(config, "listen.endpoints",
                              f"{ep}: its ACL takes every {proto} link for the sim, so this process "
                              f"may not listen on one")
