"""Errors of bus calls: what a failed request raises, and why an instance was given up on."""

from __future__ import annotations

from ..errors import ServiceError
from ..messages import ErrorCode


class BusError(ServiceError):
    """A request that failed: ``code`` is machine-readable, ``message`` is for humans."""

    def __init__(self, code: ErrorCode, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


class BusTimeout(BusError):
    """A live instance did not answer in time: ``seconds`` waited, ``waiting_for`` what the
    service said it waited for ("" when it said nothing: a quick call)."""

    def __init__(self, service: str, op: str, seconds: float, waiting_for: str):
        detail = f" ({waiting_for})" if waiting_for else ""
        super().__init__("timeout", f"{service}: no reply to {op} within {seconds:.1f} s{detail}")
        self.service, self.op, self.seconds, self.waiting_for = service, op, seconds, waiting_for


class CallAbandoned(ServiceError):
    """The caller gave up on a request (``Bus.request``'s ``abandon``); its query is cancelled."""


class _InstanceLost(Exception):
    """The instance vanished (``gone``) or did not answer; the request may be retried elsewhere."""

    def __init__(self, message: str, gone: bool = False):
        super().__init__(message)
        self.gone = gone

