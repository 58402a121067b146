"""One ROS 2 node in its own context, spun by its own executor in a thread of its own.

A process's control thread never waits on rclpy: subscriptions store what arrives (the newest
sample, stamped on arrival), the control thread reads it and publishes (rclpy's ``publish`` is
safe from any thread). Each :class:`RosNode` has its own ``rclpy.Context``: nothing global, two
in one process (a test) do not share a shutdown.

Discovery stays on this machine when the caller says so (docs/ros2.md "Discovery"): a network
namespace with only loopback, or ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` with the Fast DDS
profile ``configs/ros2/fastdds_localhost.xml``.
"""

from __future__ import annotations

import contextlib
import threading
from types import TracebackType
from typing import Any


class Ros2Missing(RuntimeError):
    """rclpy or a message package is not installed."""


def import_rclpy() -> Any:
    """rclpy, or :class:`Ros2Missing` saying how to install it."""
    try:
        import rclpy
        import rclpy.executors
    except ImportError as e:
        raise Ros2Missing(f"needs ROS 2's Python client (pip install 'wmm-qp[ros2]'): {e}") from None
    return rclpy


def qos(reliable: bool, depth: int = 1) -> Any:
    """A keep-last QoS profile: reliable (commands: ros2_control's controllers subscribe reliable,
    and a best-effort publisher never matches them) or best effort (state in: the newest wins, and
    a best-effort subscription matches either kind of publisher)."""
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT)


class RosNode:
    """A node named ``name`` (in ``namespace``), spun in a daemon thread until :meth:`close`.

    Raises:
        Ros2Missing: rclpy is not installed.
    """

    def __init__(self, name: str, namespace: str = "") -> None:
        rclpy = import_rclpy()
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node: Any = Node(name, namespace=namespace, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name=f"rclpy-{name}", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        with contextlib.suppress(Exception):  # the context shut down under it: the thread ends
            while self.context.ok():
                self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        """Stop the executor, destroy the node, shut the context down (idempotent)."""
        with contextlib.suppress(Exception):
            self.context.shutdown()
        self._thread.join(timeout=2.0)
        with contextlib.suppress(Exception):
            self.executor.shutdown(timeout_sec=0.5)
        with contextlib.suppress(Exception):
            self.node.destroy_node()

    def __enter__(self) -> RosNode:
        return self

    def __exit__(self, t: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None) -> None:
        self.close()
