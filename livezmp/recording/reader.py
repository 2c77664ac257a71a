"""Reading a recording back: the body and session it was made with, and its messages."""

from __future__ import annotations

import contextlib
import json
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from zstandard import ZstdError

from livezmp.checks import check_input_file
from livezmp.errors import InputError
from livezmp.model.body_spec import BodySpec
from livezmp.recording.schemas import BODY_PREFIX, TOPICS


@dataclass
class Recording:
    """What a finished recording says about its session: ``body_spec``, ``session``
    settings, message ``counts`` per topic."""

    path: Path
    body_spec: BodySpec
    session: dict
    counts: dict[str, int]
    totals: dict | None = None  # the ``livezmp.totals`` record written when the session ended

    @property
    def dropped(self) -> int:
        """Messages the recording's writer dropped (queue full) or failed to write."""
        rec = (self.totals or {}).get("recording") or {}
        return int(rec.get("dropped_total", 0) or 0) + int(rec.get("failed", 0) or 0)


MAX_CHUNK_BYTES = 64 << 20  # the writer's chunks are a few hundred kB
MCAP_MAGIC = b"\x89MCAP0\r\n"
# What the mcap library and the JSON decoding raise on damaged bytes or a foreign layout.
DAMAGED = (McapError, ZstdError, struct.error, EOFError, ValueError, KeyError, IndexError, TypeError, AttributeError)


class BoundedFile:
    """A recording opened for the mcap reader: a read never asks for more than the file
    holds, so a damaged length field cannot make it allocate gigabytes."""

    def __init__(self, path: Path):
        self._f = open(path, "rb")  # noqa: SIM115 - closed with this object
        self._size = os.fstat(self._f.fileno()).st_size

    def read(self, n: int = -1) -> bytes:
        left = max(self._size - self._f.tell(), 0)
        return self._f.read(left if n is None or n < 0 or n > left else n)

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._f.seek(offset, whence)

    def tell(self) -> int:
        return self._f.tell()

    def __enter__(self) -> BoundedFile:
        return self

    def __exit__(self, *exc) -> None:
        self._f.close()


def _reader(f: BoundedFile) -> SeekingReader:
    return SeekingReader(f, record_size_limit=max(f._size, 1))


def _broken(path: Path, why: str) -> InputError:
    return InputError(f"{path}: not a complete MCAP recording ({why}); "
                      f"if the monitor was killed, run: livezmp recover {path} -o fixed.mcap")


def open_recording(path: str | Path) -> Recording:
    """Read the session and body of a finished recording; :class:`InputError` if it is
    not one (with the ``livezmp recover`` hint for an unfinished file)."""
    p = check_input_file(path, "recording")
    with open(p, "rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise InputError(f"{p}: not an MCAP file (a livezmp recording starts with the MCAP magic)")
    try:
        with BoundedFile(p) as f:
            reader = _reader(f)
            summary = reader.get_summary()
            if summary is None:
                raise _broken(p, "no summary")
            size = p.stat().st_size
            for c in summary.chunk_indexes:  # damaged sizes are refused before the chunk is inflated
                if c.uncompressed_size > MAX_CHUNK_BYTES or c.compressed_size > size:
                    raise _broken(p, f"chunk at byte {c.chunk_start_offset} claims {c.uncompressed_size} bytes")
            meta = {m.name: m.metadata for m in reader.iter_metadata()}
            files = {a.name[len(BODY_PREFIX):]: a.data.decode() for a in reader.iter_attachments()
                     if a.name.startswith(BODY_PREFIX)}
    except OSError as e:
        raise InputError(f"{p}: cannot read recording: {e.strerror}") from None
    except DAMAGED as e:
        raise _broken(p, _why(e)) from None
    with damaged_as_input_error(p):
        return _recording(p, meta, files, summary)


def _why(e: BaseException) -> str:
    return (str(e).splitlines() or [""])[0][:120] or type(e).__name__


@contextlib.contextmanager
def damaged_as_input_error(path: Path):
    """Turn what damaged recording content raises while it is interpreted into one line naming the file."""
    try:
        yield
    except InputError:
        raise
    except DAMAGED as e:
        raise InputError(f"{path}: not a valid livezmp recording ({type(e).__name__}: {_why(e)})") from None


def _recording(p: Path, meta: dict, files: dict, summary) -> Recording:
    if "livezmp.body" not in meta or "livezmp.session" not in meta:
        raise InputError(f"{p}: not a livezmp recording (no livezmp.model.body / livezmp.session metadata)")
    body = meta["livezmp.body"]
    spec = BodySpec(body["kind"], files, json.loads(body["options"]))
    session = {k: json.loads(v) for k, v in meta["livezmp.session"].items()}
    topic_of = {c.id: c.topic for c in summary.channels.values()}
    counts = dict.fromkeys(TOPICS, 0) | dict.fromkeys(topic_of.values(), 0)
    stats = summary.statistics
    for cid, n in (stats.channel_message_counts.items() if stats else ()):
        counts[topic_of[cid]] = n
    totals = {k: json.loads(v) for k, v in meta["livezmp.totals"].items()} if "livezmp.totals" in meta else None
    return Recording(p, spec, session, counts, totals)


def iter_messages(path: str | Path, topic: str) -> Iterator[dict]:
    """The decoded messages of one topic of a finished recording, in file order."""
    p = Path(path)
    try:
        with BoundedFile(p) as f:
            for _, _, msg in _reader(f).iter_messages(topics=[topic], log_time_order=False):
                m = json.loads(msg.data)
                if not isinstance(m, dict):
                    raise _broken(p, f"a {topic} message is not a JSON object")
                yield m
    except DAMAGED as e:
        raise _broken(p, _why(e)) from None
