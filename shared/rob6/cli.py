"""The ``rob6`` command: run the system, the Zenoh router, health checks, session logs."""

from __future__ import annotations

import os
import sys

import click

from . import logs
from .config import DEFAULT_ROUTER, DEFAULT_ROUTER_PORT, LINKS, BusSettings, bus_options
from .messages import SERVICES
from .robots import DEFAULT_ROBOT, ROBOT_TYPES


@click.group()
def main() -> None:
    """rob6: a distributed rob6server (see README.md)."""


@main.command()
@click.option("--robot", envvar="ROB6_ROBOT", default=DEFAULT_ROBOT, show_default=True, type=click.Choice(ROBOT_TYPES))
@click.option("--robot-id", envvar="ROB6_ROBOT_ID", default="robot1", show_default=True)
@click.option("--port", envvar="ROB6_PORT", default=5005, show_default=True, type=int)
@click.option("--router-port", envvar="ROB6_ROUTER_PORT", default=DEFAULT_ROUTER_PORT, show_default=True, type=int)
@click.option("--log-dir", envvar="ROB6_LOG_DIR", default="./logs", show_default=True)
@click.option("--dummy/--real-time", envvar="ROB6_DUMMY", default=False, show_default=True,
              help="Instantaneous motion (the original's -d) or real time.")
@click.option("--allow-shutdown/--no-allow-shutdown", envvar="ROB6_ALLOW_SHUTDOWN", default=True,
              show_default=True, help="Let a client's Shutdown stop the system.")
@click.option("--restart/--no-restart", default=True, show_default=True,
              help="Restart a service that died (it is reported either way).")
@click.option("--link", envvar="ROB6_LINK", default="sim", show_default=True, type=click.Choice(LINKS),
              help="How the driver reaches the robot: the simulation, a KUKA over RSI, an Adept over "
                   "simple_message (simple_message, also called adept), or a Kawasaki running rob6's AS "
                   "program (kawasaki) [env ROB6_LINK].")
@click.option("--service", "services", multiple=True, type=click.Choice(SERVICES),
              help="Start only these services (repeat).")
@click.option("--ros/--no-ros", envvar="ROB6_ROS", default=True, show_default=True,
              help="The robot as a ROS 2 node (rmw_zenoh) among the services started by default "
                   "[env ROB6_ROS, 0 = off].")
@click.option("--log-level", envvar="ROB6_LOG_LEVEL", default="WARNING", show_default=True,
              type=click.Choice(["DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"], case_sensitive=False))
def run(robot: str, robot_id: str, port: int, router_port: int, log_dir: str, dummy: bool, allow_shutdown: bool,
        restart: bool, link: str, services: tuple[str, ...], ros: bool, log_level: str) -> None:
    """Start everything on this machine: router, services and gateway."""
    from .launcher import run as run_system
    os.environ["ROB6_LINK"] = link  # the driver reads it
    sys.exit(run_system(robot=robot, robot_id=robot_id, port=port, router_port=router_port,
                        log_dir=log_dir, dummy=dummy, allow_shutdown=allow_shutdown, restart=restart,
                        services=tuple(services) or tuple(s for s in SERVICES if ros or s != "ros"), log_level=log_level.upper()))


@main.command()
@bus_options
def router(settings: BusSettings, log_level: str) -> None:
    """Run a Zenoh router (every rob6 process connects to it); --listen defaults to tcp/127.0.0.1:7447."""
    from .router import run as run_router
    logs.configure("router", log_level)
    run_router(settings, settings.listen or (DEFAULT_ROUTER,))


@main.command()
@bus_options
@click.argument("service")
@click.option("--timeout", default=3.0, show_default=True, type=float)
def health(settings: BusSettings, log_level: str, service: str, timeout: float) -> None:
    """Exit 0 when SERVICE is up: its liveliness token is on the bus.

    The gateway declares its token once it listens, so this also covers the gateway
    without opening a client session (which would take the single client slot).
    """
    from .bus import Bus
    bus = Bus(settings, "health", mode="client")
    try:
        ok = not bus.wait_for([service], timeout)
    finally:
        bus.close()
    click.echo(f"{service}: {'up' if ok else 'DOWN'}")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()

