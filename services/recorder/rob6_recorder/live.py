"""The live view: the recorder's channels on a Foxglove WebSocket server (``foxglove-sdk``).

``LiveView`` publishes what the recorder writes, with the same topics and JSON schemas
as the MCAP files (``schemas.schema_for``), so a layout made for a recording works live:
``/robot_description`` (the URDF, ``std_msgs/String``), ``/tf`` (``foxglove.FrameTransforms``,
derived from the joint states), ``/driver/joint_state`` (mode, moving, link, late packets;
every field, defaults included, as ``/driver/clearance``),
``/driver/link``, ``/gripper/state``, ``/log`` (``foxglove.Log``), the raw session and bus
channels, and ``/commands``: every client line and its reply as a ``foxglove.Log``
(``name`` = ``session <n>``, ``message`` = ``> line`` / ``< reply``) for the Log panel. From
the driver's ``/cell`` and ``/driver/clearance`` it draws the cell on ``/cell/scene``
(``foxglove.SceneUpdate``, ``cell_scene``): the safety zones and the tool, the zone nearest
the arm coloured by its distance.

The recorder calls ``publish`` for each record it queues for its files (``Recorder.submit``):
the live view is one more subscriber of the bus and costs the real-time path nothing. A
message goes to the clients subscribed to its channel only; one without subscribers is
dropped in the SDK. The WebSocket protocol has no latched topics, so the last message of
``LATCHED`` topics (the URDF, the cell and its scene, gripper, link, joint state, ``/tf``...)
is sent again when a client subscribes to it: a panel opened later shows the robot at once.

The URDF is also an asset (``package://rob6/robot.urdf``, ``fetchAsset``), for a 3D
panel's URDF layer with a URL.

``rob6-log play FILE`` (``playback.py``) serves a recording through the same class.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import foxglove
import msgspec
from foxglove.websocket import (
    Capability,
    ChannelView,
    Client,
    PlaybackControlRequest,
    PlaybackState,
    ServerListener,
    WebSocketServer,
)

from rob6.config import DEFAULT_LIVE_PORT, BusSettings
from rob6.errors import RefusedError
from rob6.messages import Clearance, JointState
from rob6_recorder_native import ROBOT_DESCRIPTION_TOPIC, STATUS_TOPIC

from .cell_scene import SCENE_TOPIC, CellScene
from .payloads import as_dict, encode
from .schemas import schema_for, stamp
from .writer import CELL_TOPIC, CLEARANCE_TOPIC, JOINT_STATE_TOPIC

log = logging.getLogger("rob6.recorder.live")

DEFAULT_PORT = DEFAULT_LIVE_PORT
COMMANDS_TOPIC = "/commands"
URDF_ASSET = "package://rob6/robot.urdf"
#: advertised from the start (a panel can subscribe before the first message)
STANDARD_TOPICS = ("/tf", "/driver/joint_state", "/driver/link", "/gripper/state", "/log", COMMANDS_TOPIC,
                   SCENE_TOPIC)
#: a latched topic's last message goes out this long after a client subscribed to it (s)
RESEND_DELAY_S = 0.05
LATCHED = frozenset({ROBOT_DESCRIPTION_TOPIC, "/tf", "/flange", "/driver/joint_state", "/driver/link",
                     "/gripper/state", STATUS_TOPIC, CELL_TOPIC, CLEARANCE_TOPIC, SCENE_TOPIC})
#: the latched topics the view makes itself, never found in a recording
OWN_LATCHED = frozenset({ROBOT_DESCRIPTION_TOPIC, SCENE_TOPIC})

_encoder = msgspec.json.Encoder()
#: the driver's messages shown with every field (it leaves defaults out: ``mode`` idle,
#: ``link`` connected, ``late`` 0, a clearance's ``zone`` true...), so a panel shows them at any time
_COMPLETED: dict[str, msgspec.json.Decoder[Any]] = {JOINT_STATE_TOPIC: msgspec.json.Decoder(JointState),
                                                     CLEARANCE_TOPIC: msgspec.json.Decoder(Clearance)}


def _complete(topic: str, payload: bytes) -> bytes:
    """The record as a panel gets it: a driver's message with every field, the rest as it is."""
    decoder = _COMPLETED.get(topic)
    if decoder is None:
        return payload
    try:
        return _encoder.encode(msgspec.structs.asdict(decoder.decode(payload)))
    except (msgspec.DecodeError, msgspec.ValidationError):
        return payload


class LiveRefused(RefusedError):
    """The live view may not run with these settings (one line for the user)."""


