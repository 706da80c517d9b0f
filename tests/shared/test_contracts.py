"""Bus contracts as types: a motion kind or an error code outside its set fails where the
message is decoded, not somewhere downstream."""

import msgspec
import pytest

from rob6.messages import MOTION_KINDS, ErrorBody, MoveRequest


def test_every_motion_kind_decodes() -> None:
    for kind in MOTION_KINDS:
        assert msgspec.json.decode(msgspec.json.encode({"kind": kind}), type=MoveRequest).kind == kind


def test_a_motion_kind_typo_is_refused_at_decoding() -> None:
    with pytest.raises(msgspec.ValidationError):
        msgspec.json.decode(b'{"kind": "MovePTPJoint"}', type=MoveRequest)


def test_an_unknown_error_code_is_refused_at_decoding() -> None:
    assert msgspec.json.decode(b'{"code": "timeout", "message": "m"}', type=ErrorBody).code == "timeout"
    with pytest.raises(msgspec.ValidationError):
        msgspec.json.decode(b'{"code": "time-out", "message": "m"}', type=ErrorBody)
