"""A fake rob6 TCP server: an asyncio loop in a thread answering each line as a handler says.

The recording tests replay sessions against it, and bench/bench_recording.py uses it as the
replay target.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable

__all__ = ["GREETING", "FakeServer", "Handler"]

#: the greeting of rob6 and the original rob6server
GREETING = "welcome to rob6server 0.1.01 !\n"

#: a fake server's answer to one received chunk of connection n: (reply bytes, close after it)
Handler = Callable[[int, bytes], tuple[bytes, bool]]


class FakeServer:
    """A rob6-like TCP server on 127.0.0.1 run by an asyncio loop in a thread.

    ``handler(connection_index, message_bytes) -> (reply_bytes, close_after)`` is
    called for each line (``per_line=True``) or each received chunk.
    """

    def __init__(self, handler: Handler,
                 greeting: str = GREETING, per_line: bool = True) -> None:
        self.handler = handler
        self.greeting = greeting
        self.per_line = per_line
        self.connections = 0
        self.received: list[bytes] = []
        self.loop = asyncio.new_event_loop()
        self.port = 0
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.server = self.loop.run_until_complete(
            asyncio.start_server(self._client, "127.0.0.1", 0))
        self.port = self.server.sockets[0].getsockname()[1]
        self._ready.set()
        self.loop.run_forever()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        index = self.connections
        self.connections += 1
        writer.write(self.greeting.encode("latin-1"))
        await writer.drain()
        buf = b""
        try:
            while True:
                data = await reader.read(4096)
                if not data:
                    break
                messages = []
                if self.per_line:
                    buf += data
                    while b"\n" in buf:
                        line, buf = buf.split(b"\n", 1)
                        messages.append(line + b"\n")
                else:
                    messages.append(data)
                for msg in messages:
                    self.received.append(msg)
                    reply, close = self.handler(index, msg)
                    if reply:
                        writer.write(reply)
                        await writer.drain()
                    if close:
                        writer.close()
                        return
        except (asyncio.CancelledError, ConnectionError):
            pass
        finally:
            writer.close()

    def __enter__(self) -> FakeServer:
        self._thread.start()
        self._ready.wait(5)
        return self

    def __exit__(self, *exc: object) -> None:
        async def stop() -> None:
            self.server.close()
            await self.server.wait_closed()
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self.loop.stop()
        asyncio.run_coroutine_threadsafe(stop(), self.loop)
        self._thread.join(5)
        self.loop.close()
