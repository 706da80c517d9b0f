"""Where the ground truth lives, and the system/client harness (rob6.testing)."""

import os
from pathlib import Path

from rob6.testing import Client, System, free_port, running

__all__ = ["CONFORMANCE", "REPO", "SHARED", "Client", "System", "free_port", "running"]

REPO = Path(__file__).resolve().parents[1]
#: the original server's transcripts, kept with the tests (tests/transcripts/ORIGIN.md)
CONFORMANCE = REPO / "tests" / "transcripts"
#: where they are refreshed from: the ground truth beside the project, when present
SHARED = Path(os.environ.get("ROB6_SHARED", REPO.parent / "shared")).resolve()
