"""The test suite: one package. Helpers are imported as ``tests.<module>`` (``harness.system``,
``tests.recording.rec_helpers``...); shared fixtures live in the conftest.py files."""
