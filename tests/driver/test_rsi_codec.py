"""The RSI XML codec: what varies between RSI versions parses, garbage gives a clear error."""

from __future__ import annotations

import random

import pytest

from rob6_driver.links.rsi_codec import RobPacket, RsiParseError, format_sen, ipoc_of, parse_rob

AXES = 'A1="1.5" A2="-90.25" A3="90" A4="0.0001" A5="-0.5" A6="180"'
START = 'A1="0" A2="-90" A3="90" A4="0" A5="0" A6="0"'

STANDARD = (f'<Rob TYPE="KUKA"><RIst X="1" Y="2" Z="3" A="4" B="5" C="6"/><RSol X="1" Y="2" Z="3" A="4" '
            f'B="5" C="6"/><AIPos {AXES}/><ASPos {START}/><Delay D="7"/><IPOC>4208105428</IPOC></Rob>').encode()


def check(packet: RobPacket) -> None:
    assert packet.aipos == (1.5, -90.25, 90.0, 0.0001, -0.5, 180.0)
    assert packet.aspos == (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
    assert packet.ipoc == b"4208105428" and packet.stamp == 4208105428


def test_the_controllers_packet() -> None:
    packet = parse_rob(STANDARD)
    check(packet)
    assert packet.delay == 7 and packet.robot_type == "KUKA"


@pytest.mark.parametrize("text", [
    # Type instead of TYPE, extra elements (EIPos, Tech, digital inputs) in between
    f'<Rob Type="KUKA"><AIPos {AXES}/><EIPos E1="0" E2="0"/><ASPos {START}/><Tech C11="0"/>'
    f'<Digin>0</Digin><Delay D="0"/><IPOC>4208105428</IPOC></Rob>',
    # attributes in another order, single quotes, spaces and new lines everywhere
    "<?xml version='1.0'?>\n<Rob  TYPE = 'KUKA' >\n  <IPOC> 4208105428 </IPOC>\n"
    "  <ASPos A6='0' A5='0' A4='0' A3='90' A2='-90' A1='0' />\n"
    "  <AIPos\n A6 = \"180\" A1=\"1.5\"  A3=\"90\" A2=\"-90.25\" A5=\"-0.5\" A4=\"0.0001\"/>\n"
    "  <Delay D='0' />\n</Rob>\r\n",
    # elements written with an end tag, no Delay element at all, lower-case attribute names
    f'<Rob><AIPos {AXES.lower()}></AIPos><ASPos {START}></ASPos><IPOC>4208105428</IPOC></Rob>',
])
def test_variants_of_other_rsi_versions(text: str) -> None:
    check(parse_rob(text.encode()))


def test_a_missing_delay_counts_as_zero() -> None:
    packet = parse_rob(f"<Rob><AIPos {AXES}/><ASPos {START}/><IPOC>1</IPOC></Rob>".encode())
    assert packet.delay == 0


@pytest.mark.parametrize("text, message", [
    (b"", "no <Rob> element"),
    (b"hello", "no <Rob> element"),
    (b'<Sen Type="ImFree"><AK A1="0"/><IPOC>1</IPOC></Sen>', "no <Rob> element"),
    (f"<Rob><AIPos {AXES}/><ASPos {START}/></Rob>".encode(), "no <IPOC>"),
    (f"<Rob><AIPos {AXES}/><ASPos {START}/><IPOC>-4</IPOC></Rob>".encode(), "no <IPOC>"),
    (f"<Rob><ASPos {START}/><IPOC>1</IPOC></Rob>".encode(), "no <AIPos> element"),
    (f"<Rob><AIPos {AXES}/><IPOC>1</IPOC></Rob>".encode(), "no <ASPos> element"),
    (f'<Rob><AIPos A1="1" A2="2"/><ASPos {START}/><IPOC>1</IPOC></Rob>'.encode(), "<AIPos> has no A3"),
    (f'<Rob><AIPos {AXES.replace("1.5", "x1")}/><ASPos {START}/><IPOC>1</IPOC></Rob>'.encode(),
     "A1='x1' is not a number"),
    (f'<Rob><AIPos {AXES.replace("1.5", "nan")}/><ASPos {START}/><IPOC>1</IPOC></Rob>'.encode(), "not finite"),
    (f'<Rob><AIPos {AXES}/><ASPos {START}/><Delay D="many"/><IPOC>1</IPOC></Rob>'.encode(),
     "<Delay> without a count"),
    # the packet cut off by a too small buffer
    (STANDARD[:150], "no <IPOC>"),
])
def test_garbage_gives_a_clear_error(text: bytes, message: str) -> None:
    with pytest.raises(RsiParseError, match=message.replace("(", r"\(").replace("[", r"\[")):
        parse_rob(text)


def test_random_bytes_never_crash_the_parser() -> None:
    rng = random.Random(7)
    for _ in range(3000):
        data = bytearray(STANDARD)
        for _ in range(rng.randint(1, 8)):  # mutate, insert, delete
            i = rng.randrange(len(data))
            kind = rng.random()
            if kind < 0.4:
                data[i] = rng.randrange(256)
            elif kind < 0.7:
                data.insert(i, rng.randrange(256))
            else:
                del data[i]
        try:
            packet = parse_rob(bytes(data))
        except RsiParseError:
            continue
        assert len(packet.aipos) == len(packet.aspos) == 6


def test_the_answer() -> None:
    """Every element the shipped configuration reads (RECEIVE: Stop, AK.A1..A6), always:
    an answer without <Stop> is one the controller cannot take."""
    sen = format_sen(b"ImFree", [0.1, -2.0, 0.0, 1e-7, 123.456789, -0.0000004], b"4208105428")
    assert sen == (b'<Sen Type="ImFree"><AK A1="0.100000" A2="-2.000000" A3="0.000000" A4="0.000000" '
                   b'A5="123.456789" A6="-0.000000"/><Stop>0</Stop><IPOC>4208105428</IPOC></Sen>')
    stop = format_sen(b"ImFree", [0.0] * 6, b"17", stop=True)
    assert stop.endswith(b"/><Stop>1</Stop><IPOC>17</IPOC></Sen>")


def test_ipoc_of() -> None:
    assert ipoc_of(STANDARD) == 4208105428
    assert ipoc_of(b"<Rob></Rob>") == -1
