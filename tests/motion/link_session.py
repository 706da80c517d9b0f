"""What the real-time link suites (RSI, simple_message) do as a client of the whole system."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

import numpy as np

from harness.client import Client

R = TypeVar("R")


def reply(client: Client, command: str, timeout: float = 30.0) -> str:
    """The whole reply: one line, or two when the first is an ERROR line."""
    client.send(command + "\n")
    text = client.read_lines(1, timeout)
    return text + client.read_lines(1, timeout) if text.startswith("ERROR") else text


def joints(client: Client) -> np.ndarray:
    return np.array([float(x) for x in client.ask("GetPositionJoints").split()])


def wait_until(predicate: Callable[[], R | None], timeout: float = 20.0, what: str = "condition") -> R:
    """The predicate's first result that is neither None nor False, polled every 20 ms."""
    deadline = time.monotonic() + timeout
    while (result := predicate()) is None or result is False:
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)
    return result

