"""rmw_zenoh's wire format on a Zenoh session: a ROS 2 node with publishers and service servers.

What a ROS 2 node using ``rmw_zenoh_cpp`` expects to find (ros2/rmw_zenoh: docs/design.md,
liveliness_utils.cpp, qos.cpp, attachment_helpers.cpp, rmw_publisher_data.cpp):

* data on ``<domain>/<name without leading slash>/<type>/<type hash>``, the type as
  ``pkg::msg::dds_::Name_`` and the hash ``RIHS01_<hex>`` (Jazzy and later) or
  ``TypeHashNotSupported`` (Humble);
* a liveliness token per node and per entity, ``@ros2_lv/<domain>/<session id>/<node id>/
  <entity id>/<NN|MP|MS|SS|SC>/<enclave>/<namespace>/<node>[/<name>/<type>/<hash>/<qos>]``,
  names with ``/`` replaced by ``%`` (the empty namespace is ``%``), the QoS as
  ``reliability:durability:history,depth:deadline s,ns:lifespan s,ns:liveliness,s,ns`` with
  every value equal to rmw_zenoh's default left empty;
* every publication, query and reply carries an attachment of 33 bytes: the sequence number
  (int64 LE), the source timestamp in ns (int64 LE), 0x10 (the GID's length) and the 16-byte
  GID of the sender (a reply carries the request's number and the client's GID);
* publishers are zenoh.ext advanced publishers; a transient-local one keeps the last ``depth``
  samples for late joiners and can be detected (``publisher_detection``), with sample-miss
  heartbeats when it is reliable;
* a service is a complete queryable on its key expression; its reply may come later than
  the query's callback (an action's get_result answers when the goal ends).

rmw_zenoh makes the GID from an XXH3 hash of the token; here it is the first 16 bytes of
the token's SHA-256: peers only compare GIDs, they never recompute them.
"""

from __future__ import annotations

import hashlib
import itertools
import logging
import struct
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh

from . import cdr
from .idl import dds_name, type_hash

log = logging.getLogger("rob6.ros")

ADMIN_SPACE = "@ros2_lv"
#: distros whose key expressions carry type hashes; Humble puts this in their place
NO_HASH = "TypeHashNotSupported"
HASHED_DISTROS = ("jazzy", "kilted", "rolling")
DISTROS = ("humble", *HASHED_DISTROS)
ATTACHMENT_SIZE = 33
#: rmw_zenoh's sporadic heartbeat of a reliable transient-local publisher, seconds
HEARTBEAT_S = 0.5

# rmw's QoS enums
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2
#: rmw_zenoh's default QoS, whose values a token leaves out
DEFAULT_RELIABILITY, DEFAULT_DURABILITY, DEFAULT_HISTORY, DEFAULT_DEPTH = RELIABLE, VOLATILE, KEEP_LAST, 42


@dataclass(frozen=True)
class Qos:
    reliability: int = RELIABLE
    durability: int = VOLATILE
    history: int = KEEP_LAST
    depth: int = 10

    def keyexpr(self) -> str:
        """As rmw_zenoh writes it into a token (deadline, lifespan and liveliness at their defaults)."""
        def differs(value: int, default: int) -> str:
            return "" if value == default else str(value)

        return (f"{differs(self.reliability, DEFAULT_RELIABILITY)}:{differs(self.durability, DEFAULT_DURABILITY)}:"
                f"{differs(self.history, DEFAULT_HISTORY)},{differs(self.depth, DEFAULT_DEPTH)}:,:,:,,")


#: rclcpp's defaults: topics depth 10; services (rmw_qos_profile_services_default) depth 10
#: volatile; the action status topic transient local, depth 1; robot_description like
#: robot_state_publisher's (transient local, depth 1)
TOPIC_QOS = Qos()
SERVICE_QOS = Qos()
LATCHED_QOS = Qos(durability=TRANSIENT_LOCAL, depth=1)


def mangle(name: str) -> str:
    """A name as one key-expression chunk: ``/`` -> ``%``; the empty name is ``%``."""
    return name.replace("/", "%") if name else "%"


def join(namespace: str, name: str) -> str:
    """The fully qualified name of ``name`` (relative or absolute) in ``namespace``."""
    if name.startswith("/"):
        return name
    return f"{namespace.rstrip('/')}/{name}"


