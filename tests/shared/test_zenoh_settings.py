"""rob6's Zenoh sessions send without batching, also under a configuration file of a lab's own."""

from __future__ import annotations

import json
from pathlib import Path

import zenoh

from rob6.bus import zenoh_config
from rob6.config import BusSettings


def _batching(settings: BusSettings) -> bool:
    enabled: bool = json.loads(zenoh_config(settings).get_json("transport/link/tx/queue/batching/enabled"))
    return enabled


def test_zenoh_batching_is_off_where_zenoh_has_it_on() -> None:
    assert json.loads(zenoh.Config().get_json("transport/link/tx/queue/batching/enabled")) is True
    assert _batching(BusSettings()) is False


def test_a_configuration_file_keeps_its_settings_and_batching_stays_off(tmp_path: Path) -> None:
    path = tmp_path / "lab.json5"
    path.write_text('{transport: {link: {tx: {queue: {batching: {enabled: true, time_limit: 3}}}}}}')
    settings = BusSettings(zenoh_config=str(path))
    assert json.loads(zenoh_config(settings).get_json("transport/link/tx/queue/batching/time_limit")) == 3
    assert _batching(settings) is False
