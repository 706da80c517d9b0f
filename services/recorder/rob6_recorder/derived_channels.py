"""The Foxglove channels derived from each joint state (/tf, /flange), and when they are written.

The Foxglove channels derived from each joint state, and when: per-link ``/tf`` from the
URDF and, with a forward-kinematics callable, ``/flange`` and an ``fk_flange`` frame on
``/tf`` (the computation itself: ``transforms.py``).

Runs in the recorder's ``submit`` of a joint state, so it keeps itself cheap: at most
``tf_max_rate`` derivations a second; an FK callable that raises is not called again (one
warning), one that takes over 20 ms is paused for 5 s (a remote call must not hold up the
recording).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from typing import Any

import msgspec

from .payloads import as_dict
from .transforms import Fk, TfDeriver, flange_message

log = logging.getLogger("rob6.recorder")

TF_TOPIC = "/tf"
FLANGE_TOPIC = "/flange"
FK_FLANGE_FRAME = "fk_flange"

_encoder = msgspec.json.Encoder()


class JointStateDerivation:
    """Joint state -> the derived records ``(topic, payload)``; see the module docstring."""

    def __init__(self, urdf: str | None, fk: Fk | None,
                 joint_map: Sequence[tuple[float, float]] | None = None, tf_max_rate: float = 50.0):
        self.fk = fk
        self.tf: TfDeriver | None = None
        if urdf:
            try:
                self.tf = TfDeriver(urdf, joint_map)
            except Exception as exc:  # a bad URDF must not stop the recording
                log.warning("URDF not usable for /tf (%s); recording without /tf", exc)
        self.period_ns = int(1e9 / tf_max_rate) if tf_max_rate > 0 else 0
        self._last_ns = -1 << 62
        self._fk_failed = False
        self._fk_pause = 0.0

    @property
    def active(self) -> bool:
        """Whether there is anything to derive (a usable URDF or an FK)."""
        return self.tf is not None or self.fk is not None

    def derive(self, data: Any, log_time: int) -> list[tuple[str, bytes]]:
        """The records derived from one joint state (JSON bytes, a dict or a Struct with
        ``q``), none when rate limited or without joints."""
        if log_time - self._last_ns < self.period_ns:
            return []
        self._last_ns = log_time
        state = as_dict(data)  # after the rate check: most joint states are not decoded
        q = state.get("q") if isinstance(state, dict) else None
        if not q:
            return []
        root = self.tf.root_frame if self.tf is not None else "base"
        tf = self.tf.transforms(q, log_time) if self.tf is not None else {"transforms": []}
        flange = None
        if self.fk is not None and not self._fk_failed and time.monotonic() >= self._fk_pause:
            began = time.monotonic()
            try:
                flange = flange_message(self.fk, q, log_time, root)
            except Exception as exc:
                self._fk_failed = True  # one warning, then no more FK calls
                log.warning("fk callable failed (%r): no /flange from now on", exc)
            took = time.monotonic() - began
            if took > 0.02:  # the recording must not wait on a slow FK (a remote call?)
                self._fk_pause = time.monotonic() + 5.0
                log.warning("fk callable took %.0f ms: /flange paused for 5 s", took * 1000)
            if flange is not None:
                pose = flange["poses"][0]
                tf["transforms"].append({
                    "timestamp": flange["timestamp"], "parent_frame_id": root,
                    "child_frame_id": FK_FLANGE_FRAME, "translation": pose["position"],
                    "rotation": pose["orientation"]})
        out = []
        if tf["transforms"]:
            out.append((TF_TOPIC, _encoder.encode(tf)))
        if flange is not None:
            out.append((FLANGE_TOPIC, _encoder.encode(flange)))
        return out
