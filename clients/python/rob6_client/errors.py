"""The error model: what the server said, and what happened to the connection."""

from __future__ import annotations


class Rob6Error(Exception):
    """The server answered ``ERROR: <message>`` (a refused or malformed command).

    The connection stays usable. ``command`` is the protocol name (``MovePTPJoints``),
    ``message`` the server's text after ``ERROR: `` (``incorrect joints``,
    ``planner unavailable``...).
    """

    def __init__(self, command: str, message: str) -> None:
        super().__init__(f"{command}: {message}")
        self.command = command
        self.message = message


class Rob6ConnectionError(ConnectionError):
    """No usable connection: refused, handshake failed, closed by the server, or closed
    by this client because replies could no longer be matched to commands."""


class Rob6Timeout(Rob6ConnectionError, TimeoutError):
    """No complete reply within the timeout. The connection is closed: a reply arriving
    later would otherwise be taken for the answer to the next command."""


class Rob6ProtocolError(Rob6ConnectionError):
    """A reply this library does not understand; the connection is closed (see Rob6Timeout)."""
