"""Shared pytest configuration: the Docker tests' images, built once before the first test;
ROB6_SKIP_DOCKER=1 skips the Docker tests; a failed test shows the output of the rob6 systems
it ran (its fixtures' and its own)."""

import os
from collections.abc import Generator

import pytest

from harness import images
from harness.system import STARTED, System

#: the one image build of this test run, made before the first test (absent: no Docker test was selected)
IMAGES_BUILT = pytest.StashKey[images.Outcome]()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get("ROB6_SKIP_DOCKER") != "1":
        return
    skip = pytest.mark.skip(reason="ROB6_SKIP_DOCKER=1")
    for item in items:
        if "docker" in item.keywords:
            item.add_marker(skip)


def pytest_collection_finish(session: pytest.Session) -> None:
    """Build the images here, after selection (-k, -m) and before any test: outside every
    test's timeout, once for all Docker suites."""
    selected = [item for item in session.items
                if "docker" in item.keywords and not item.get_closest_marker("skip")]
    if not selected or session.config.option.collectonly or images.docker_missing():
        return  # the suites skip themselves where no Docker engine answers
    terminal = session.config.pluginmanager.get_plugin("terminalreporter")
    if terminal is not None:
        terminal.write_line(f"building the rob6 images (rob6/*:{images.TAG}) for {len(selected)} Docker tests ...")
    outcome = session.config.stash[IMAGES_BUILT] = images.build()
    if terminal is not None:
        for line in outcome.steps:
            terminal.write_line(line)
        terminal.write_line(f"rob6 images: {outcome.error or 'ready'} ({outcome.seconds:.0f} s)")


@pytest.fixture(scope="session")
def rob6_images(pytestconfig: pytest.Config) -> images.Outcome:
    """The images every Docker test runs; a failed build fails the test with its one-line reason."""
    outcome = pytestconfig.stash.get(IMAGES_BUILT, None)
    if outcome is None:
        pytest.fail("no rob6 image was built before this test (pytest_collection_finish did not run)", pytrace=False)
    if outcome.error:
        pytest.fail(f"rob6 images not built: {outcome.error}", pytrace=False)
    return outcome


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    STARTED.clear()  # a module's system, started in this setup, is still among the fixtures


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    """A failed test's report gets the last lines each of its systems printed (the services'
    warnings and errors), which is often all that tells what happened on a slow machine."""
    report = yield
    if report.failed:
        fixtures = [v for v in getattr(item, "funcargs", {}).values() if isinstance(v, System)]
        for system in dict.fromkeys(fixtures + STARTED):
            report.sections.append((f"rob6 system {system.robot} on port {system.port}: its last output",
                                    "\n".join(system.output[-60:])))
    return report
