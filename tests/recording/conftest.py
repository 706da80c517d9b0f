import pytest

from tests.recording.rec_helpers import URDF


@pytest.fixture
def urdf() -> str:
    return URDF