def live_settings(port: int, bind: str, settings: BusSettings | None = None,
                  tls_cert: str | None = None, tls_key: str | None = None) -> tuple[bytes, bytes] | None:
    """Check the live view's settings; the TLS certificate and key to use, if any.

    On a secure bus (a ``tls/`` or ``quic/`` Zenoh endpoint, as in docker-compose.secure.yml)
    an unencrypted, unauthenticated WebSocket would publish what the bus protects: the live
    view is refused there unless it gets a certificate and key (then it serves ``wss://``).
    """
    if bool(tls_cert) != bool(tls_key):
        raise LiveRefused("ROB6_LIVE_TLS_CERT and ROB6_LIVE_TLS_KEY go together")
    if tls_cert and tls_key:
        with open(tls_cert, "rb") as cert, open(tls_key, "rb") as key:
            return cert.read(), key.read()
    if settings is not None and secure_bus(settings):
        raise LiveRefused(
            f"live view on port {port} refused: the bus is TLS-protected (secure profile) and the live "
            f"view has no certificate; set ROB6_LIVE_TLS_CERT/ROB6_LIVE_TLS_KEY (wss://) or ROB6_LIVE_PORT=0")
    return None


def secure_bus(settings: BusSettings) -> bool:
    """True when the Zenoh bus runs over TLS or QUIC (the secure profile)."""
    return any(e.startswith(("tls/", "quic/")) for e in (*settings.connect, *settings.listen))


def command_log(topic: str, data: Any, log_time: int) -> dict[str, Any] | None:
    """A session's client line or reply as a ``foxglove.Log`` (None for other topics)."""
    if not topic.startswith("/session/") or not topic.endswith(("/client_in", "/client_out")):
        return None
    record = as_dict(data)
    if not isinstance(record, dict):
        return None
    incoming = topic.endswith("/client_in")
    text = str(record.get("text", "")).rstrip("\r\n")
    session = record.get("session", topic.split("/")[2])
    message = f"{'>' if incoming else '<'} {text}"
    level = 4 if not incoming and text.startswith(("ERROR", "Error", "error")) else 2
    return {"timestamp": stamp(log_time), "level": level, "message": message, "name": f"session {session}",
            "file": "", "line": 0, "session": session, "cid": record.get("cid", ""),
            "direction": "in" if incoming else "out"}


class _Listener(ServerListener):
    """Server callbacks: re-send latched topics to a new subscriber; playback control."""

    def __init__(self, view: LiveView):
        self.view = view

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        if channel.topic in LATCHED:
            # after the SDK registered the subscription (the callback runs before it does). A
            # daemon thread named so from the start: a Timer would ask this thread, the SDK's,
            # for its Python thread, and the dummy one Python makes for it cannot be joined
            # when the recorder stops (rob6.service.end_threads: exit code 1)
            threading.Thread(target=self.view.resend, args=(channel.topic, RESEND_DELAY_S), daemon=True).start()

    def on_playback_control_request(self, request: PlaybackControlRequest) -> PlaybackState | None:
        handler = self.view.playback_handler
        return handler(request) if handler is not None else None


