"""Line framing: terminators, NUL, several commands per read, bounded lines."""

from rob6_gateway.framing import Framer, Line


def texts(lines: list[Line]) -> list[str]:
    return [line.text for line in lines]


def test_terminators() -> None:
    framer = Framer()
    assert texts(framer.feed(b"GetRobot\r\nFoo\nBar\r\r\n")) == ["GetRobot", "Foo", "Bar\r"]
    assert not framer.pending()


def test_unterminated_chunk_waits_for_the_pause() -> None:
    framer = Framer()
    assert framer.feed(b"GetRo") == []
    assert framer.pending()
    assert texts(framer.feed(b"bot\n")) == ["GetRobot"]  # arrived before the pause: one line
    assert framer.feed(b"GetRobot\r") == []
    assert texts(framer.flush()) == ["GetRobot"]  # the pause passed: a command


def test_nul_ends_the_line() -> None:
    assert texts(Framer().feed(b"Get\0Robot\n\0GetRobot\nGetRobot\0GetVersion\n")) == ["Get", "", "GetRobot"]


def test_latin1_passes_through() -> None:
    assert texts(Framer().feed("GetRobot\xe4\n".encode("latin-1"))) == ["GetRobot\xe4"]


def test_overlong_lines_are_reported_and_dropped() -> None:
    framer = Framer(max_line=100)
    lines = framer.feed(b"A" * 250 + b"\nGetRobot\n")
    assert lines[0].too_long == 251 and texts(lines[1:]) == ["GetRobot"]
    assert framer.feed(b"B" * 150) == []  # no terminator yet: dropped while it grows
    lines = framer.feed(b"B" * 60 + b"\nCM_PING\n")
    assert lines[0].too_long == 211 and texts(lines[1:]) == ["CM_PING"]
