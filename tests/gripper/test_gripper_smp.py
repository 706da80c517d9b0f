"""SMP frames, CRC and the stream decoder (rob6_gripper.smp), no serial port involved.

The byte vectors are the RS232 examples of the Schunk Motion Protocol manual 1.41
(HTML edition, docu304-307: referencing, MOVE POS 10 mm, GET STATE 1 s, error +
CMD ACK, CHECK MC PC COMMUNICATION), module id 1.
"""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings, strategies as st

from rob6_gripper import smp

# (frame without CRC, CRC as sent) -- every CRC printed in the manual's RS232 examples
MANUAL_VECTORS = [
    ("05 01 01 92", "D1 31"),  # CMD REFERENCE
    ("07 01 03 92 4F 4B", "E9 D9"),  # "OK"
    ("07 01 05 93 21 56 B9 40", "4D 22"),  # CMD MOVE BLOCKED at 5.792 mm
    ("05 01 05 B0 00 00 20 41", "48 80"),  # MOVE POS 10 mm
    ("07 01 05 B0 EE EE 56 40", "7B E4"),  # will reach in 3.358 s
    ("07 01 05 94 B6 F3 1F 41", "7E D5"),  # CMD POS REACHED 9.9969 mm
    ("05 01 06 95 00 00 80 3F 01", "54 41"),  # GET STATE every 1 s, position
    ("07 01 07 95 36 89 81 3F 02 00", "F9 BC"),  # 1.011 mm, moving, no error
    ("07 01 07 95 76 BE A1 40 02 00", "38 A0"),
    ("03 01 02 88 74", "82 1B"),  # CMD ERROR: MOTOR VOLTAGE LOW
    ("05 01 01 8B", "10 FB"),  # CMD ACK
    ("07 01 03 8B 4F 4B", "38 1E"),  # "OK"
    ("07 01 03 8A 08 00", "1A 19"),  # CMD INFO: INFO NO ERROR
    ("05 01 03 E4 01 01", "BD B6"),  # CHECK MC PC COMMUNICATION
]


def h(text: str) -> bytes:
    return bytes.fromhex(text)


@pytest.mark.parametrize(("body", "crc"), MANUAL_VECTORS)
def test_crc16_matches_manual(body: str, crc: str) -> None:
    assert smp.crc16(h(body)).to_bytes(2, "little") == h(crc)


def test_crc16_is_crc16_arc() -> None:
    assert smp.crc16(b"123456789") == 0xBB3D  # the CRC catalogue's check value of CRC-16/ARC
    assert smp.crc16(b"") == 0


@pytest.mark.parametrize(("body", "crc"), MANUAL_VECTORS)
def test_encode_decode_manual_frames(body: str, crc: str) -> None:
    raw = h(body) + h(crc)
    group, mid, dlen, cmd = raw[:4]
    frame = smp.Frame(group, mid, cmd, raw[4:3 + dlen])
    assert frame.encode() == raw
    dec = smp.FrameDecoder(groups=(0x03, 0x05, 0x07))
    assert dec.feed(raw) == [frame]


def test_encode_commands() -> None:
    assert smp.encode(1, smp.CMD_REFERENCE) == h("05 01 01 92 D1 31")
    assert smp.encode(1, smp.MOVE_POS, smp.f32(10.0)) == h("05 01 05 B0 00 00 20 41 48 80")
    assert smp.encode(1, smp.GET_STATE, smp.get_state_payload(0x01, 1.0)) == \
        h("05 01 06 95 00 00 80 3F 01 54 41")
    assert smp.encode(1, smp.CMD_ACK) == h("05 01 01 8B 10 FB")
    # MOVE CUR 3.5 A ([M] docu45 data frame "05 B3 00 00 60 40")
    assert smp.encode(12, smp.MOVE_CUR, smp.f32(3.5))[2:-2] == h("05 B3 00 00 60 40")
    assert smp.encode(12, smp.CMD_STOP)[:4] == h("05 0C 01 91")


def test_failure_frame() -> None:
    [f] = smp.FrameDecoder().feed(h("03 01 02 88 74 82 1B"))
    assert f.is_failure and f.error_code == 0x74
    assert smp.error_name(f.error_code) == "ERROR MOTOR VOLTAGE LOW (0x74)"
    [ok] = smp.FrameDecoder().feed(h("07 01 03 92 4F 4B E9 D9"))
    assert not ok.is_failure and ok.payload == smp.OK


def test_parse_get_state_from_manual() -> None:
    [f] = smp.FrameDecoder().feed(h("07 01 07 95 36 89 81 3F 02 00 F9 BC"))
    s = smp.parse_state(f.payload, mode=0x01)
    assert s.position == pytest.approx(1.011, abs=2e-3)  # the manual rounds 1.01200
    assert s.moving and not s.referenced and not s.in_error and s.error == 0


