"""The argument reader behaves like the original's C++ istream parsing (REFERENCE.md 3, 5)."""

import pytest

from rob6_gateway.args import Args, ParseError


@pytest.mark.parametrize("text, value", [
    ("1e1", 10.0), ("+10", 10.0), ("10.", 10.0), (".5e1", 5.0), ("-0", -0.0),
    ("10.123456789", 10.123456789), ("\t7", 7.0), ("10abc", 10.0), ("0x0A", 0.0), ("10,0", 10.0),
])
def test_numbers_parse_like_istream(text: str, value: float) -> None:
    assert Args(text).double() == value


@pytest.mark.parametrize("text", ["nan", "inf", "1e400", "x", "", "   ", ",5"])
def test_numbers_that_fail(text: str) -> None:
    assert Args(text).double() is None


def test_rest_of_a_token_is_the_next_field() -> None:
    args = Args("10abc 0")
    assert args.double() == 10.0
    assert args.double() is None  # "abc" fails


def test_integer_fields_leave_the_fraction_as_next_value() -> None:
    args = Args("2.5 0.3")
    assert args.index() == 2
    assert args.value() == 0.5  # SetSingleJointMaxSpeed 2.5 0.3 sets joint 2 to 0.5


@pytest.mark.parametrize("text, count", [("1 2 3 4 5 6", 6), ("1 2 3 4 5 6 7", 6), ("10,0,0", 1), ("", 0)])
def test_leading_doubles(text: str, count: int) -> None:
    assert len(Args(text).leading_doubles(6)) == count


@pytest.mark.parametrize("text", ["1 2 3", "a b c d e f", "5,0,0,0,0,0", "nan 0 0 0 0 0", ""])
def test_bad_joints(text: str) -> None:
    with pytest.raises(ParseError, match="incorrect joints"):
        Args(text).joints()


@pytest.mark.parametrize("text, pattern", [
    ("noflip up lefty", ["noflip", "up", "lefty"]),
    ("up noflip lefty", ["noflip", "up", "lefty"]),
    ("righty down flip", ["flip", "down", "righty"]),
    ("toggleArm toggleElbow toggleHand", ["toggleHand", "toggleElbow", "toggleArm"]),
    ("noflip up", ["noflip", "up", "toggleArm"]),
    ("noflip", ["noflip", "toggleElbow", "toggleArm"]),
    ("noflip up lefty extra", ["noflip", "up", "lefty"]),
    ("flip noToggleElbow noToggleArm", ["flip", "noToggleElbow", "noToggleArm"]),
])
def test_status_words(text: str, pattern: list[str]) -> None:
    assert Args(text).status() == pattern


@pytest.mark.parametrize("text", ["NOFLIP UP LEFTY", "Flip down righty", "foo up lefty", "flip flip righty",
                                  "flip flip flip", "", "noflip up extra"])
def test_bad_status(text: str) -> None:
    with pytest.raises(ParseError, match="incorrect status"):
        Args(text).status()
