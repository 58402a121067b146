"""Reading an arm out of a URDF: the path, the chain to the EE frame, the limits, the reduced model.

Run once at start-up (robot file loading, :class:`~wmm_qp.model.arm.ArmModel`): the per-tick
code only indexes what is built here. Every failure is a :class:`ConfigError` naming the robot
file and the key that caused it.

Paths: a ``urdf`` value is relative to the robot file, absolute, or ``package://NAME/REST``
(the convention the URDFs themselves use for meshes), resolved to ``<share>/NAME/REST`` in the
first ``share`` folder of this Python environment that holds ``NAME`` — ``sys.prefix/share``
and the ``cmeel.prefix/share`` where PyPI packages such as ``example-robot-data`` put theirs —
or ``pkg://MODULE/REST``, resolved to ``REST`` inside the installed Python package ``MODULE``
(a package that ships a robot description as package data, e.g. ``franky_sim/assets``); the
package is located, not imported.
"""

from __future__ import annotations

import contextlib
import importlib.util
import math
import os
import sys
import sysconfig
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from .exceptions import ConfigError

PACKAGE_HINTS = {"example-robot-data": "pip install 'wmm-qp[robots]' (or: pip install example-robot-data)",
                 "franky_sim": "pip install franky-sim"}
"""How to install the packages the shipped robot files name."""

# Pinocchio's one-DOF joint models: revolute (any axis), continuous (stored as cos, sin), prismatic.
_REVOLUTE = ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned")
_CONTINUOUS = ("JointModelRUBX", "JointModelRUBY", "JointModelRUBZ", "JointModelRevoluteUnboundedUnaligned")
_PRISMATIC = ("JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned")


def share_dirs() -> list[Path]:
    """The ``share`` folders of this environment where packages install robot descriptions."""
    out = [Path(sys.prefix) / "share"]
    purelib = Path(sysconfig.get_paths()["purelib"])
    out.append(purelib / "cmeel.prefix" / "share")
    out += [Path(p) / "cmeel.prefix" / "share" for p in sys.path if p and Path(p).name == "site-packages"]
    seen: list[Path] = []
    for d in out:
        if d not in seen:
            seen.append(d)
    return seen


def resolve_urdf(robot_file: Path, value: str, key: str = "arm.urdf") -> Path:
    """The URDF a robot file's ``urdf`` value names (see the module docstring).

    Raises:
        ConfigError: the file does not exist, or the package it names is not installed.
    """
    if value.startswith("pkg://"):
        module, _, rest = value[len("pkg://") :].partition("/")
        try:
            spec = importlib.util.find_spec(module) if module.isidentifier() else None
        except (ImportError, ValueError):
            spec = None
        if spec is None or not spec.submodule_search_locations:
            hint = PACKAGE_HINTS.get(module, f"install the Python package {module!r}")
            raise ConfigError(robot_file, key, f"needs the Python package {module!r}, which is not installed: {hint}")
        path = Path(next(iter(spec.submodule_search_locations))) / rest
        if not path.is_file():
            raise ConfigError(robot_file, key, f"the Python package {module!r} has no file {rest!r}")
        return path
    if value.startswith("package://"):
        package, _, rest = value[len("package://") :].partition("/")
        for share in share_dirs():
            if (share / package).is_dir():
                path = share / package / rest
                if not path.is_file():
                    raise ConfigError(robot_file, key, f"the package {package!r} has no file {rest!r}")
                return path
        hint = PACKAGE_HINTS.get(package, f"install the package that provides {package!r}")
        raise ConfigError(robot_file, key, f"needs the package {package!r}, which is not installed: {hint}")
    path = Path(value)
    path = (path if path.is_absolute() else robot_file.parent / path).resolve()
    if not path.is_file():
        raise ConfigError(robot_file, key, f"file not found: {path}")
    return path


def package_dirs(urdf: Path) -> list[str]:
    """Folders in which ``package://`` mesh paths of ``urdf`` resolve (for geometry loading)."""
    return [str(d) for d in share_dirs() if d.is_dir()] + [str(urdf.parent)]


