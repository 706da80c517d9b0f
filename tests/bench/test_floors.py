"""The benchmark's floors measure the bare thing: the relay's answer is a real Zenoh query's."""

from __future__ import annotations

from bench.latency import bare_relay, end
from harness.client import Client


def test_relay_answers_each_line_after_a_bare_query() -> None:
    with bare_relay() as (relay_port, server), Client(relay_port, handshake=False) as client:
        assert client.greeting == "welcome\n"
        client.send("one\ntwo\n")
        assert client.read_lines(2) == "pong\npong\n"
        end(server)  # no queryable left: the query gets no answer, and the relay says so
        assert client.ask("three") == "ERROR\n"
