"""What the real-time link suites (RSI, simple_message) do as a client of the whole system."""

from __future__ import annotations

import time

import numpy as np


def reply(client, command: str, timeout: float = 30.0) -> str:
    """The whole reply: one line, or two when the first is an ERROR line."""
    client.send(command + "\n")
    text = client.read_lines(1, timeout)
    return text + client.read_lines(1, timeout) if text.startswith("ERROR") else text


def joints(client) -> np.ndarray:
    return np.array([float(x) for x in client.ask("GetPositionJoints").split()])


def wait_until(predicate, timeout: float = 20.0, what: str = "condition"):
    """The predicate's first result that is neither None nor False, polled every 20 ms."""
    deadline = time.monotonic() + timeout
    while (result := predicate()) is None or result is False:
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)
    return result
