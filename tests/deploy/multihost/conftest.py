"""A failed multi-host test prints what the containers said last: the services' warnings and
Zenoh's own (RUST_LOG=zenoh=warn in the compose file), which a report alone cannot show."""

from collections.abc import Generator
from typing import Any

import pytest


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Generator[None, Any, None]:
    outcome = yield
    report = outcome.get_result()
    topology = item.funcargs.get("topology") if hasattr(item, "funcargs") else None
    if report.when == "call" and report.failed and topology is not None:
        # every container's last lines, whole: a cap on the whole text kept only the containers
        # that print last, the routers' Zenoh warnings, and cut the gateway's and driver's
        logs = topology.compose("logs", "--no-color", "--timestamps", "--tail", "40", check=False).stdout
        report.sections.append(("containers' last log lines", logs))
