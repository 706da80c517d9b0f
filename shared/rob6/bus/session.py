"""The Zenoh session of a rob6 process: configuration, opening, identity and key expressions.

The Zenoh session of a rob6 process: its configuration, its opening, who it is and its
key expressions (``rob6/<id>/...``)."""

from __future__ import annotations

import threading
from typing import Any

import msgspec
import zenoh

from ..config import BusSettings
from .codec import Decoders


def zenoh_config(settings: BusSettings, *, mode: str | None = None,
                 listen: tuple[str, ...] | None = None) -> zenoh.Config:
    """Zenoh configuration from rob6 settings.

    Zenoh's transport settings stay its defaults. Batching off removed a 1 ms tail between
    two processes on one host, and it cost a multi-host deployment's remote calls two to
    three times their p99, also when only the services on the robot PC had it
    (docs/PERFORMANCE.md, "Zenoh's batching").

    A JSON5 file in the settings (TLS, access control) is the base; mode, connect and
    listen come from the settings unless the file sets them itself.
    """
    config = zenoh.Config.from_file(settings.zenoh_config) if settings.zenoh_config else zenoh.Config()
    defaults = zenoh.Config()
    file_mode = msgspec.json.decode(config.get_json("mode"))
    if file_mode != msgspec.json.decode(defaults.get_json("mode")):
        mode = file_mode  # the file decides (a secure profile runs every service as a TLS client)
    mode = mode or settings.mode
    listen = settings.listen if listen is None else listen
    if mode == "peer" and not listen:
        # loopback only unless asked: peers link to each other directly (one hop)
        # without opening ports on the lab network
        listen = ("tcp/127.0.0.1:0",)

    def set_unless_in_file(key: str, value: object) -> None:
        if config.get_json(key) == defaults.get_json(key):
            config.insert_json5(key, msgspec.json.encode(value).decode())

    set_unless_in_file("mode", mode)
    if mode != "router" and settings.connect:
        set_unless_in_file("connect/endpoints", list(settings.connect))
    if listen:
        set_unless_in_file("listen/endpoints", list(listen))
    # no multicast scouting: rob6 finds its router by configuration, never by
    # broadcasting on the lab network
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


def open_session(settings: BusSettings, *, mode: str | None = None,
                 listen: tuple[str, ...] | None = None) -> zenoh.Session:
    zenoh.try_init_log_from_env()  # Zenoh's own log on stderr, only when RUST_LOG asks for it
    return zenoh.open(zenoh_config(settings, mode=mode, listen=listen))


class BusSession:
    """One Zenoh session of one rob6 process, with what every job of the bus shares: who
    it is (service, instance), its keys, its lock, its decoders and whether it is closed."""

    def __init__(self, settings: BusSettings, service: str, *, mode: str | None = None,
                 listen: tuple[str, ...] | None = None):
        self.settings = settings
        self.service = service
        self.instance = settings.instance
        self.prefix = f"rob6/{settings.robot_id}"
        self.session = open_session(settings, mode=mode, listen=listen)
        self._lock = threading.Lock()
        self._declared: list[Any] = []  # zenoh declarations that live as long as the session
        self._closed = threading.Event()
        self._decoder = Decoders()
        self._attachment = self.instance.encode()

    @property
    def closed(self) -> threading.Event:
        """Set when the bus closes: a thread of the bus's user waits on it to end with it."""
        return self._closed

    def key(self, *parts: str) -> str:
        return "/".join((self.prefix, *parts))
