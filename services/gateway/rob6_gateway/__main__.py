"""rob6-gateway: the rob6server protocol on TCP (default port 5005)."""

from __future__ import annotations

import logging
import signal
import socket
import sys
import threading
import time

import click

from rob6 import logs, service
from rob6.bus import Bus
from rob6.config import BusSettings, bus_options
from rob6.ownership import EXIT_REFUSED
from rob6.robots import get_robot

from .commands import Gateway, Options
from .server import AddressFilter, Server

log = logging.getLogger("rob6.gateway")

#: how long a stopping gateway gives the open session to end: its thread finishes and
#: queues its last records, and the planner confirms that what it left moving is at rest
#: (the launcher allows the gateway more: rob6.launcher.STOP_ORDER)
SESSION_END_S = 10.0


@click.command()
@bus_options
@click.option("--port", envvar="ROB6_PORT", default=5005, show_default=True, type=int,
              help="TCP port for clients [env ROB6_PORT].")
@click.option("--bind", envvar="ROB6_BIND", default="0.0.0.0", show_default=True,
              help="Address to listen on; all interfaces by default, as the original [env ROB6_BIND].")
@click.option("--allow-shutdown/--no-allow-shutdown", envvar="ROB6_ALLOW_SHUTDOWN", default=False,
              show_default=True, help="Let clients stop the whole system with Shutdown "
                                      "[env ROB6_ALLOW_SHUTDOWN].")
@click.option("--allow-direct-adept-cmd/--no-allow-direct-adept-cmd", envvar="ROB6_ALLOW_DIRECT_ADEPT_CMD",
              default=False, show_default=True,
              help="Let clients send raw controller commands (ad850) [env ROB6_ALLOW_DIRECT_ADEPT_CMD].")
@click.option("--allow-client", "allow_clients", envvar="ROB6_ALLOW_CLIENTS", multiple=True,
              help="Accept clients only from these addresses/networks (CIDR); repeat or comma-separate "
                   "[env ROB6_ALLOW_CLIENTS]. Default: everyone.")
@click.option("--pause-ms", envvar="ROB6_PAUSE_MS", default=5.0, show_default=True, type=float,
              help="An unterminated command is complete when no byte follows for this long.")
@click.option("--idle-timeout", envvar="ROB6_IDLE_TIMEOUT", default=0.0, show_default=True, type=float,
              help="Close a client that sends nothing for this many seconds (0: never).")
def main(settings: BusSettings, log_level: str, port: int, bind: str, allow_shutdown: bool,
         allow_direct_adept_cmd: bool, allow_clients: tuple[str, ...], pause_ms: float, idle_timeout: float) -> None:
    """Serve the rob6server text protocol and forward the work to the rob6 services."""
    logs.configure("gateway", log_level)
    service.follow_launcher()
    networks = [n.strip() for item in allow_clients for n in item.split(",") if n.strip()]
    exit_code = _serve(settings, port, bind, Options(allow_shutdown, allow_direct_adept_cmd),
                       AddressFilter(networks) if networks else None, pause_ms / 1000.0, idle_timeout)
    service.end_threads()  # the gateway's objects are unreachable now: gone before the interpreter
    if exit_code:
        sys.exit(exit_code)


def _serve(settings: BusSettings, port: int, bind: str, options: Options, allow: AddressFilter | None,
           pause_s: float, idle_timeout: float) -> int:
    """The gateway from the bus's opening to its close; the exit code."""
    bus = Bus(settings, "gateway")
    stop = threading.Event()
    stood_down: list[str] = []  # an earlier gateway of this robot appeared (see rob6.ownership)

    def stand_down(message: str) -> None:
        stood_down.append(message)
        stop.set()

    ownership = service.claim(bus, stand_down)
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    with logs.to_bus(bus):
        _serve_clients(bus, stop, settings, port, bind, Server(
            Gateway(bus, get_robot(settings.robot), options), pause_s=pause_s, idle_timeout_s=idle_timeout,
            allow=allow))
        if ownership is not None:
            ownership.release()
    bus.close()
    return EXIT_REFUSED if stood_down else 0


def _serve_clients(bus: Bus, stop: threading.Event, settings: BusSettings, port: int, bind: str,
                   server: Server) -> None:
    """Once what the commands need is alive, clients until ``stop`` (or a client's
    Shutdown); then the session still open ends."""
    gateway = server.gateway
    # clients only once the services their commands reach are alive in this process'
    # own view: a client connecting the instant the port opens gets real answers
    deadline = time.monotonic() + service.NEEDS_WAIT_S
    while (missing := service.missing_needs(bus, "gateway")) and not stop.is_set():
        if time.monotonic() > deadline:
            log.warning("gateway: %s not alive after %.0f s; accepting clients without",
                        ", ".join(missing), service.NEEDS_WAIT_S)
            break
        stop.wait(0.02)
    if stop.is_set():
        return
    try:
        listener = socket.create_server((bind, port), family=socket.AF_INET6 if ":" in bind else socket.AF_INET)
    except OSError as exc:
        bus.close()
        service.fail("gateway", f"cannot listen on {bind}:{port}: {exc.strerror or exc}; is another "
                                f"rob6 or rob6server running? Stop it or choose another ROB6_PORT",
                     EXIT_REFUSED)
    threading.Thread(target=server.serve_forever, args=(listener,), name="accept", daemon=True).start()
    bus.announce()  # tells tools and the launcher the gateway is up
    log.warning("gateway listening on %s:%d (robot %s)", bind, port, settings.robot)
    while not stop.is_set() and not gateway.shutdown_requested.is_set():
        stop.wait(0.1)
    if gateway.shutdown_requested.is_set():
        log.warning("shutting down rob6server.")
        bus.publish("control/shutdown", b"{}", reliable=True)
    listener.shutdown(socket.SHUT_RDWR)  # wakes the accepting thread (a close alone does not)
    listener.close()
    server.close(SESSION_END_S)


if __name__ == "__main__":
    main()
