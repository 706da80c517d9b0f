"""The client's parsers against every reply the original rob6server gave in the transcripts.

No network: each recorded reply goes through ``parse_reply``, which drives the same
exchange generators ``Robot`` and ``AsyncRobot`` use. Every reply of a command the library
covers must parse completely (no line left over), and exactly the ``ERROR:`` replies
must raise Rob6Error.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Iterator
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest

from rob6_client import COMMANDS, ROB6_ONLY, Rob6ConnectionError, Rob6Error, normalize_status, parse_reply
from rob6_client.protocol import handshake, run_offline
from tests.conformance import CONFORMANCE

FILES = sorted(CONFORMANCE.glob("*/*.jsonl"))
MAX_MESSAGE = 1024  # the original reads at most this much per message (longer sends are split)


def command_word(sent: str) -> str | None:
    """The command the original executed: the first word of the message up to a NUL."""
    words = sent.split("\0", maxsplit=1)[0].split()
    return words[0] if words else None


def covered_records(path: Path) -> Iterator[tuple[str, dict[str, Any], str | list[str]]]:
    """(kind, record, reply to parse) for the records whose reply the library must understand.

    Left out: a command left waiting for its missing arguments (`no_reply_within_ms`) and
    the record after it, whose reply belongs to the waiting command; the original crashing
    (no reply, connection closed); sends longer than one message; unknown commands.
    A SetAllowedStatus with words and no reply is its success: the library's CM_PING probe
    would have been answered with PONG.
    """
    records = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]
    greeting, tainted = None, False
    for record in records:
        if "connect" in record:
            greeting, tainted = record["greeting"], False
            continue
        if "send" not in record:
            continue
        sent, reply = record["send"], record["reply"].removesuffix("<EOF>\n")  # EOF marker of some files
        if greeting is not None:  # the first message of a connection is the handshake
            yield "handshake", record, [greeting.removesuffix("\n"), *reply.split("\n")[:-1]]
            greeting = None
            continue
        name = command_word(sent)
        waiting = "no_reply_within_ms" in record
        skip, tainted = tainted, waiting
        if skip or name not in COMMANDS or len(sent.encode("latin-1")) > MAX_MESSAGE:
            continue
        if name == "SetAllowedStatus":
            if waiting and len(sent.split()) > 1:  # silent success, not waiting
                tainted = False
                yield name, record, reply + "PONG\n"
            elif not waiting:
                yield name, record, reply + "PONG\n"
        elif not waiting and reply:
            yield name, record, reply


@pytest.mark.parametrize("path", FILES, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_every_recorded_reply_parses(path: Path) -> None:
    checked: Counter[str] = Counter()
    for name, record, reply in covered_records(path):
        if name == "handshake":
            assert isinstance(reply, list)
            accepted = reply[1:] == ["accepted"]
            if accepted:
                assert run_offline(name, handshake(), reply) == reply[0]
            else:
                with pytest.raises(Rob6ConnectionError, match="handshake failed"):
                    run_offline(name, handshake(), reply)
            continue
        assert isinstance(reply, str)
        try:
            value = parse_reply(name, reply)
        except Rob6Error as exc:
            assert reply.startswith("ERROR: "), (record, exc)
            assert reply.split("\n")[0] == f"ERROR: {exc.message}"
        else:
            assert not reply.startswith("ERROR"), record
            if value is not None and COMMANDS[name].reply.returns == "Joints":
                assert len(value) == 6 and all(isinstance(v, float) for v in value)
        checked[name] += 1
    assert checked or path.stem in ("framing_wait",), "no reply of this file was checked"


def test_the_transcripts_exercise_every_reply_shape() -> None:
    """The corpus is big enough to stand for the original: nearly every command, every shape."""
    commands, shapes, total = set(), set(), 0
    for path in FILES:
        for name, _, _ in covered_records(path):
            if name != "handshake":
                commands.add(name)
                shapes.add(COMMANDS[name].reply.returns)
                total += 1
    assert total > 20000
    assert commands == set(COMMANDS) - ROB6_ONLY, sorted(set(COMMANDS) - ROB6_ONLY - commands)
    assert {"bool", "str", "int", "float", "Joints", "Joints | None", "Pose", "Status",
            "tuple[Pose, Status] | None", "PingResult | None", "None"} <= shapes


def test_set_allowed_status_normalises_like_the_original() -> None:
    """After a successful SetAllowedStatus the original's GetAllowedStatus shows the pattern
    in hand/elbow/arm order with missing categories toggled: what normalize_status sends."""
    compared = 0
    for path in FILES:
        records = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]
        for first, second in pairwise(records):
            words = first.get("send", "").split()[1:4]  # the original ignores a 4th word
            if (first.get("send", "").startswith("SetAllowedStatus ") and first["reply"] == ""
                    and second.get("send") == "GetAllowedStatus\n"):
                assert parse_reply("GetAllowedStatus", second["reply"]) == normalize_status(words), first
                compared += 1
    assert compared >= 30
