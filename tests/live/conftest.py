import pytest

from harness.ports import free_port


@pytest.fixture
def live_port() -> int:
    return free_port()
