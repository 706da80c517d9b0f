"""Rebuild a readable, indexed MCAP file from an unfinished or damaged one.

Same idea as ``mcap recover`` (Go CLI): read every complete record of the data
section in order, skip chunks that fail their CRC or decompression, stop at the
truncated tail, and write a new file with the schemas, channels, messages,
attachments and metadata, followed by a full summary (statistics, chunk/message
indexes, summary offsets). Message channel ids are remapped if needed; log/publish
times and sequence numbers are kept.

``recover_unfinished(directory)`` applies it to every ``*.mcap`` left unfinished in a
directory (e.g. after a crash of the recorder): ``X.mcap`` is rebuilt in place and
the original is kept as ``X.mcap.unfinished``.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from . import __version__
from .reader import ScanReport, is_complete, scan

log = logging.getLogger("rob6.recorder.recover")


@dataclass
class RecoverResult:
    path: str
    out_path: str
    messages: int = 0
    schemas: int = 0
    channels: int = 0
    attachments: int = 0
    metadata: int = 0
    first_log_time: int = 0
    last_log_time: int = 0
    scan: ScanReport = field(default_factory=ScanReport)

    @property
    def lost_bytes(self) -> int:
        return self.scan.size - self.scan.good_until

    def describe(self) -> str:
        s = self.scan
        state = "complete" if s.complete else ("truncated" if s.truncated else "unfinished")
        span = (self.last_log_time - self.first_log_time) / 1e9 if self.messages else 0.0
        lines = [
            f"{self.path}: {state}, {s.size} bytes, readable up to offset {s.good_until}"
            f" ({self.lost_bytes} bytes after it dropped)",
            f"  chunks: {s.chunks} ({s.bad_chunks} damaged, skipped)",
            f"  recovered: {self.messages} messages over {span:.3f} s on {self.channels} "
            f"channels, {self.schemas} schemas, {self.attachments} attachments, "
            f"{self.metadata} metadata records",
            f"  written to {self.out_path}",
        ]
        if s.error and not s.complete:
            lines.insert(1, f"  {s.error}")
        return "\n".join(lines)


def recover(path: str | os.PathLike[str], out_path: str | os.PathLike[str], *,
            chunk_size: int = 1 << 20, compression: str = "zstd") -> RecoverResult:
    """Write to ``out_path`` an indexed MCAP file with everything readable in ``path``."""
    path, out_path = str(path), str(out_path)
    if os.path.abspath(path) == os.path.abspath(out_path):
        raise ValueError("recover needs a different output path (use recover_in_place)")
    result = RecoverResult(path=path, out_path=out_path)
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
            "none": CompressionType.NONE}[compression]
    tmp = out_path + ".tmp"
    with open(tmp, "wb") as fh:
        writer = Writer(fh, chunk_size=chunk_size, compression=comp)
        started = False
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}

        def ensure_started(profile: str = "", library: str = "") -> None:
            nonlocal started
            if not started:
                writer.start(profile=profile,
                             library=f"rob6-recover/{__version__} ({library})" if library
                             else f"rob6-recover/{__version__}")
                started = True

        for rec in scan(path, result.scan):
            if isinstance(rec, Header):
                ensure_started(rec.profile, rec.library)
                continue
            ensure_started()
            if isinstance(rec, Schema):
                if rec.id not in schema_ids:
                    schema_ids[rec.id] = writer.register_schema(rec.name, rec.encoding, rec.data)
                    result.schemas += 1
            elif isinstance(rec, Channel):
                if rec.id not in channel_ids:
                    sid = schema_ids.get(rec.schema_id, 0) if rec.schema_id else 0
                    channel_ids[rec.id] = writer.register_channel(
                        rec.topic, rec.message_encoding, sid, dict(rec.metadata))
                    result.channels += 1
            elif isinstance(rec, Message):
                ch = channel_ids.get(rec.channel_id)
                if ch is None:
                    continue  # its channel record was lost
                writer.add_message(ch, rec.log_time, rec.data, rec.publish_time, rec.sequence)
                if result.messages == 0:
                    result.first_log_time = rec.log_time
                result.first_log_time = min(result.first_log_time, rec.log_time)
                result.last_log_time = max(result.last_log_time, rec.log_time)
                result.messages += 1
            elif isinstance(rec, Attachment):
                writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type,
                                      rec.data)
                result.attachments += 1
            elif isinstance(rec, Metadata):
                writer.add_metadata(rec.name, dict(rec.metadata))
                result.metadata += 1
            # indexes, statistics, summary offsets, DataEnd, Footer: rebuilt by finish()
        ensure_started()
        if not result.scan.complete:
            writer.add_metadata("rob6.recovered", {
                "source": os.path.basename(path), "recovered_at": str(time.time_ns()),
                "readable_until": str(result.scan.good_until), "size": str(result.scan.size),
                "bad_chunks": str(result.scan.bad_chunks), "reason": result.scan.error})
            result.metadata += 1
        writer.finish()
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, out_path)
    return result


def recover_in_place(path: str | os.PathLike[str], keep: bool = True) -> RecoverResult:
    """Rebuild ``path`` itself; the original is kept as ``<path>.unfinished`` if ``keep``."""
    path = str(path)
    tmp = path + ".recovering"
    result = recover(path, tmp)
    if keep:
        os.replace(path, path + ".unfinished")
    os.replace(tmp, path)
    result.out_path = path
    return result


def recover_unfinished(directory: str | os.PathLike[str], min_age_s: float = 5.0,
                       keep: bool = True) -> list[RecoverResult]:
    """Recover every unfinished ``*.mcap`` in ``directory`` not modified for ``min_age_s``.

    Do not point it at a directory another recorder is still writing to: a live file
    that has been idle for longer than ``min_age_s`` would be taken for a dead one.
    """
    results = []
    now = time.time()
    for p in sorted(Path(directory).glob("*.mcap")):
        try:
            if is_complete(p) or now - p.stat().st_mtime < min_age_s:
                continue
            result = recover_in_place(p, keep=keep)
            log.warning("recovered unfinished recording %s (%d messages)", p, result.messages)
            results.append(result)
        except Exception as exc:
            log.error("could not recover %s: %r", p, exc)
    return results