class LiveView:
    """A Foxglove WebSocket server fed with recorder records (topic, log time, JSON)."""

    def __init__(self, *, host: str = "127.0.0.1", port: int = DEFAULT_PORT, urdf: str | None = None,
                 name: str = "rob6", tls: tuple[bytes, bytes] | None = None,
                 playback_time_range: tuple[int, int] | None = None,
                 playback_handler: Callable[[PlaybackControlRequest], PlaybackState | None] | None = None,
                 clock: Callable[[], int] | None = None):
        self.context = foxglove.Context()
        self.urdf = urdf
        self.playback_handler = playback_handler
        self._channels: dict[str, foxglove.Channel] = {}
        self._last: dict[str, tuple[bytes, int]] = {}
        self._lock = threading.Lock()  # channel creation and the latched messages
        self.scene = CellScene()
        capabilities = [Capability.Time]
        if playback_time_range is not None:
            capabilities.append(Capability.PlaybackControl)
        self.server: WebSocketServer = foxglove.start_server(
            name=name, host=host, port=port, context=self.context, capabilities=capabilities,
            server_listener=_Listener(self), asset_handler=self._asset,
            playback_time_range=playback_time_range,
            tls_cert=tls[0] if tls else None, tls_key=tls[1] if tls else None)
        self.scheme = "wss" if tls else "ws"
        self.host = host
        self.closed = False
        if urdf:
            now = clock() if clock else _now()
            self.publish(ROBOT_DESCRIPTION_TOPIC, now, {"data": urdf})

    @property
    def port(self) -> int:
        return self.server.port

    @property
    def url(self) -> str:
        host = "127.0.0.1" if self.host in ("0.0.0.0", "", "::") else self.host
        return f"{self.scheme}://{host}:{self.port}"

    # ------------------------------------------------------------------ publishing
    def channel(self, topic: str) -> foxglove.Channel:
        with self._lock:
            ch = self._channels.get(topic)
            if ch is None:
                spec = schema_for(topic)
                ch = self._channels[topic] = foxglove.Channel(
                    topic, schema=foxglove.Schema(name=spec.name, encoding="jsonschema", data=spec.data),
                    message_encoding="json", context=self.context)
            return ch

    def advertise(self, topics: Sequence[str]) -> None:
        """Create these channels now (clients see them before their first message)."""
        for topic in topics:
            self.channel(topic)

    def publish(self, topic: str, log_time: int, data: Any, payload: bytes | None = None) -> None:
        """One record (``data`` a dict/Struct/JSON bytes; ``payload`` its JSON if known)."""
        if self.closed:
            return
        if payload is None:
            payload = encode(data)
        ch = self._channels.get(topic) or self.channel(topic)
        if topic in LATCHED:
            self._last[topic] = (payload, log_time)
        if ch.base.has_sinks():  # nobody watching: no work beyond this check
            ch.base.log(_complete(topic, payload), log_time)
        if topic.startswith("/session/"):
            commands = self._channels.get(COMMANDS_TOPIC) or self.channel(COMMANDS_TOPIC)
            entry = command_log(topic, data, log_time) if commands.base.has_sinks() else None
            if entry is not None:
                commands.base.log(_encoder.encode(entry), log_time)
        elif topic in (CELL_TOPIC, CLEARANCE_TOPIC):
            scene = self.scene.update(topic, payload, log_time)
            if scene is not None:
                self.publish(SCENE_TOPIC, log_time, scene)

    def resend(self, topic: str, after_s: float = 0.0) -> None:
        """The last message of a latched topic again, ``after_s`` from now (a client just subscribed to it)."""
        time.sleep(after_s)
        last = self._last.get(topic)
        ch = self._channels.get(topic)
        if last is not None and ch is not None and not self.closed:
            payload, log_time = last
            ch.base.log(_complete(topic, payload), log_time)

    def clear_latched(self) -> None:
        """Forget the latched messages (playback seeks), the URDF excepted."""
        for topic in list(self._last):
            if topic != ROBOT_DESCRIPTION_TOPIC:
                self._last.pop(topic, None)
        self.scene = CellScene()

    def broadcast_time(self, ns: int) -> None:
        self.server.broadcast_time(ns)

    def _asset(self, uri: str) -> bytes | None:
        if self.urdf and (uri == URDF_ASSET or uri.endswith(".urdf")):
            return self.urdf.encode()
        return None

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.server.stop()


def _now() -> int:
    return time.time_ns()


def start_live(urdf: str | None, *, port: int, bind: str, settings: BusSettings | None = None,
               tls_cert: str | None = None, tls_key: str | None = None, name: str = "rob6",
               **options: Any) -> LiveView | None:
    """The recorder's live view, or None (port 0, refused, or the port taken: logged, the
    recording goes on without it)."""
    if port == 0:
        return None
    try:
        tls = live_settings(port, bind, settings, tls_cert, tls_key)
    except (LiveRefused, OSError) as exc:
        log.error("%s", exc)
        return None
    try:
        view = LiveView(host=bind, port=port, urdf=urdf, name=name, tls=tls, **options)
        view.advertise(STANDARD_TOPICS)
    except Exception as exc:  # the port in use, a bad certificate: no live view, recording goes on
        log.error("live view not started on %s:%d: %s", bind, port, exc)
        return None
    log.info("live view: %s (open in Foxglove: Open connection, Foxglove WebSocket)", view.url)
    return view


def env_tls() -> tuple[str | None, str | None]:
    return os.environ.get("ROB6_LIVE_TLS_CERT") or None, os.environ.get("ROB6_LIVE_TLS_KEY") or None


__all__: Sequence[str] = ("DEFAULT_PORT", "COMMANDS_TOPIC", "LATCHED", "OWN_LATCHED", "LiveRefused", "LiveView",
                          "command_log", "live_settings", "secure_bus", "start_live")
