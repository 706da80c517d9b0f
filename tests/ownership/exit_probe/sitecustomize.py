"""A probe for the clean-stop test: at exit, whatever still references a Ruckig object.

Put on PYTHONPATH of a rob6 system, it is imported by every one of its processes. An
object still alive when the interpreter exits is reported by nanobind as leaked, or not,
depending on the order of finalization; this makes it certain: each process that still
holds one when its last ``atexit`` handler runs prints ``leaked at exit`` with the count.
"""

from __future__ import annotations

import atexit
import gc
import sys


def _probe() -> None:
    ruckig = sys.modules.get("ruckig")
    if ruckig is None:
        return
    kinds = (ruckig.Ruckig, ruckig.Trajectory, ruckig.InputParameter, ruckig.OutputParameter)
    alive = sum(1 for holder in gc.get_objects() for held in gc.get_referents(holder) if isinstance(held, kinds))
    if alive:
        print(f"exit probe: {alive} references to Ruckig objects leaked at exit in {sys.argv[0]}",
              file=sys.stderr, flush=True)


atexit.register(_probe)  # the first registered: the last to run
