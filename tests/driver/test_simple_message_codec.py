"""The driver's simple_message codec against frames packed by hand from the protocol's
definition (struct here, nothing of the codec), in both byte orders."""

from __future__ import annotations

import math
import struct

import pytest

from rob6_driver.links import simple_message_codec as sm

ORDERS = {"big": ">", "little": "<"}


def packed(e: str, msg_type: int, comm: int, reply: int, body: bytes) -> bytes:
    return struct.pack(e + "i", 12 + len(body)) + struct.pack(e + "3i", msg_type, comm, reply) + body


@pytest.mark.parametrize("order", ["big", "little"])
def test_a_trajectory_point_request_is_68_bytes_in_the_protocols_layout(order: str) -> None:
    e = ORDERS[order]
    joints = [0.1, -0.2, 1.5, 0.0, 2.0, -3.0]
    frame = sm.Codec(order).traj_pt(7, joints, velocity=0.25, duration=0.048)
    body = struct.pack(e + "i10fff", 7, *joints, 0, 0, 0, 0, 0.25, 0.048)
    assert frame == packed(e, 11, 2, 0, body)
    assert len(frame) == 68 and struct.unpack(e + "i", frame[:4]) == (64,)


@pytest.mark.parametrize("order", ["big", "little"])
def test_state_messages_and_replies_are_read(order: str) -> None:
    e = ORDERS[order]
    codec = sm.Codec(order)
    joints = [0.5, -1.0, 1.5707964, 0.25, -0.75, 3.0, 0, 0, 0, 0]
    position = packed(e, 10, 1, 0, struct.pack(e + "i10f", 0, *joints))
    status = packed(e, 13, 1, 0, struct.pack(e + "7i", 1, 0, 0, 0, 1, 2, 0))
    reply = packed(e, 11, 3, 1, struct.pack(e + "i", 0))
    buffer = bytearray(position + status + reply[:9])  # the reply arrives in two pieces
    payloads = codec.split(buffer)
    assert len(payloads) == 2 and len(buffer) == 9
    pos = codec.decode(payloads[0])
    assert pos.header == sm.Header(sm.JOINT_POSITION, sm.TOPIC, sm.INVALID)
    assert isinstance(pos.value, sm.JointPosition)
    assert pos.value.sequence == 0
    assert [round(x, 6) for x in pos.value.joints] == [round(struct.unpack("f", struct.pack("f", x))[0], 6)
                                                        for x in joints]
    st = codec.decode(payloads[1]).value
    assert st == sm.RobotStatus(drives_powered=1, e_stopped=0, error_code=0, in_error=0, in_motion=1,
                                mode=sm.MODE_AUTO, motion_possible=0)
    buffer += reply[9:]
    (payload,) = codec.split(buffer)
    answer = codec.decode(payload)
    assert answer.header == sm.Header(sm.JOINT_TRAJ_PT, sm.SERVICE_REPLY, sm.SUCCESS)
    assert answer.value is None and codec.reply_sequence(answer.body) == 0 and not buffer


@pytest.mark.parametrize("order", ["big", "little"])
def test_what_the_codec_packs_it_reads_back(order: str) -> None:
    codec = sm.Codec(order)
    status = sm.RobotStatus(0, 1, 42, 1, 0, sm.MODE_MANUAL, -1)
    point = codec.decode(codec.split(bytearray(codec.traj_pt(-3, [1.0, 2.0], 0.5, 1.25)))[0]).value
    assert point == sm.TrajPoint(-3, (1.0, 2.0) + (0.0,) * 8, 0.5, 1.25)
    assert codec.decode(codec.split(bytearray(codec.status(status)))[0]).value == status
    reply = codec.decode(codec.split(bytearray(codec.reply(sm.JOINT_TRAJ_PT, sm.FAILURE, b"\0\0\0\0")))[0])
    assert reply.header.reply_code == sm.FAILURE


def test_the_wrong_byte_order_is_named() -> None:
    little = packed("<", 10, 1, 0, struct.pack("<i10f", 0, *[0.0] * 10))
    with pytest.raises(sm.SimpleMessageError, match=r"read little-endian it would be 56: is the byte order"):
        sm.Codec("big").split(bytearray(little))
    with pytest.raises(sm.SimpleMessageError, match="frame length -5 is not possible$"):
        sm.Codec("big").split(bytearray(struct.pack(">i", -5) + b"x" * 8))


def test_a_known_message_with_the_wrong_body_is_refused() -> None:
    short = packed(">", 13, 1, 0, struct.pack(">6i", 1, 0, 0, 0, 0, 2))
    codec = sm.Codec("big")
    with pytest.raises(sm.SimpleMessageError, match="STATUS body of 24 bytes, expected 28"):
        codec.decode(codec.split(bytearray(short))[0])
    # a type rob6 does not read passes with its body unparsed
    other = codec.decode(codec.split(bytearray(packed(">", 15, 1, 0, b"abcd")))[0])
    assert other.value is None and other.body == b"abcd"


def test_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="byte order 'middle'"):
        sm.Codec("middle")
    with pytest.raises(ValueError, match="at most 10 joints"):
        sm.Codec().traj_pt(0, [0.0] * 11)
    assert math.isclose(struct.unpack(">f", sm.Codec().traj_pt(0, [0.0], 0.0, 0.1)[-4:])[0], 0.1, rel_tol=1e-6)
