#!/usr/bin/env python3
"""netem in user space: delay, jitter, loss and reordering of the packets iptables queues.

Why: the kernels of some CI machines and VMs have no ``sch_netem`` (``tc qdisc add ... netem``
answers "Specified qdisc kind is unknown"), but every Linux with netfilter has NFQUEUE. This
program takes the packets an iptables rule puts in a queue and gives each its verdict later:

    iptables -I OUTPUT -d 10.5.0.2 -j NFQUEUE --queue-num 7 --queue-bypass
    iptables -I INPUT  -s 10.5.0.2 -j NFQUEUE --queue-num 7 --queue-bypass
    nfq_netem.py --queue 7 --delay-ms 5 --jitter-ms 2 --loss 0.05 --reorder 0.25

Every queued packet is held ``delay ± jitter`` ms (uniform, like netem without a distribution
table; jitter larger than the gaps between packets reorders them, as netem does) and dropped
with probability ``loss``, then accepted; with probability ``reorder`` a packet is not held
at all, so it overtakes the ones held before it (netem's ``reorder``). With the two rules above, each direction between
this network namespace and 10.5.0.2 gets the delay: ``--delay-ms 5`` is 5 ms one way, 10 ms
round trip. Run it inside the namespace of the "host" to slow down, e.g. from the machine:
``nsenter -t <pid of the container> -n python3 nfq_netem.py ...`` (needs root: CAP_NET_ADMIN).
``--queue-bypass`` lets packets through when this program is not running.

Only the standard library (raw netlink), one thread; SIGTERM/SIGINT: every held packet is
released at once and the queue unbound. Prints one line per second with ``--stats``.
"""

from __future__ import annotations

import argparse
import heapq
import os
import random
import select
import signal
import socket
import struct
import sys
import time

NETLINK_NETFILTER = 12
NFNL_SUBSYS_QUEUE = 3
NFQNL_MSG_PACKET, NFQNL_MSG_VERDICT, NFQNL_MSG_CONFIG = 0, 1, 2
NFQA_PACKET_HDR = 1
NFQA_VERDICT_HDR = 2
NFQA_CFG_CMD, NFQA_CFG_PARAMS, NFQA_CFG_QUEUE_MAXLEN = 1, 2, 3
NFQNL_CFG_CMD_BIND, NFQNL_CFG_CMD_UNBIND = 1, 2
NFQNL_COPY_META = 1
NLM_F_REQUEST, NLM_F_ACK = 1, 4
NLMSG_ERROR = 2
NF_DROP, NF_ACCEPT = 0, 1


def _attr(kind: int, data: bytes) -> bytes:
    raw = struct.pack("=HH", 4 + len(data), kind) + data
    return raw + b"\0" * (-len(raw) % 4)


class Queue:
    """One bound NFQUEUE (packet metadata only: the payload is never copied)."""

    def __init__(self, number: int):
        self.number = number
        self.sock = socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, NETLINK_NETFILTER)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.bind((0, 0))
        self.seq = 0
        self._config(_attr(NFQA_CFG_CMD, struct.pack("!BxH", NFQNL_CFG_CMD_BIND, 0)))
        self._config(_attr(NFQA_CFG_PARAMS, struct.pack("!IB", 0, NFQNL_COPY_META)))
        self._config(_attr(NFQA_CFG_QUEUE_MAXLEN, struct.pack("!I", 8192)))

    def _send(self, msg_type: int, body: bytes, flags: int = NLM_F_REQUEST) -> None:
        self.seq += 1
        payload = struct.pack("!BBH", socket.AF_UNSPEC, 0, self.number) + body
        header = struct.pack("=IHHII", 16 + len(payload), (NFNL_SUBSYS_QUEUE << 8) | msg_type, flags, self.seq, 0)
        self.sock.send(header + payload)

    def _config(self, body: bytes) -> None:
        self._send(NFQNL_MSG_CONFIG, body, NLM_F_REQUEST | NLM_F_ACK)
        while True:  # the ack (an NLMSG_ERROR with error 0) or the refusal
            data = self.sock.recv(65536)
            length, kind = struct.unpack_from("=IH", data)
            if kind == NLMSG_ERROR:
                (error,) = struct.unpack_from("=i", data, 16)
                if error:
                    raise OSError(-error, f"NFQUEUE {self.number} config: {os.strerror(-error)}")
                return

    def packets(self) -> list[int]:
        """Packet ids of whatever is waiting (non-blocking after select)."""
        ids = []
        data = self.sock.recv(1 << 20)
        offset = 0
        while offset + 16 <= len(data):
            length, kind = struct.unpack_from("=IH", data, offset)
            if length < 16:
                break
            if kind == (NFNL_SUBSYS_QUEUE << 8) | NFQNL_MSG_PACKET:
                pos = offset + 20  # nlmsghdr + nfgenmsg
                while pos + 4 <= offset + length:
                    alen, atype = struct.unpack_from("=HH", data, pos)
                    if alen < 4:
                        break
                    if atype & 0x7FFF == NFQA_PACKET_HDR:
                        ids.append(struct.unpack_from("!I", data, pos + 4)[0])
                    pos += (alen + 3) & ~3
            offset += (length + 3) & ~3
        return ids

    def verdict(self, packet_id: int, verdict: int) -> None:
        self._send(NFQNL_MSG_VERDICT, _attr(NFQA_VERDICT_HDR, struct.pack("!II", verdict, packet_id)))

    def close(self) -> None:
        try:
            self._send(NFQNL_MSG_CONFIG, _attr(NFQA_CFG_CMD, struct.pack("!BxH", NFQNL_CFG_CMD_UNBIND, 0)))
        finally:
            self.sock.close()


