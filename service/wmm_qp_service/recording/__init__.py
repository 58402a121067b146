"""Recording a control host's ticks to MCAP, and reading them back (``wmm-qp serve --record``).

:class:`~.journal.TickJournal` is the hook the control thread calls: it copies each tick's
numbers into a ring in shared memory and returns; a separate writer process
(:mod:`.writer`) turns them into an MCAP file with the ``ros2`` profile (CDR messages of ROS 2
types that ROS tools open without wmm-qp, and JSON channels of wmm-qp's own), so the control
thread never waits for a disk or for the interpreter's lock held by serialisation.
:mod:`.reader` reads a recording back, tolerant of a truncated or corrupt end; :mod:`.replay`
re-runs the controller on it. The writer and the reader need the ``record`` extra
(``pip install 'wmm-qp[record]'``: mcap, rosbags); the runtime imports without it.
"""

from __future__ import annotations

import contextlib

from wmm_qp.exceptions import WmmQpError

EXTRA = "record"


class RecordingUnavailable(WmmQpError):
    """The ``record`` extra (mcap, rosbags) is not installed (one line, exit 2)."""

    def __init__(self, missing: str, extra: str = EXTRA) -> None:
        super().__init__(f"recording needs the {missing!r} package: pip install 'wmm-qp[{extra}]'")
        self.missing = missing


def require() -> None:
    """Raise :class:`RecordingUnavailable` unless mcap and rosbags import."""
    for name in ("mcap", "rosbags"):
        try:
            __import__(name)
        except ImportError:
            raise RecordingUnavailable(name) from None


class RecordingError(WmmQpError):
    """A recording that cannot be read or replayed (one line, exit 2)."""


BASELINE = "proxsuite_pywrap"
"""proxsuite's baseline build (no AVX): its solves do not depend on where its buffers lie."""


def proxsuite_build() -> str:
    """Which of proxsuite's builds this process loaded (``proxsuite_pywrap_avx512``, ``_avx2`` or
    the baseline ``proxsuite_pywrap``), or "" when it is not loaded."""
    import sys

    mod = sys.modules.get("proxsuite")
    sub = getattr(mod, "_submodule", None) if mod is not None else None
    return str(getattr(sub, "__name__", "")).rsplit(".", 1)[-1]


def load_proxsuite(build: str) -> str:
    """Load proxsuite's ``build`` in this process, if proxsuite is not loaded yet; the build loaded.

    proxsuite loads its AVX-512 or AVX2 build where the CPU has them; their last bits depend on the
    alignment of their heap buffers, which differs from process to process, so a recording made with
    them does not replay bit for bit (docs/recording.md "Replay"). A recording host and the replay
    load the baseline build (:data:`BASELINE`) instead, by answering proxsuite's own CPU check "no
    AVX" while it loads. Without proxsuite installed: "".
    """
    import sys
    import types

    if "proxsuite" in sys.modules or build != BASELINE:
        with contextlib.suppress(ImportError):
            import proxsuite
        return proxsuite_build()
    stub = types.ModuleType("proxsuite.instructionset")
    stub.has_AVX512F = stub.has_AVX2 = lambda: False  # type: ignore[attr-defined]
    sys.modules["proxsuite.instructionset"] = stub
    try:
        import proxsuite  # noqa: F401
    except ImportError:
        return ""
    finally:
        sys.modules.pop("proxsuite.instructionset", None)
    return proxsuite_build()
