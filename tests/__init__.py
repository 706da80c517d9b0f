"""The test suite: one package. Its own helpers are imported as ``tests.<module>``
(``tests.conformance``, ``tests.recording.rec_helpers``...), what it shares with the
benchmarks as ``harness.<module>``; shared fixtures live in the conftest.py files."""