def test_state_payload_roundtrip_and_length_check() -> None:
    s = smp.ModuleState(12.5, -32.0, -1.0, smp.ST_REFERENCED | smp.ST_MOVING, 0)
    assert smp.parse_state(smp.state_payload(s)) == s
    with pytest.raises(smp.SmpProtocolError):
        smp.parse_state(b"\x00" * 7)


def test_decoder_byte_by_byte() -> None:
    raw = smp.encode(12, smp.GET_STATE, smp.get_state_payload(), group=smp.GROUP_FROM_MODULE)
    dec = smp.FrameDecoder()
    out = []
    for b in raw[:-1]:
        out += dec.feed(bytes((b,)))
        assert out == []
    out += dec.feed(raw[-1:])
    assert len(out) == 1 and out[0].command == smp.GET_STATE


def test_decoder_skips_garbage_and_bad_crc() -> None:
    good = smp.Frame(7, 12, smp.CMD_STOP, smp.OK).encode()
    bad = bytearray(good)
    bad[-1] ^= 0xFF
    dec = smp.FrameDecoder()
    out = dec.feed(b"\x00\xff\x13garbage" + bytes(bad) + good + b"\x55" + good)
    assert [f.command for f in out] == [smp.CMD_STOP, smp.CMD_STOP]
    assert dec.crc_errors == 1 and dec.garbage_bytes > 0


def test_decoder_false_header_with_long_dlen_does_not_swallow_next_frame() -> None:
    good = smp.Frame(7, 12, smp.CMD_STOP, smp.OK).encode()
    dec = smp.FrameDecoder(module_id=12)
    # "07 0C F0 ..." looks like the start of a 240-byte frame
    assert dec.feed(h("07 0C F0 91") + good) == [smp.Frame(7, 12, smp.CMD_STOP, smp.OK)]


def test_decoder_module_id_filter() -> None:
    other = smp.Frame(7, 11, smp.CMD_STOP, smp.OK).encode()
    mine = smp.Frame(7, 12, smp.CMD_STOP, smp.OK).encode()
    assert smp.FrameDecoder(module_id=12).feed(other + mine) == [smp.Frame(7, 12, 0x91, b"OK")]


def test_fragments_reassembled() -> None:
    frame = smp.Frame(7, 12, smp.GET_STATE, bytes(range(14)))
    pieces = frame.encode_fragments(4)
    assert [p[3] for p in pieces] == [smp.FRAG_START, smp.FRAG_MIDDLE, smp.FRAG_MIDDLE,
                                      smp.FRAG_END]
    assert all(p[2] == len(p) - 6 for p in pieces)  # D-Len excludes the marker
    dec = smp.FrameDecoder()
    assert dec.feed(b"".join(pieces)) == [frame]
    # single-chunk message: start + empty end
    small = smp.Frame(7, 12, smp.CMD_STOP, smp.OK)
    assert dec.feed(b"".join(small.encode_fragments(10))) == [small]


def test_fragment_errors_counted() -> None:
    frame = smp.Frame(7, 12, smp.GET_STATE, bytes(range(14)))
    start, *rest = frame.encode_fragments(5)
    dec = smp.FrameDecoder()
    assert dec.feed(b"".join(rest)) == []  # middle/end without a start
    assert dec.fragment_errors >= 1
    assert dec.feed(start + start + b"".join(rest)) == [frame]  # restarted message


FRAMES = st.builds(
    lambda group, cmd, payload: smp.Frame(group, 12, cmd, payload),
    st.sampled_from([smp.GROUP_FROM_MODULE, smp.GROUP_ERROR]),
    st.sampled_from([smp.GET_STATE, smp.MOVE_POS, smp.CMD_STOP, smp.CMD_ERROR, smp.CMD_POS_REACHED]),
    st.binary(min_size=0, max_size=20).filter(lambda b: len(b) != 1),
)


@settings(max_examples=150, deadline=None)
@given(frames=st.lists(FRAMES, min_size=1, max_size=6),
       garbage=st.lists(st.binary(max_size=6), min_size=7, max_size=7),
       cuts=st.lists(st.integers(0, 400), max_size=12))
def test_decoder_recovers_every_frame_whatever_the_chunking(frames: list[smp.Frame], garbage: list[bytes],
                                                            cuts: list[int]) -> None:
    stream = b""
    for i, f in enumerate(frames):
        stream += garbage[i] + f.encode()
    stream += garbage[-1]
    points = sorted({c % (len(stream) + 1) for c in cuts})
    chunks = [stream[a:b] for a, b in zip([0, *points], [*points, len(stream)], strict=True)]
    dec = smp.FrameDecoder(module_id=12)
    out = []
    for c in chunks:
        out += dec.feed(c)
    assert out == frames


def test_float_encoding_little_endian() -> None:
    assert smp.f32(-1.0) == struct.pack("<f", -1.0) == h("00 00 80 BF")
