"""Shared pytest configuration: Docker tests can be skipped locally with ROB6_SKIP_DOCKER=1."""

import os

import pytest


def pytest_collection_modifyitems(config, items):
    if os.environ.get("ROB6_SKIP_DOCKER") != "1":
        return
    skip = pytest.mark.skip(reason="ROB6_SKIP_DOCKER=1")
    for item in items:
        if "docker" in item.keywords:
            item.add_marker(skip)
