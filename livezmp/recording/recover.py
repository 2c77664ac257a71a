"""Recovering a recording after a crash: every intact record copied into a complete file,
stopping at the first truncated or corrupt one."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Chunk, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer
from zstandard import ZstdError

from livezmp.checks import check_input_file, check_output_path
from livezmp.errors import InputError
from livezmp.recording.reader import MCAP_MAGIC, BoundedFile
from livezmp.recording.writer import CHUNK_BYTES


@dataclass
class RecoverReport:
    """``complete``: the input had its footer (nothing was lost); ``stopped`` says where
    and why copying stopped otherwise. Counts are of records copied."""

    messages: int
    chunks: int
    attachments: int
    metadata: int
    complete: bool
    stopped: str = ""


class _Copier:
    """Re-writes schemas, channels and messages into a new file, mapping record ids."""

    def __init__(self, writer: Writer):
        self.writer = writer
        self.schemas: dict[int, int] = {}
        self.channels: dict[int, int] = {}
        self.messages = 0

    def add(self, record) -> None:
        if isinstance(record, Schema) and record.id not in self.schemas:
            self.schemas[record.id] = self.writer.register_schema(record.name, record.encoding, record.data)
        elif isinstance(record, Channel) and record.id not in self.channels:
            sid = self.schemas.get(record.schema_id, 0)
            self.channels[record.id] = self.writer.register_channel(record.topic, record.message_encoding, sid,
                                                                    record.metadata)
        elif isinstance(record, Message) and record.channel_id in self.channels:
            self.writer.add_message(self.channels[record.channel_id], record.log_time, record.data,
                                    record.publish_time, record.sequence)
            self.messages += 1


def recover(src: str | Path, dst: str | Path) -> RecoverReport:
    """Copy every intact record of ``src`` (possibly truncated by a crash) into a
    complete MCAP file ``dst``. A chunk is copied whole or not at all (its CRC checked)."""
    src, dst = check_input_file(src, "recording"), Path(dst)
    if dst.exists():
        raise InputError(f"{dst}: already exists; write the recovered file to a new name")
    check_output_path(dst, "-o")
    with open(src, "rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise InputError(f"{src}: not an MCAP file (a livezmp recording starts with the MCAP magic)")
    chunks = attachments = metadata = 0
    complete, stopped = False, ""
    with BoundedFile(src) as f, open(dst, "xb") as out:
        writer = Writer(out, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD, enable_crcs=True)
        copier = _Copier(writer)
        started = False
        # no record is longer than the file: a damaged length is refused before it is allocated
        records = StreamReader(f, emit_chunks=True, record_size_limit=max(src.stat().st_size, 1)).records
        try:
            for record in records:
                if isinstance(record, Header):
                    writer.start(profile=record.profile, library=record.library)
                    started = True
                elif isinstance(record, Chunk):
                    inner = breakup_chunk(record, validate_crc=True)
                    for r in inner:
                        copier.add(r)
                    chunks += 1
                elif isinstance(record, Attachment):
                    writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type,
                                          record.data)
                    attachments += 1
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, record.metadata)
                    metadata += 1
                elif isinstance(record, DataEnd | Footer):
                    complete = True
                    break
                else:
                    copier.add(record)
        except CRCValidationError as e:
            stopped = f"chunk {chunks}: {e}"
        except (McapError, ZstdError, struct.error, ValueError, EOFError) as e:
            stopped = f"after {chunks} chunks: {type(e).__name__} {e}".strip()
        if not started:
            out.close()
            dst.unlink()
            raise InputError(f"{src}: not an MCAP file (no header): {stopped}")
        writer.finish()
    return RecoverReport(copier.messages, chunks, attachments, metadata, complete, stopped)
