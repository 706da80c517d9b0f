"""Build the rob6 images (``rob6/<name>:TAG``) with ``deploy/build-images.sh``, and say why when it fails.

tests/conftest.py calls ``build`` once per test run, before the first test marked ``docker``
and outside any test's timeout (a cold build takes far longer than pytest's 300 s per test);
bench/multihost.py calls it before its run. ``deploy/build-images.sh`` (``make images``) is
the one place that knows how to build them.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "deploy" / "build-images.sh"
#: the tag of the images the tests build and run (rob6/<name>:e2e)
TAG = os.environ.get("ROB6_TAG", "e2e")
BASE_IMAGE = os.environ.get("ROB6_BASE_IMAGE", "rob6/base:bookworm")
#: a cold build on this project's 2-core machine took 4.5 min with other work running
#: (deploy/README.md): eight times that, so a slow day does not fail it, and a hung build ends
BUILD_TIMEOUT_S = 2400


@dataclass
class Outcome:
    """What the one build of this test run did: its steps' lines, or why it failed."""

    seconds: float = 0.0
    steps: list[str] = field(default_factory=list)
    error: str | None = None


def docker_missing() -> str | None:
    """Why no image can be built here (None: it can)."""
    if not shutil.which("docker"):
        return "no docker command here"
    if subprocess.run(["docker", "info"], capture_output=True, check=False, timeout=60).returncode != 0:
        return "no Docker engine answers"
    return None


def build() -> Outcome:
    """Run deploy/build-images.sh for TAG; its step lines, or its failure in one line."""
    start = time.monotonic()
    env = {**os.environ, "ROB6_TAG": TAG, "ROB6_BASE_IMAGE": BASE_IMAGE}
    try:
        proc = subprocess.run(["bash", str(SCRIPT)], capture_output=True, check=False, text=True, env=env, cwd=REPO,
                              timeout=BUILD_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return Outcome(time.monotonic() - start, error=f"{SCRIPT.name} did not finish in {BUILD_TIMEOUT_S} s")
    steps = [line for line in proc.stdout.splitlines() if line.startswith("build-images: ")]
    outcome = Outcome(time.monotonic() - start, steps)
    if proc.returncode != 0:
        last = [line for line in (proc.stderr + proc.stdout).splitlines() if line.strip()][-1:] or ["(no output)"]
        outcome.error = f"{SCRIPT.name} exited {proc.returncode}: {last[0].strip()[:300]}"
    return outcome
