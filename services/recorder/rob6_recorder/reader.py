"""Reading rob6 recordings, finished or not.

``scan(path)`` walks the file record by record and stops cleanly at a truncated tail
(a SIGKILLed writer leaves a file without summary/footer whose last record may be
cut); a chunk whose CRC or compression is broken is skipped and counted. It yields
the records of the data section in file order, chunks already broken up.

``read_records(path, topics=None)`` gives decoded ``Record``s (topic, log_time,
publish_time, data, schema name, sequence) in the order they were written.
"""

from __future__ import annotations

import contextlib
import io
import os
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any, BinaryIO

import msgspec
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import breakup_chunk

from rob6.errors import InputError

MAGIC = bytes([137, 77, 67, 65, 80, 48, 13, 10])

_READERS = {
    Opcode.HEADER: Header.read, Opcode.FOOTER: Footer.read, Opcode.SCHEMA: Schema.read,
    Opcode.CHANNEL: Channel.read, Opcode.CHUNK: Chunk.read,
    Opcode.MESSAGE_INDEX: MessageIndex.read, Opcode.CHUNK_INDEX: ChunkIndex.read,
    Opcode.ATTACHMENT: Attachment.read, Opcode.ATTACHMENT_INDEX: AttachmentIndex.read,
    Opcode.STATISTICS: Statistics.read, Opcode.METADATA: Metadata.read,
    Opcode.METADATA_INDEX: MetadataIndex.read, Opcode.SUMMARY_OFFSET: SummaryOffset.read,
    Opcode.DATA_END: DataEnd.read,
}


class NotMcap(InputError, ValueError):
    """The file does not begin with the MCAP magic: it is not a recording."""


@dataclass
class ScanReport:
    """What ``scan`` found: where the readable part ends and why."""

    size: int = 0
    good_until: int = 0  # offset after the last complete record
    complete: bool = False  # a footer (and the closing magic) was found
    data_end: bool = False  # the data section ended properly (DataEnd record)
    truncated: bool = False  # the file ends inside a record
    chunks: int = 0
    bad_chunks: int = 0
    bad_chunk_offsets: list[int] = field(default_factory=list)
    messages: int = 0
    error: str = ""


def scan(path: str | os.PathLike[str], report: ScanReport | None = None,
         validate_crcs: bool = True) -> Iterator[Any]:
    """Yield every record of the data section in file order (chunks broken up).

    Stops at DataEnd (the summary after it is not yielded), at a footer, or at the
    first truncated/unparsable record; ``report`` says which.
    """
    report = report if report is not None else ScanReport()
    with open(path, "rb") as fh:
        fh.seek(0, os.SEEK_END)
        report.size = size = fh.tell()
        fh.seek(0)
        if fh.read(8) != MAGIC:
            raise NotMcap(f"{path}: not an MCAP file (bad magic)")
        report.good_until = pos = 8
        while True:
            head = fh.read(9)
            if len(head) < 9:
                report.truncated = len(head) > 0
                if not head:
                    report.error = "file ends without a footer (writer did not finish)"
                else:
                    report.error = f"truncated record header at offset {pos}"
                return
            opcode, length = struct.unpack("<BQ", head)
            if pos + 9 + length > size:
                report.truncated = True
                report.error = (f"truncated record (opcode 0x{opcode:02x}, {length} bytes) "
                                f"at offset {pos}")
                return
            body = fh.read(length)
            reader = _READERS.get(opcode)
            if opcode == Opcode.MESSAGE:
                try:
                    record = Message.read(ReadDataStream(io.BytesIO(body)), length)
                except Exception as exc:
                    report.error = f"bad message record at offset {pos}: {exc!r}"
                    return
            elif reader is None:
                record = None  # unknown opcode: skip (the spec allows extensions)
            else:
                try:
                    record = reader(ReadDataStream(io.BytesIO(body)))
                except Exception as exc:
                    report.error = f"unparsable record 0x{opcode:02x} at offset {pos}: {exc!r}"
                    return
            pos += 9 + length
            if isinstance(record, Chunk):
                report.chunks += 1
                try:
                    inner = breakup_chunk(record, validate_crc=validate_crcs)
                except Exception:
                    report.bad_chunks += 1
                    report.bad_chunk_offsets.append(pos - 9 - length)
                    report.good_until = pos
                    continue
                report.good_until = pos
                for rec in inner:
                    if isinstance(rec, Message):
                        report.messages += 1
                    yield rec
                continue
            report.good_until = pos
            if isinstance(record, DataEnd):
                report.data_end = True
                _check_footer(fh, size, report)
                return
            if isinstance(record, Footer):
                report.complete = fh.read(8) == MAGIC
                return
            if isinstance(record, Message):
                report.messages += 1
            if record is not None:
                yield record


def _check_footer(fh: BinaryIO, size: int, report: ScanReport) -> None:
    if size < 8 + 9 + 20 + 8:
        return
    fh.seek(size - 8 - 29)
    tail = fh.read(29 + 8)
    report.complete = tail[-8:] == MAGIC and tail[0] == Opcode.FOOTER


def is_complete(path: str | os.PathLike[str]) -> bool:
    """True when the file ends with a footer and the closing magic (the writer finished)."""
    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            if size < 8 + 29 + 8:
                return False
            fh.seek(0)
            if fh.read(8) != MAGIC:
                return False
            fh.seek(size - 8 - 29)
            tail = fh.read(37)
            return tail[-8:] == MAGIC and tail[0] == Opcode.FOOTER
    except OSError:
        return False


@dataclass(frozen=True)
class Record:
    topic: str
    log_time: int
    publish_time: int
    data: Any
    schema: str = ""
    sequence: int = 0


_decoder = msgspec.json.Decoder()


class RecordingReader:
    """Messages, metadata and attachments of one recording (finished or unfinished)."""

    def __init__(self, path: str | os.PathLike[str], validate_crcs: bool = True):
        self.path = str(path)
        self.validate_crcs = validate_crcs
        self.report = ScanReport()
        self.header: Header | None = None
        self.metadata: dict[str, dict[str, str]] = {}
        self.attachments: list[Attachment] = []
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}

    def records(self, topics: Iterable[str] | None = None, decode: bool = True) -> Iterator[Record]:
        wanted = set(topics) if topics is not None else None
        self.report = ScanReport()
        for rec in scan(self.path, self.report, self.validate_crcs):
            if isinstance(rec, Message):
                channel = self.channels.get(rec.channel_id)
                if channel is None:
                    continue  # channel record lost (cannot happen with our writer)
                if wanted is not None and channel.topic not in wanted:
                    continue
                schema = self.schemas.get(channel.schema_id)
                data: Any = rec.data
                if decode and channel.message_encoding == "json":
                    with contextlib.suppress(msgspec.DecodeError):
                        data = _decoder.decode(rec.data)
                yield Record(channel.topic, rec.log_time, rec.publish_time, data,
                             schema.name if schema else "", rec.sequence)
            elif isinstance(rec, Channel):
                self.channels[rec.id] = rec
            elif isinstance(rec, Schema):
                self.schemas[rec.id] = rec
            elif isinstance(rec, Metadata):
                self.metadata[rec.name] = dict(rec.metadata)
            elif isinstance(rec, Attachment):
                self.attachments.append(rec)
            elif isinstance(rec, Header):
                self.header = rec


def read_records(path: str | os.PathLike[str], topics: Iterable[str] | None = None) -> Iterator[Record]:
    """Decoded records of a recording in write order (works on unfinished files)."""
    yield from RecordingReader(path).records(topics)
