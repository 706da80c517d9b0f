"""The benchmark's floors measure the bare thing: the relay's answer is a real Zenoh query's."""

from __future__ import annotations

from bench.latency import bare_process, bare_queryable, end, peer_config
from harness.client import Client
from harness.ports import free_port


def test_relay_answers_each_line_after_a_bare_query() -> None:
    port, relay_port = free_port(), free_port()
    server = bare_queryable(peer_config(**{"listen/endpoints": [f"tcp/127.0.0.1:{port}"]}))
    relay = bare_process("relay", peer_config(**{"connect/endpoints": [f"tcp/127.0.0.1:{port}"]}), str(relay_port))
    try:
        with Client(relay_port, handshake=False) as client:
            assert client.greeting == "welcome\n"
            client.send("one\ntwo\n")
            assert client.read_lines(2) == "pong\npong\n"
            end(server)  # no queryable left: the query gets no answer, and the relay says so
            assert client.ask("three") == "ERROR\n"
        end(relay)
    finally:
        for process in (server, relay):
            process.kill()
            process.wait()
