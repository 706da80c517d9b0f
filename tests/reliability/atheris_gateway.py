"""Optional coverage-guided fuzzing of the gateway's framer, parser and dispatch with atheris.

Not part of the test suite (atheris is not a project dependency). To use it:

    .tools/bin/uv pip install --python .venv/bin/python atheris
    .venv/bin/python -m tests.reliability.atheris_gateway -atheris_runs=200000

The properties are those of ``harness/fuzz.py`` (``check_framer``, ``check_args``,
``check_execute``); any assertion failure or exception is a crash that atheris reports
with the input that caused it.
"""

import sys

import atheris

with atheris.instrument_imports():  # before anything imports them, so they are instrumented
    from rob6_gateway import args, commands, framing  # noqa: F401

from harness.fuzz import COMMAND_NAMES, check_args, check_execute, check_framer, make_dead_gateway

GATEWAY, SESSION = make_dead_gateway("kr16")


def one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    target = fdp.ConsumeIntInRange(0, 2)
    if target == 0:
        max_line = fdp.ConsumeIntInRange(1, 64)
        cuts = [fdp.ConsumeIntInRange(0, 256) for _ in range(fdp.ConsumeIntInRange(0, 6))]
        check_framer(fdp.ConsumeBytes(256), cuts, max_line)
        return
    text = fdp.ConsumeBytes(200).replace(b"\n", b"").decode("latin-1")
    if target == 1:
        check_args(text)
    else:  # a real command name (atheris would rarely guess one) and fuzzed arguments
        check_execute(GATEWAY, SESSION, fdp.PickValueInList(COMMAND_NAMES) + " " + text)


if __name__ == "__main__":
    atheris.Setup(sys.argv, one_input)
    atheris.Fuzz()
