"""Run every benchmark and print the tables (``make bench``)."""

from __future__ import annotations

import sys

from rob6.testing import running

from .latency import echo_baseline, measure, percentiles

COUNT = 5000


def row(name: str, samples: list[float], target: str) -> str:
    p50, p99 = percentiles(samples)
    return f"| {name:<44} | {p50:8.3f} | {p99:8.3f} | {target:<24} |"


def gateway_table() -> list[str]:
    lines = ["Gateway round trips (ms, %d requests each, one client, TCP_NODELAY)" % COUNT, "",
             f"| {'measurement':<44} | {'p50':>8} | {'p99':>8} | {'target':<24} |",
             f"|{'-' * 46}|{'-' * 10}|{'-' * 10}|{'-' * 26}|"]
    lines.append(row("bare asyncio TCP echo (baseline)", echo_baseline(COUNT), "floor"))
    with running("kr16", dummy=True) as system:
        with system.client() as client:
            lines.append(row("CM_PING (gateway only)", measure(client, "CM_PING", 1, COUNT),
                             "p50<=0.15 p99<=0.5"))
            lines.append(row("GetPositionJoints (gateway, live state)",
                             measure(client, "GetPositionJoints", 1, COUNT), "p50<=0.6"))
            lines.append(row("PingRobot 1 0 (one bus round trip to driver)",
                             measure(client, "PingRobot 1 0", 1, COUNT), "p50<=0.6 p99<=2"))
            lines.append(row("ForwardCalc (bus to kinematics, 2-line reply)",
                             measure(client, "ForwardCalc 10 20 30 40 50 60", 2, COUNT), "p50<=0.6"))
    return lines


def main() -> int:
    for line in gateway_table():
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
