"""rob6-recorder: every exchange of one robot into MCAP files (ROB6_LOG_DIR)."""

from __future__ import annotations

from collections.abc import Callable

import click

from rob6 import service
from rob6.bus import Bus
from rob6.config import BusSettings, bus_options
from rob6.robots import get_robot

from .live import DEFAULT_PORT, env_tls
from .service import RecorderService


@click.command()
@bus_options
@click.option("--log-dir", envvar="ROB6_LOG_DIR", default="./logs", show_default=True,
              type=click.Path(file_okay=False), help="Where the MCAP files go [env ROB6_LOG_DIR].")
@click.option("--rotate-mb", envvar="ROB6_ROTATE_MB", default=256, show_default=True, type=int,
              help="Start a new system recording after this many MiB.")
@click.option("--rotate-minutes", envvar="ROB6_ROTATE_MINUTES", default=60, show_default=True, type=int,
              help="Start a new system recording after this many minutes.")
@click.option("--live-port", envvar="ROB6_LIVE_PORT", default=DEFAULT_PORT, show_default=True, type=int,
              help="Port of the live view (Foxglove WebSocket); 0 = off [env ROB6_LIVE_PORT].")
@click.option("--bind", envvar="ROB6_BIND", default="0.0.0.0", show_default=True,
              help="Address the live view listens on, like the gateway [env ROB6_BIND].")
def main(settings: BusSettings, log_level: str, log_dir: str, rotate_mb: int, rotate_minutes: int,
         live_port: int, bind: str) -> None:
    """Record the robot's bus, client sessions, joint states and logs; serve the live view."""

    def setup(bus: Bus) -> Callable[[], None]:
        recorder = RecorderService(bus, get_robot(settings.robot), log_dir,
                                   live_port=live_port, live_bind=bind, live_tls=env_tls(),
                                   rotate_bytes=rotate_mb << 20, rotate_seconds=rotate_minutes * 60)
        recorder.start()
        return recorder.stop

    service.run(settings, "recorder", log_level, setup)


if __name__ == "__main__":
    main()