def run(queue: Queue, delay: float, jitter: float, loss: float, reorder: float, stats: bool) -> None:
    held: list[tuple[float, int, int]] = []  # (release time, order, packet id)
    order = 0
    stop = False
    counts = {"passed": 0, "dropped": 0}

    def on_signal(*_: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    next_stats = time.monotonic() + 1
    while not stop:
        now = time.monotonic()
        while held and held[0][0] <= now:
            queue.verdict(heapq.heappop(held)[2], NF_ACCEPT)
            counts["passed"] += 1
        wait = max(0.0, held[0][0] - now) if held else 0.5
        try:
            ready, _, _ = select.select([queue.sock], [], [], wait)
        except InterruptedError:
            continue
        if ready:
            arrived = time.monotonic()
            for packet_id in queue.packets():
                if loss and random.random() < loss:
                    queue.verdict(packet_id, NF_DROP)
                    counts["dropped"] += 1
                    continue
                hold = max(0.0, delay + random.uniform(-jitter, jitter)) if jitter else delay
                if reorder and random.random() < reorder:
                    hold = 0.0
                if hold <= 0:
                    queue.verdict(packet_id, NF_ACCEPT)
                    counts["passed"] += 1
                    continue
                order += 1
                heapq.heappush(held, (arrived + hold, order, packet_id))
        if stats and time.monotonic() >= next_stats:
            next_stats += 1
            print(f"nfq_netem queue {queue.number}: {counts} held {len(held)}", flush=True)
    for _release, _order, packet_id in held:  # let everything go on the way out
        queue.verdict(packet_id, NF_ACCEPT)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--queue", type=int, default=0, help="NFQUEUE number (iptables --queue-num)")
    parser.add_argument("--delay-ms", type=float, default=0.0, help="added delay per packet")
    parser.add_argument("--jitter-ms", type=float, default=0.0, help="± uniform around the delay")
    parser.add_argument("--loss", type=float, default=0.0, help="drop probability per packet, 0..1")
    parser.add_argument("--reorder", type=float, default=0.0,
                        help="probability per packet of being sent at once, overtaking held ones, 0..1")
    parser.add_argument("--stats", action="store_true", help="one line of counts per second")
    args = parser.parse_args(argv)
    try:
        queue = Queue(args.queue)
    except OSError as exc:
        print(f"nfq_netem: cannot bind NFQUEUE {args.queue}: {exc} (root / CAP_NET_ADMIN needed)", file=sys.stderr)
        return 1
    print(f"nfq_netem: queue {args.queue} delay {args.delay_ms} ms ± {args.jitter_ms} ms loss {args.loss:.1%} "
          f"reorder {args.reorder:.1%}", flush=True)
    try:
        run(queue, args.delay_ms / 1000, args.jitter_ms / 1000, args.loss, args.reorder, args.stats)
    finally:
        queue.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