def attachment(sequence: int, gid: bytes, timestamp_ns: int | None = None) -> bytes:
    stamp = time.time_ns() if timestamp_ns is None else timestamp_ns
    return struct.pack("<qq", sequence, stamp) + bytes([len(gid)]) + gid


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp ns, GID) of an rmw_zenoh attachment."""
    if len(data) != ATTACHMENT_SIZE or data[16] != 16:
        raise ValueError(f"not an rmw_zenoh attachment ({len(data)} bytes)")
    sequence, stamp = struct.unpack_from("<qq", data)
    return sequence, stamp, bytes(data[17:33])


#: a reply to send (once) for a request that was answered later
Respond = Callable[[dict[str, Any]], None]
#: a service's handler: the response now, or None and ``respond`` called later (on any thread)
Handler = Callable[[dict[str, Any], Respond], "dict[str, Any] | None"]


class Node:
    """One ROS 2 node on a Zenoh session: its token and its entities' tokens and key expressions."""

    def __init__(self, session: zenoh.Session, name: str, *, namespace: str = "/", domain_id: int = 0,
                 distro: str = "jazzy", enclave: str = "/"):
        if distro not in DISTROS:
            raise ValueError(f"ROS distro {distro!r}: expected one of {', '.join(DISTROS)}")
        if not namespace.startswith("/"):
            namespace = "/" + namespace
        self.session, self.name, self.namespace = session, name, namespace.rstrip("/") or "/"
        self.domain_id, self.distro, self.enclave = domain_id, distro, enclave
        self.zid = str(session.info.zid())
        self._ids = itertools.count(1)
        self.node_id = next(self._ids)
        self._tokens: list[Any] = []
        self._closers: list[Callable[[], None]] = []
        self._tokens.append(session.liveliness().declare_token(self._token_key(self.node_id, "NN")))

    def hash_of(self, type_name: str) -> str:
        return type_hash(type_name) if self.distro in HASHED_DISTROS else NO_HASH

    def topic_key(self, name: str, type_name: str) -> str:
        """The key expression of a topic or service ``name`` (resolved in this node's namespace)."""
        return f"{self.domain_id}/{join(self.namespace, name).strip('/')}/{dds_name(type_name)}/{self.hash_of(type_name)}"

    def _token_key(self, entity_id: int, kind: str, name: str = "", type_name: str = "", qos: Qos | None = None) -> str:
        key = (f"{ADMIN_SPACE}/{self.domain_id}/{self.zid}/{self.node_id}/{entity_id}/{kind}/"
               f"{mangle(self.enclave)}/{mangle(self.namespace if self.namespace != '/' else '')}/{self.name}")
        if name:
            assert qos is not None
            key += (f"/{mangle(join(self.namespace, name))}/{dds_name(type_name)}/{self.hash_of(type_name)}/"
                    f"{qos.keyexpr()}")
        return key

    def _entity(self, kind: str, name: str, type_name: str, qos: Qos) -> bytes:
        """Declare an entity's token; its GID."""
        key = self._token_key(next(self._ids), kind, name, type_name, qos)
        self._tokens.append(self.session.liveliness().declare_token(key))
        return hashlib.sha256(key.encode()).digest()[:16]

    def publisher(self, name: str, type_name: str, qos: Qos = TOPIC_QOS) -> Publisher:
        return Publisher(self, name, type_name, qos)

    def service(self, name: str, service_type: str, handler: Handler, qos: Qos = SERVICE_QOS) -> Service:
        return Service(self, name, service_type, handler, qos)

    def close(self) -> None:
        for close in reversed(self._closers):
            try:
                close()
            except Exception:  # the session may be closed already
                log.debug("closing a ROS entity failed", exc_info=True)
        for token in reversed(self._tokens):
            try:
                token.undeclare()
            except Exception:
                log.debug("undeclaring a ROS token failed", exc_info=True)
        self._tokens.clear()
        self._closers.clear()


class Publisher:
    """A ROS 2 publisher: CDR payloads with the attachment, from a zenoh.ext advanced publisher."""

    def __init__(self, node: Node, name: str, type_name: str, qos: Qos):
        self.type_name = type_name
        self.key = node.topic_key(name, type_name)
        latched = qos.durability == TRANSIENT_LOCAL
        options: dict[str, Any] = {}
        if latched:
            options["cache"] = zenoh.ext.CacheConfig(qos.depth)
            options["publisher_detection"] = True
            if qos.reliability == RELIABLE:
                options["sample_miss_detection"] = zenoh.ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=HEARTBEAT_S)
        self._publisher = zenoh.ext.declare_advanced_publisher(
            node.session, self.key, congestion_control=zenoh.CongestionControl.DROP,
            reliability=zenoh.Reliability.RELIABLE if qos.reliability == RELIABLE else zenoh.Reliability.BEST_EFFORT,
            **options)
        self.gid = node._entity("MP", name, type_name, qos)
        node._closers.append(self._publisher.undeclare)
        self._sequence = itertools.count(1)
        self._lock = threading.Lock()

    def publish(self, message: dict[str, Any]) -> None:
        payload = cdr.serialize(self.type_name, message)
        with self._lock:  # numbers go out in order
            self._publisher.put(payload, attachment=attachment(next(self._sequence), self.gid))


class Service:
    """A ROS 2 service server: a complete queryable; the reply echoes the request's number and GID."""

    def __init__(self, node: Node, name: str, service_type: str, handler: Handler, qos: Qos):
        self.service_type, self.handler = service_type, handler
        self.key = node.topic_key(name, service_type)
        self.gid = node._entity("SS", name, service_type, qos)
        self._queryable = node.session.declare_queryable(self.key, zenoh.handlers.Callback(self._on_query),
                                                         complete=True)
        node._closers.append(self._queryable.undeclare)

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            if query.attachment is None or query.payload is None:
                raise ValueError("a ROS 2 request needs a payload and an attachment")
            sequence, _stamp, client_gid = parse_attachment(query.attachment.to_bytes())
            request = cdr.deserialize(f"{self.service_type}_Request", query.payload.to_bytes())
        except Exception as exc:  # a malformed request: say so to the caller, as an err reply
            log.warning("ROS service %s: %s", self.key, exc)
            query.reply_err(f"rob6: {exc}")
            query.drop()
            return
        answered = threading.Lock()

        def respond(response: dict[str, Any]) -> None:
            if not answered.acquire(blocking=False):
                return  # answered already
            try:
                payload = cdr.serialize(f"{self.service_type}_Response", response)
                query.reply(query.key_expr, payload, attachment=attachment(sequence, client_gid))
            except Exception:  # the session closed, the caller gave up
                log.debug("ROS service %s: the reply could not be sent", self.key, exc_info=True)
            finally:
                query.drop()

        try:
            response = self.handler(request, respond)
        except Exception as exc:
            log.exception("ROS service %s failed", self.key)
            if answered.acquire(blocking=False):
                query.reply_err(f"rob6: {type(exc).__name__}: {exc}")
                query.drop()
            return
        if response is not None:
            respond(response)
