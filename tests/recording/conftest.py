import pytest

from .rec_helpers import URDF


@pytest.fixture
def urdf() -> str:
    return URDF
