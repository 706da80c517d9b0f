"""A joint-state recorder on the robot PC: a container in the robot PC's network namespace
(``docker run --network container:<robot-pc>``) that prints every ``driver/state`` sample as a
JSON line, so a motion can be compared sample by sample whatever happens to the storage host.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from harness.compose import run
from harness.images import TAG
from harness.topology import Topology

SCRIPT = r"""
import json, signal, sys, threading, zenoh
conf = zenoh.Config()
# a peer like the robot PC's services, linked to the driver directly: what a client of the
# router receives depends on the router, which a partition of the other hosts can hold up
conf.insert_json5("mode", '"peer"')
conf.insert_json5("connect/endpoints", '["tcp/127.0.0.1:7447"]')
conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)
def on_sample(sample):
    s = json.loads(sample.payload.to_bytes())
    # a joint state leaves out fields at their defaults (mode idle, missed 0)
    print(json.dumps([s["cycle"], s["q"], s.get("mode", "idle"), s.get("missed", 0)]), flush=True)
sub = session.declare_subscriber("rob6/robot1/driver/state", on_sample)
print("ready", flush=True)
stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
stop.wait()
session.close()
"""


@dataclass
class Sample:
    cycle: int
    q: list[float]
    mode: str
    missed: int


class StateRecorder:
    def __init__(self, topology: Topology, name: str) -> None:
        self.topology = topology
        self.name = f"{topology.project}-{name}"

    def __enter__(self) -> StateRecorder:
        robot_pc = self.topology.container("robot-pc")
        run(["docker", "run", "-d", "--name", self.name, "--network", f"container:{robot_pc}",
             f"rob6/router:{TAG}", "python3", "-c", SCRIPT])
        import time
        deadline = time.monotonic() + 20
        while "ready" not in run(["docker", "logs", self.name]).stdout:
            if time.monotonic() > deadline:
                raise RuntimeError(f"state recorder did not start: {run(['docker', 'logs', self.name]).stderr}")
            time.sleep(0.2)
        return self

    def stop(self) -> list[Sample]:
        run(["docker", "stop", "-t", "3", self.name], check=False)
        out = run(["docker", "logs", self.name]).stdout.splitlines()
        run(["docker", "rm", "-f", self.name], check=False)
        samples = []
        for line in out:
            if line.startswith("["):
                cycle, q, mode, missed = json.loads(line)
                samples.append(Sample(cycle, q, mode, missed))
        samples.sort(key=lambda s: s.cycle)
        return samples

    def __exit__(self, *exc: object) -> None:
        run(["docker", "rm", "-f", self.name], check=False)


def same_motion(reference: list[Sample], other: list[Sample], until: int, shifts: int = 3) -> bool:
    """Whether ``other`` holds the same joint positions as ``reference`` at the same cycles
    counted from where each motion starts, over the first ``until`` cycles of the reference's
    motion. Samples the probe did not receive (a state is dropped, never queued, under
    congestion) are skipped, at most one in ten; a missed first sample is allowed for by
    trying the start up to ``shifts`` cycles either way."""
    def by_cycle(samples: list[Sample]) -> dict[int, list[float]]:
        first = samples[0].q
        start = next((i for i, s in enumerate(samples) if s.q != first), len(samples))
        # the cycle before the first that moved (at rest the driver publishes only every few cycles)
        origin = samples[min(start, len(samples) - 1)].cycle - 1
        return {s.cycle - origin: s.q for s in samples}

    ref, oth = by_cycle(reference), by_cycle(other)
    for shift in range(-shifts, shifts + 1):
        common = [c for c in range(until) if c in ref and c + shift in oth]
        if len(common) >= 0.9 * until and all(ref[c] == oth[c + shift] for c in common):
            return True
    return False


def motion(samples: list[Sample]) -> list[list[float]]:
    """The joint positions from the first sample that differs from the first one to the last
    that differs from the last one (the motion itself, whatever the idle time around it)."""
    if not samples:
        return []
    first, last = samples[0].q, samples[-1].q
    start = next((i for i, s in enumerate(samples) if s.q != first), len(samples))
    end = max((i for i, s in enumerate(samples) if s.q != last), default=-1)
    return [s.q for s in samples[max(0, start - 1):end + 2]]
