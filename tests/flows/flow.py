"""A client flow against a running rob6: lines sent with a real client's reading habit,
every exchange kept, and the session's MCAP log compared with what went over the wire.

A flow reads the way the client it stands for reads, so a reply with a line too many or
too few shows as the wrong text in the next reply, never as a hidden timeout:

* ``fixed(line, n)``: send one line, read exactly ``n`` lines (rob-chess, Scala);
* ``one(line)``: send one line, wait for one line (RobPraktikum, followme);
* ``pipelined([(line, n), ...])``: every line in one write, then the replies in order.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from harness.client import Client
from rob6_recorder.reader import read_records

GREETING = "welcome to rob6server 0.1.01 !\n"


@dataclass
class Exchange:
    """One line the client sent and the whole reply it read for it."""

    line: str  # without its "\n"
    reply: str  # "" when the command answers nothing (SetAllowedStatus)


@dataclass
class Flow:
    """One client session, opened with the greeting read as the clients read it (one line)."""

    port: int
    timeout: float = 60.0
    exchanges: list[Exchange] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.client = Client(self.port, handshake=False, timeout=self.timeout)
        host, port = self.client.sock.getsockname()[:2]
        self.peer = f"{host}:{port}"  # how the gateway names this session in the recording
        assert self.client.greeting == GREETING, self.client.greeting

    def fixed(self, line: str, count: int) -> list[str]:
        """Send ``line``, read exactly ``count`` lines (a short read is an error, not a wait)."""
        self.client.send(line + "\n")
        return self._read(line, count)

    def one(self, line: str) -> str:
        """Send-and-wait: one line out, one line back, without its newline."""
        return self.fixed(line, 1)[0]

    def pipelined(self, items: list[tuple[str, int]]) -> list[list[str]]:
        """Every line in one write, then each reply's ``count`` lines in order; ``""`` sends an
        empty line (answered with nothing and not recorded), a count of 0 reads nothing."""
        self.client.send("".join(line + "\n" for line, _ in items))
        replies = []
        for line, count in items:
            if line:
                replies.append(self._read(line, count))
            else:
                assert count == 0, "an empty line is answered with nothing"
        return replies

    def _read(self, line: str, count: int) -> list[str]:
        text = self.client.read_lines(count) if count else ""
        assert text.count("\n") == count, f"{line!r}: {count} lines expected, got {text!r} within {self.timeout} s"
        self.exchanges.append(Exchange(line, text))
        return text.splitlines()

    def quiet(self) -> None:
        """Nothing more came than the flow read: no reply was longer than its count."""
        assert self.client.read_quiet(0.3) == ""

    def close(self) -> None:
        self.client.close()

    def __enter__(self) -> Flow:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()  # a flow that failed half-way leaves the server to the next one


def numbers(text: str) -> np.ndarray:
    return np.array([float(x) for x in text.split()])


def fmt(values: Any) -> str:
    return " ".join(f"{x:f}" for x in values)


def session_records(log_dir: Path, peer: str, timeout: float = 20.0) -> list[Any]:
    """The records of the session file of the session whose client was ``peer``, once the
    recorder has written its close event (it finishes a session file after the client left)."""
    deadline = time.monotonic() + timeout
    while True:
        for path in sorted(log_dir.glob("*_session*.mcap")):
            records = list(read_records(path))
            opened = [r for r in records if r.topic.endswith("/event") and r.data["event"] == "open"]
            if opened and opened[0].data["peer"] == peer:
                if any(r.topic.endswith("/event") and r.data["event"] == "close" for r in records):
                    return records
                break
        assert time.monotonic() < deadline, f"no finished session file of {peer} in {log_dir}"
        time.sleep(0.2)


def assert_recorded(log_dir: Path, flow: Flow) -> None:
    """The session's MCAP file holds the complete exchange log of ``flow``: the open event
    with the greeting, every line in and its reply out (byte for byte, numbered 1..n without
    a gap or a repeat), then the close event, and nothing else from the client."""
    records = session_records(log_dir, flow.peer)
    events = sorted((r for r in records if r.topic.endswith("/event")), key=lambda r: r.log_time)
    assert [e.data["event"] for e in events] == ["open", "close"], [e.data for e in events]
    number = events[0].data["session"]
    outs = [r for r in records if r.topic == f"/session/{number}/client_out"]
    greetings = [r.data for r in outs if r.data.get("kind") == "greeting"]
    assert greetings == [{"session": number, "cid": "", "text": GREETING, "kind": "greeting"}]
    ins = sorted((r for r in records if r.topic == f"/session/{number}/client_in"), key=lambda r: r.data["seq"])
    replies = sorted((r for r in outs if "seq" in r.data), key=lambda r: r.data["seq"])
    assert [r.data["seq"] for r in ins] == list(range(1, len(flow.exchanges) + 1)), "a gap or a repeat"
    assert [r.data["seq"] for r in replies] == [r.data["seq"] for r in ins]
    recorded = [Exchange(i.data["text"][:-1], o.data["text"]) for i, o in zip(ins, replies, strict=True)]
    assert recorded == flow.exchanges
    assert all(i.data["cid"] == o.data["cid"] and i.data["peer"] == flow.peer
               for i, o in zip(ins, replies, strict=True))
    assert events[0].log_time <= ins[0].log_time and replies[-1].log_time <= events[1].log_time
