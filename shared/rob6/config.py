"""Configuration shared by every rob6 process: CLI flags with environment fallbacks.

Every option can be given as a flag or as the environment variable shown in
``--help`` (flags win). A Zenoh JSON5 file (``--zenoh-config`` / ``ROB6_ZENOH_CONFIG``)
is merged on top of the generated Zenoh configuration; that is how TLS and access
control are switched on (see deploy/).
"""

from __future__ import annotations

import functools
import os
import socket
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import click

from .robots import DEFAULT_ROBOT, ROBOT_TYPES

#: the Zenoh router's port (``rob6 run --router-port``, ``ROB6_ROUTER_PORT``)
DEFAULT_ROUTER_PORT = 7447
DEFAULT_ROUTER = f"tcp/127.0.0.1:{DEFAULT_ROUTER_PORT}"
#: the live view's port (Foxglove WebSocket, served by the recorder; ROB6_LIVE_PORT, 0 = off)
DEFAULT_LIVE_PORT = 8765
#: how the driver reaches the robot: the simulation, a KUKA KR C4 over RSI, or an Adept
#: V+ controller over ROS-Industrial simple_message (``adept`` is another name for it)
LINKS = ("sim", "rsi", "simple_message", "adept", "kawasaki")


def default_instance() -> str:
    """A key-expression-safe id for this process: host name plus a random suffix."""
    host = "".join(c if c.isalnum() or c in "-_" else "-" for c in socket.gethostname())
    return f"{host or 'host'}-{uuid.uuid4().hex[:6]}"


@dataclass(frozen=True)
class BusSettings:
    robot: str = DEFAULT_ROBOT
    robot_id: str = "robot1"
    connect: tuple[str, ...] = (DEFAULT_ROUTER,)
    listen: tuple[str, ...] = ()
    mode: str = "peer"  # peer: direct links between services (lowest latency); client: all via router
    zenoh_config: str | None = None
    instance: str = field(default_factory=default_instance)

    @classmethod
    def from_env(cls, **overrides: Any) -> BusSettings:
        """Settings from ROB6_* variables (used by tests and tools without a CLI)."""
        env = os.environ
        values: dict[str, Any] = dict(
            robot=env.get("ROB6_ROBOT", DEFAULT_ROBOT),
            robot_id=env.get("ROB6_ROBOT_ID", "robot1"),
            connect=_split(env.get("ROB6_ZENOH_CONNECT", DEFAULT_ROUTER)),
            listen=_split(env.get("ROB6_ZENOH_LISTEN", "")),
            mode=env.get("ROB6_ZENOH_MODE", "peer"),
            zenoh_config=env.get("ROB6_ZENOH_CONFIG") or None,
        )
        values.update(overrides)
        return cls(**values)


def _split(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(",") if part.strip())


R = TypeVar("R")


def bus_options(func: Callable[..., R]) -> Callable[..., R]:
    """Click options every service shares; passes ``settings: BusSettings``."""

    @click.option("--robot", envvar="ROB6_ROBOT", default=DEFAULT_ROBOT, show_default=True,
                  type=click.Choice(ROBOT_TYPES), help="Robot type [env ROB6_ROBOT].")
    @click.option("--robot-id", envvar="ROB6_ROBOT_ID", default="robot1", show_default=True,
                  help="Name of this robot on the bus; several robots can share one Zenoh network "
                       "[env ROB6_ROBOT_ID].")
    @click.option("--connect", envvar="ROB6_ZENOH_CONNECT", default=DEFAULT_ROUTER, show_default=True,
                  help="Zenoh endpoints to connect to, comma-separated [env ROB6_ZENOH_CONNECT].")
    @click.option("--listen", envvar="ROB6_ZENOH_LISTEN", default="",
                  help="Zenoh endpoints to listen on, comma-separated [env ROB6_ZENOH_LISTEN].")
    @click.option("--mode", envvar="ROB6_ZENOH_MODE", default="peer", show_default=True,
                  type=click.Choice(["peer", "client"]),
                  help="Zenoh mode: peer links services directly, client goes through the router "
                       "[env ROB6_ZENOH_MODE].")
    @click.option("--zenoh-config", envvar="ROB6_ZENOH_CONFIG", default=None,
                  type=click.Path(exists=True, dir_okay=False),
                  help="Zenoh JSON5 file merged on top (TLS, access control) [env ROB6_ZENOH_CONFIG].")
    @click.option("--log-level", envvar="ROB6_LOG_LEVEL", default="WARNING", show_default=True,
                  type=click.Choice(["DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"], case_sensitive=False),
                  help="Initial log level; SetVerbosity changes it at run time [env ROB6_LOG_LEVEL].")
    @functools.wraps(func)
    def wrapper(*args: Any, robot: str, robot_id: str, connect: str, listen: str, mode: str,
                zenoh_config: str | None, log_level: str, **kwargs: Any) -> R:
        settings = BusSettings(
            robot=robot, robot_id=robot_id, connect=_split(connect), listen=_split(listen),
            mode=mode, zenoh_config=zenoh_config,
        )
        return func(*args, settings=settings, log_level=log_level.upper(), **kwargs)

    return wrapper
