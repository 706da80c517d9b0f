"""Where the ground truth lives, and the system/client harness (rob6.testing)."""

import os
from pathlib import Path

from rob6.testing import Client, System, free_port, running  # noqa: F401

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("ROB6_SHARED", REPO.parent / "shared")).resolve()
CONFORMANCE = SHARED / "conformance"
