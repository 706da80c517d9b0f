"""A Foxglove viewer in a process of its own, the subscriber of the live-view benchmark.

A Foxglove viewer in a process of its own, for the live-view benchmark: a real viewer
(Foxglove Studio) is a separate program, usually on another machine, and decoding every
message in the measuring process would charge its cost to the gateway round trips.

    python -m bench.viewer ws://127.0.0.1:8765

Subscribes to ``/tf`` and ``/driver/joint_state`` and prints ``ready``; on a line ``all``
on stdin subscribes to every advertised channel and prints ``subscribed``; at the end of
stdin prints the number of messages received and exits.
"""

from __future__ import annotations

import subprocess
import sys


class Viewer:
    """This program as a subprocess: ``Viewer(url)`` returns once it is connected."""

    def __init__(self, url: str) -> None:
        self.process = subprocess.Popen([sys.executable, "-m", "bench.viewer", url],
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        if self._says() != "ready":
            self.process.kill()
            raise RuntimeError("the Foxglove viewer did not connect")

    def subscribe_all(self) -> None:
        """Subscribe to every channel advertised by now."""
        self._says("all")

    def close(self) -> int:
        """Disconnect; the number of messages received."""
        try:
            return int(self._says(None))
        finally:
            self.process.kill()
            self.process.wait()

    def _says(self, line: str | None = "") -> str:
        """Send ``line`` (None: end the input) and read the answer."""
        assert self.process.stdin is not None and self.process.stdout is not None  # both are pipes
        if line is None:
            self.process.stdin.close()
        elif line:
            self.process.stdin.write(line + "\n")
            self.process.stdin.flush()
        return self.process.stdout.readline().strip()


def main(url: str) -> None:
    from harness.foxglove_client import FoxgloveClient

    with FoxgloveClient(url) as viewer:
        viewer.subscribe(*viewer.wait_topics(["/tf", "/driver/joint_state"]))
        print("ready", flush=True)
        for line in sys.stdin:
            if line.strip() == "all":
                viewer.subscribe(*(t for t in viewer.topics() if t not in viewer._subs.values()))
                print("subscribed", flush=True)
        with viewer._lock:
            print(sum(len(v) for v in viewer.messages.values()), flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