@dataclass(frozen=True)
class UrdfChain:
    """The arm's chain in a URDF, with the URDF's limits of each chain joint.

    Attributes:
        joints: names of the actuated joints from the root to the EE frame, in order.
        types: "revolute", "continuous" or "prismatic", per joint.
        lower, upper: position limits (±inf for continuous joints).
        velocity, effort: the URDF's velocity and effort limits (0 where the URDF gives none).
        others: every other actuated joint of the URDF (to be locked).
    """

    joints: tuple[str, ...]
    types: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    others: tuple[str, ...]


def load_full_model(robot_file: Path, urdf: Path) -> pin.Model:
    """Pinocchio's model of the whole URDF (fixed base).

    Raises:
        ConfigError: Pinocchio cannot parse it.
    """
    import xml.etree.ElementTree as ET

    try:  # not XML at all: say so before urdfdom, which writes its own errors to the process's stderr
        ET.parse(urdf)
    except (ET.ParseError, OSError) as e:
        raise ConfigError(robot_file, "arm.urdf", f"Pinocchio cannot load {urdf}: not valid XML ({e})") from None
    try:
        with _quiet_stderr():
            return pin.buildModelFromUrdf(str(urdf))
    except (RuntimeError, ValueError, OSError) as e:
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ConfigError(robot_file, "arm.urdf", f"Pinocchio cannot load {urdf}: {msg}") from None


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """File descriptor 2 to /dev/null meanwhile (urdfdom prints its parse errors there itself; the
    ConfigError says what went wrong in one line). Start-up only, before any thread writes."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _kind(model: pin.Model, j: int) -> str | None:
    name = model.joints[j].shortname()
    if name in _REVOLUTE:
        return "revolute"
    if name in _CONTINUOUS:
        return "continuous"
    if name in _PRISMATIC:
        return "prismatic"
    return None


_LINKS_LISTED = 40
"""At most this many link names in an ``arm.ee_frame`` error (TIAGo has over 80)."""


def _links(model: pin.Model) -> str:
    names = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
    more = len(names) - _LINKS_LISTED
    return ", ".join(names[:_LINKS_LISTED]) + (f" and {more} more" if more > 0 else "")


def ee_frame_id(robot_file: Path | str, model: pin.Model, ee_frame: str) -> int:
    """Pinocchio's id of the link ``arm.ee_frame`` names (its BODY frame).

    A URDF may give a link and a joint the same name (the Unitree Z1's ``gripperStator`` is both):
    the name then means the link, the only kind of frame ``arm.ee_frame`` accepts. A joint's
    frame is not accepted even where it coincides with its child link's: name the link.

    Raises:
        ConfigError: no link of that name (a joint of that name, or no frame at all), or several
            links of that name — naming the links to choose from.
    """
    matches = [i for i, f in enumerate(model.frames) if f.name == ee_frame]
    bodies = [i for i in matches if model.frames[i].type == pin.FrameType.BODY]
    if len(bodies) == 1:
        return bodies[0]
    if len(bodies) > 1:
        why = f"{len(bodies)} links are named {ee_frame!r}: rename one in the URDF"
    elif matches:  # a joint (or another kind of frame) of that name, and no link
        children = [f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentFrame in matches]
        hint = f" (its child link: {children[0]!r})" if children else ""
        why = f"{ee_frame!r} is a joint of the URDF, not a link{hint}: name a link"
    else:
        why = f"the URDF has no link named {ee_frame!r}"
    raise ConfigError(robot_file, "arm.ee_frame", f"{why}; links: {_links(model)}")


def add_task_frame(model: pin.Model, ee_frame: int, offset: pin.SE3) -> int:
    """Add the task point's frame to ``model``: ``offset`` (``arm.ee_offset_xyz``, ``arm.ee_offset_rpy``)
    relative to the frame ``ee_frame``, on the same joint. Positions, orientations, Jacobians and
    Hessians of this frame are those of the task point (the tool tip rather than the flange).

    Returns:
        Its frame id.
    """
    ee = model.frames[ee_frame]
    frame = pin.Frame("wmm_qp_task_point", int(ee.parentJoint), int(ee_frame), ee.placement * offset,
                      pin.FrameType.OP_FRAME)
    return int(model.addFrame(frame, False))


def chain_to(robot_file: Path, model: pin.Model, ee_frame: str) -> list[int]:
    """Joint ids (Pinocchio's) of the actuated joints from the root to ``ee_frame``, root first."""
    j = model.frames[ee_frame_id(robot_file, model, ee_frame)].parentJoint
    ids = []
    while j > 0:
        if model.joints[j].nv > 0:
            ids.append(int(j))
        j = model.parents[j]
    return ids[::-1]


def read_chain(robot_file: Path, model: pin.Model, ee_frame: str, joints: list[str] | None) -> UrdfChain:
    """The controlled joints (``joints``, or the whole chain to ``ee_frame``) and their URDF limits.

    Raises:
        ConfigError: ``ee_frame`` missing, a joint unknown, off the chain, repeated, out of chain
            order, or of a type other than revolute, continuous and prismatic.
    """
    chain = chain_to(robot_file, model, ee_frame)
    names_on_chain = [model.names[j] for j in chain]
    if joints is None:
        ids = chain
    else:
        ids = []
        for name in joints:
            if not model.existJointName(name):
                raise ConfigError(robot_file, "arm.joints", f"the URDF has no joint named {name!r}")
            j = int(model.getJointId(name))
            if j not in chain:
                raise ConfigError(
                    robot_file,
                    "arm.joints",
                    f"joint {name!r} is not on the chain from the URDF's root to {ee_frame!r} "
                    f"({', '.join(names_on_chain) or 'no joints'}): the joints must be one chain",
                )
            if j in ids:
                raise ConfigError(robot_file, "arm.joints", f"joint {name!r} is listed twice")
            if ids and chain.index(j) < chain.index(ids[-1]):
                raise ConfigError(robot_file, "arm.joints", f"joint {name!r} is out of chain order (root first)")
            ids.append(j)
    if not ids:
        raise ConfigError(robot_file, "arm.joints", f"no actuated joint between the URDF's root and {ee_frame!r}")
    types = []
    for j in ids:
        kind = _kind(model, j)
        if kind is None or model.joints[j].nv != 1:
            raise ConfigError(
                robot_file,
                "arm.joints",
                f"joint {model.names[j]!r} is a {model.joints[j].shortname()}: only revolute, continuous "
                "and prismatic joints are supported",
            )
        types.append(kind)
    lower, upper, velocity, effort = [], [], [], []
    for j, kind in zip(ids, types, strict=True):
        iq, iv = model.joints[j].idx_q, model.joints[j].idx_v
        if kind == "continuous":
            lower.append(-math.inf)
            upper.append(math.inf)
        else:
            lower.append(float(model.lowerPositionLimit[iq]))
            upper.append(float(model.upperPositionLimit[iq]))
        velocity.append(float(model.velocityLimit[iv]))
        effort.append(float(model.effortLimit[iv]))
    others = tuple(model.names[j] for j in range(1, model.njoints) if j not in ids and model.joints[j].nv > 0)
    return UrdfChain(
        joints=tuple(model.names[j] for j in ids),
        types=tuple(types),
        lower=np.array(lower),
        upper=np.array(upper),
        velocity=np.array(velocity),
        effort=np.array(effort),
        others=others,
    )


def lock_configuration(model: pin.Model, locked: dict[str, float]) -> np.ndarray:
    """Pinocchio's q of the full model: neutral, with each locked joint at its given value."""
    q = pin.neutral(model)
    for name, value in locked.items():
        jm = model.joints[model.getJointId(name)]
        if jm.nq == 2:  # continuous: (cos, sin)
            q[jm.idx_q], q[jm.idx_q + 1] = math.cos(value), math.sin(value)
        elif jm.nq == 1:
            q[jm.idx_q] = value
    return q


def reduced_model(
    model: pin.Model, joints: tuple[str, ...], locked: dict[str, float], mount: pin.SE3
) -> pin.Model:
    """The arm's own model: every joint but ``joints`` locked at ``locked`` (or neutral), the
    root placed at ``mount`` in the base frame (so its frames and Jacobians are base-frame ones)."""
    keep = {model.getJointId(n) for n in joints}
    lock = [j for j in range(1, model.njoints) if j not in keep]
    reduced = pin.buildReducedModel(model, lock, lock_configuration(model, locked)) if lock else pin.Model(model)
    if not mount.isIdentity():
        for j in range(1, reduced.njoints):
            if reduced.parents[j] == 0:
                reduced.jointPlacements[j] = mount * reduced.jointPlacements[j]
        for i in range(reduced.nframes):
            f = reduced.frames[i]
            if f.parentJoint == 0 and f.name != "universe":
                f.placement = mount * f.placement
                reduced.frames[i] = f
    return reduced
