"""Session recording in MCAP: write while monitoring, read back, recover after a crash.

One file holds everything a session saw, on JSON-schema'd JSON channels (so Foxglove
opens it and plots any field):

- ``/input``: every input frame as received (raw channels, input units);
- ``/result``: per analysed frame, ZMP (raw and clamped), CoM, support, polygon,
  soles, margin (internal frame: z up, metres);
- ``/correction``: the online correction, when enabled;
- ``/alarm``: out-of-support alarms raised and cleared;
- ``/device_error``: faults of the source (bad packets, lost connections).

The live loop (``livezmp run --record``) adds ``/foot_sensors`` (:data:`LOOP_SCHEMAS`):
the robot's foot forces and measured centre of pressure beside the computed ZMP.

The body the session analysed is stored as attachments (``body/<file>``) plus the
``livezmp.model.body`` metadata record, and the monitor settings as ``livezmp.session``, so
``livezmp replay`` rebuilds the same body and re-runs the same analysis.

Crash safety: chunks (zstd, CRC of each chunk's data) are closed and handed to the
kernel at least every ``chunk_seconds`` (0.5 s), so a killed monitor loses at most
that much. Such a file has no summary; :func:`recover` copies every intact record
into a complete file and stops at the first truncated or corrupt one.

A real-time thread hands its messages to a :class:`BackgroundWriter`, which encodes and
writes them in a thread of its own from a bounded queue, and counts what a full queue
turned away.
"""

from __future__ import annotations

import json
import math
import struct
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Chunk, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer
from zstandard import ZstdError

from livezmp.errors import InputError
from livezmp.model.body_spec import BodySpec

CHUNK_SECONDS = 0.5
IDLE_GUARD_S = 2.5e-4  # a paced writer stops this long before the producer wakes (a message takes < 0.1 ms)
CHUNK_BYTES = 1 << 20
BODY_PREFIX = "body/"
PROFILE = ""  # no ROS profile: plain JSON channels
_POINT = {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"},
                                           "z": {"type": "number"}}}
_POINT2 = {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}}}
_MAYBE_POINT = {"anyOf": [_POINT, {"type": "null"}]}

SCHEMAS = {
    "/input": ("livezmp.InputFrame", {
        "type": "object",
        "description": "One input frame as received: raw channels in the body's channel order and input units "
                       "(BVH: file length unit and degrees; robot: m and rad).",
        "properties": {
            "index": {"type": "integer", "description": "input frame number, from 0"},
            "t": {"type": "number", "description": "frame time on the source clock, s"},
            "channels": {"type": "array", "items": {"type": "number"}},
            "contacts": {"description": "foot sensors [left, right], null = detected",
                         "anyOf": [{"type": "array", "items": {"type": "boolean"}}, {"type": "null"}]},
        },
        "required": ["index", "t", "channels"],
    }),
    "/result": ("livezmp.BalanceResult", {
        "type": "object",
        "description": "Balance of one frame, internal frame: z up, metres, ground plane z = ground_z.",
        "properties": {
            "index": {"type": "integer", "description": "input frame number"},
            "t": {"type": "number", "description": "s"},
            "support": {"type": "string", "enum": ["left", "right", "double", "none"]},
            "zmp": {**_MAYBE_POINT, "description": "ZMP, m; null in flight"},
            "clamped": {**_MAYBE_POINT, "description": "ZMP moved to the nearest point of the support polygon, m"},
            "com": _POINT,
            "inside": {"type": ["boolean", "null"]},
            "margin": {"type": ["number", "null"], "description": "signed distance to the polygon edge, m (+ inside)"},
            "ground_z": {"type": "number", "description": "m"},
            "polygon": {"type": "array", "items": _POINT2, "description": "support polygon, counter-clockwise, m"},
            "soles": {"type": "object", "properties": {s: {"type": "array", "items": _POINT}
                                                       for s in ("left", "right")}},
        },
        "required": ["index", "t", "support"],
    }),
    "/correction": ("livezmp.Correction", {
        "type": "object",
        "description": "Online balance correction of one frame.",
        "properties": {
            "index": {"type": "integer"},
            "t": {"type": "number", "description": "s"},
            "delta": {**_POINT, "description": "root rotation about x, y, z, rad"},
            "limited": {"type": "boolean", "description": "a rate/size limit cut the step"},
            "offsets": {"type": "object", "additionalProperties": {"type": "number"},
                        "description": "channel name → offset in SI (m, rad)"},
        },
        "required": ["index", "t", "delta"],
    }),
    "/alarm": ("livezmp.Alarm", {
        "type": "object",
        "description": "ZMP out of the support polygon for longer than the alarm threshold.",
        "properties": {
            "event": {"type": "string", "enum": ["raised", "cleared"]},
            "index": {"type": "integer", "description": "frame of the event"},
            "t": {"type": "number", "description": "frame time of the event, s"},
            "since": {"type": "number", "description": "frame time the ZMP left the polygon, s"},
            "duration": {"type": "number", "description": "time out of support so far, s"},
            "worst_margin": {"type": "number", "description": "most negative margin so far, m"},
            "message": {"type": "string"},
        },
        "required": ["event", "index", "t"],
    }),
    "/device_error": ("livezmp.DeviceError", {
        "type": "object",
        "description": "A fault of the source (bad packets, lost connection), rate-limited per kind.",
        "properties": {
            "wall_time": {"type": "number", "description": "Unix time of the first occurrence, s"},
            "kind": {"type": "string"},
            "message": {"type": "string"},
            "count": {"type": "integer", "description": "occurrences folded into this record"},
        },
        "required": ["kind", "message"],
    }),
}
TOPICS = tuple(SCHEMAS)
_FORCES = {"type": "object",
           "properties": {s: {"type": "array", "items": {"type": "number"}} for s in ("left", "right")}}
LOOP_SCHEMAS = {
    "/foot_sensors": ("livezmp.FootSensors", {
        "type": "object",
        "description": "The robot's foot sensors at one analysed input sample, beside the ZMP computed for it "
                       "(the /result of the same index); points in that result's frame: z up, metres.",
        "properties": {
            "index": {"type": "integer", "description": "input sample number, as in /input and /result"},
            "t": {"type": "number", "description": "sample time, s"},
            "forces": {**_FORCES, "description": "vertical force of each sole cell, N, in the device's order "
                                                 "(firmware boards: front-left, front-right, rear-left, rear-right)"},
            "cop_sole": {"type": "object", "description": "the board's centre of pressure per foot in its sole frame "
                                                          "(x forward, y left, from the sole's centre), m",
                         "properties": {s: {"anyOf": [_POINT2, {"type": "null"}]} for s in ("left", "right")}},
            "load": {"type": "number", "description": "sum of the forces, N"},
            "cop": {**_MAYBE_POINT, "description": "measured centre of pressure in the result's world frame, m; "
                                                   "null in flight"},
            "zmp_distance": {"type": ["number", "null"],
                             "description": "horizontal distance from the measured CoP to the computed ZMP, m"},
        },
        "required": ["index", "t", "forces"],
    }),
}


def point_message(p) -> dict | None:
    """A point (3,) as a JSON message {x, y, z}; None stays None."""
    return None if p is None else {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


def result_message(r) -> dict:
    """The ``/result`` message of a :class:`~livezmp.balance.pipeline.FrameResult`."""
    return {
        "index": r.index, "t": r.t, "support": r.support, "zmp": point_message(r.zmp),
        "clamped": point_message(r.clamped),
        "com": point_message(r.com), "inside": r.inside, "margin": r.margin, "ground_z": float(r.ground_z),
        "polygon": [{"x": float(x), "y": float(y)} for x, y in r.polygon],
        "soles": {s: [point_message(p) for p in pts] for s, pts in r.soles.items()},
    }


def input_message(index: int, t: float, channels: np.ndarray, contacts: tuple[bool, bool] | None) -> dict:
    """The ``/input`` message of one frame: raw ``channels``, sensor ``contacts`` or None."""
    return {"index": index, "t": t, "channels": channels.tolist(),
            "contacts": None if contacts is None else list(contacts)}


class Recorder:
    """Writes one session to ``path`` (see the module docstring). ``session`` holds the
    monitor settings (plain JSON values); ``channel_names`` the body's input channels;
    ``extra_schemas`` further topics (e.g. :data:`LOOP_SCHEMAS`)."""

    def __init__(self, path: str | Path, body_spec: BodySpec, session: dict, channel_names: list[str],
                 chunk_seconds: float = CHUNK_SECONDS, chunk_bytes: int = CHUNK_BYTES,
                 extra_schemas: dict[str, tuple[str, dict]] | None = None):
        self.path = Path(path)
        try:
            self._file = open(self.path, "xb")  # noqa: SIM115 - closed in close(); never overwrite a session
        except FileExistsError:
            raise InputError(f"{self.path}: already exists; record to a new file") from None
        except OSError as e:
            raise InputError(f"{self.path}: cannot record: {e.strerror}") from None
        self.chunk_seconds = chunk_seconds
        self.writer = Writer(self._file, chunk_size=chunk_bytes, compression=CompressionType.ZSTD, enable_crcs=True)
        self.writer.start(profile=PROFILE, library="livezmp")
        now = time.time_ns()
        for name, text in body_spec.files.items():
            self.writer.add_attachment(now, now, BODY_PREFIX + name, "text/plain", text.encode())
        self.writer.add_metadata("livezmp.body", {"kind": body_spec.kind, "options": json.dumps(body_spec.options)})
        self.writer.add_metadata("livezmp.session", {k: json.dumps(v) for k, v in
                                                     {**session, "channel_names": channel_names}.items()})
        self.channels = {}
        for topic, (name, schema) in {**SCHEMAS, **(extra_schemas or {})}.items():
            sid = self.writer.register_schema(name, "jsonschema", json.dumps(schema).encode())
            self.channels[topic] = self.writer.register_channel(topic, "json", sid)
        self.counts = dict.fromkeys(self.channels, 0)
        self.writer.flush()  # header, body and session on disk before the first frame
        self._last_flush = time.monotonic()
        self._closed = False

    def write(self, topic: str, message: dict, log_time_ns: int | None = None) -> None:
        """Add one message (JSON-able) on ``topic``, logged at ``log_time_ns`` (Unix ns;
        default: the current wall time)."""
        now = time.time_ns() if log_time_ns is None else log_time_ns
        self.writer.add_message(self.channels[topic], now, json.dumps(message, separators=(",", ":")).encode(), now,
                                sequence=self.counts[topic])
        self.counts[topic] += 1
        self.tick()

    def input(self, index: int, t: float, channels: np.ndarray, contacts: tuple[bool, bool] | None) -> None:
        self.write("/input", input_message(index, t, channels, contacts))

    def tick(self) -> None:
        """Close the chunk in progress if it is ``chunk_seconds`` old; call it when idle too."""
        now = time.monotonic()
        if now - self._last_flush >= self.chunk_seconds:
            self.writer.flush()
            self._last_flush = now

    def close(self, totals: dict | None = None) -> None:
        """Finish the file: ``totals`` (plain JSON values, e.g. source counters) as the
        ``livezmp.totals`` metadata record, then summary, indexes, footer."""
        if self._closed:
            return
        self._closed = True
        if totals:
            self.writer.add_metadata("livezmp.totals", {k: json.dumps(v) for k, v in totals.items()})
        self.writer.finish()
        self._file.close()


class BackgroundWriter:
    """Writes messages to a :class:`Recorder` from a thread of its own, so that a real-time
    thread only hands them over (:meth:`put`: an append, no encoding, never blocks).

    The queue holds at most ``capacity`` messages; a message that finds it full is not
    queued and is counted in ``dropped`` (per topic). Every ``period_s`` the writer thread
    wakes, lets the recorder close a chunk that is due (so a crash loses about as much as
    the monitor's recording) and encodes and writes what is queued. A message whose
    encoding or writing fails is counted in ``failed`` and the first error kept in
    ``error``; the others are still written.

    Paced: once the producer calls :meth:`idle` (a fixed-rate loop, about to sleep until
    its next deadline), the writer writes only in those windows, so it does not hold the
    interpreter (the GIL) while the loop works: a loop woken while another thread runs
    Python code waits for it up to the interpreter's switch interval."""

    def __init__(self, recorder: Recorder, capacity: int = 8192, period_s: float = 0.02):
        if capacity < 1 or not period_s > 0:
            raise InputError(f"recording queue: capacity {capacity} must be >= 1 and period {period_s} s > 0")
        self.recorder = recorder
        self.capacity = capacity
        self.period_s = period_s
        self.dropped = dict.fromkeys(recorder.channels, 0)
        self.failed = 0
        self.error: str | None = None
        self._queue: deque[tuple] = deque()
        self._until = math.inf  # monotonic time (s) until which the writer may work
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="livezmp-recorder", daemon=True)
        self._thread.start()

    def put(self, topic: str, log_time_ns: int, encode: Callable[..., dict], *args) -> bool:
        """Queue ``encode(*args)`` (run in the writer thread: it must not depend on state the
        caller changes later) for ``topic`` at ``log_time_ns``; False when the queue was full."""
        if len(self._queue) >= self.capacity:  # only the writer thread takes out: the length can only fall
            self.dropped[topic] += 1
            return False
        self._queue.append((topic, log_time_ns, encode, args))
        return True

    def idle(self, seconds: float) -> None:
        """The producer will not run for ``seconds``: write in that window, up to
        IDLE_GUARD_S before its end (and from now on, only in such windows)."""
        self._until = time.monotonic() + seconds - IDLE_GUARD_S
        self._wake.set()

    def _run(self) -> None:
        while True:
            self._wake.wait(self.period_s)
            if self._stop.is_set():
                return
            self._wake.clear()
            self._drain(self._until)

    def _drain(self, until: float = math.inf) -> None:
        """Close a chunk that is due, then write what is queued now until ``until`` (monotonic s)."""
        queue, rec, clock = self._queue, self.recorder, time.monotonic
        rec.tick()
        for _ in range(len(queue)):  # what is there now; later puts wait for the next wake-up
            if clock() >= until:
                return
            topic, log_time_ns, encode, args = queue.popleft()
            try:
                rec.write(topic, encode(*args), log_time_ns)
            except Exception as e:  # noqa: BLE001 - counted and told in the totals, never silent
                self.failed += 1
                self.error = self.error or f"{topic}: {type(e).__name__}: {e}"

    def totals(self) -> dict:
        """What was written per topic, dropped (full queue) and failed, and the first error."""
        return {"written": dict(self.recorder.counts), "dropped": dict(self.dropped),
                "dropped_total": sum(self.dropped.values()), "failed": self.failed, "error": self.error}

    def close(self, totals: dict | None = None) -> dict:
        """Write what is queued, stop the thread, finish the file with ``totals`` and this
        writer's own counts (``recording`` key of the ``livezmp.totals`` record); those counts."""
        self._stop.set()
        self._wake.set()
        self._thread.join()
        self._drain()
        mine = self.totals()
        self.recorder.close({**(totals or {}), "recording": mine})
        return mine


@dataclass
class Recording:
    """What a finished recording says about its session: ``body_spec``, ``session``
    settings, message ``counts`` per topic."""

    path: Path
    body_spec: BodySpec
    session: dict
    counts: dict[str, int]


def _broken(path: Path, why: str) -> InputError:
    return InputError(f"{path}: not a complete MCAP recording ({why}); "
                      f"if the monitor was killed, run: livezmp recover {path} -o fixed.mcap")


def open_recording(path: str | Path) -> Recording:
    """Read the session and body of a finished recording; :class:`InputError` if it is
    not one (with the ``livezmp recover`` hint for an unfinished file)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    try:
        with open(p, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None:
                raise _broken(p, "no summary")
            meta = {m.name: m.metadata for m in reader.iter_metadata()}
            files = {a.name[len(BODY_PREFIX):]: a.data.decode() for a in reader.iter_attachments()
                     if a.name.startswith(BODY_PREFIX)}
    except (McapError, struct.error, OSError, ValueError) as e:
        raise _broken(p, str(e) or type(e).__name__) from None
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
    return Recording(p, spec, session, counts)


def iter_messages(path: str | Path, topic: str) -> Iterator[dict]:
    """The decoded messages of one topic of a finished recording, in file order."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            for _, _, msg in make_reader(f).iter_messages(topics=[topic], log_time_order=False):
                yield json.loads(msg.data)
    except (McapError, struct.error) as e:
        raise _broken(p, str(e) or type(e).__name__) from None


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
    src, dst = Path(src), Path(dst)
    if not src.is_file():
        raise InputError(f"{src}: no such file")
    if dst.exists():
        raise InputError(f"{dst}: already exists; write the recovered file to a new name")
    chunks = attachments = metadata = 0
    complete, stopped = False, ""
    with open(src, "rb") as f, open(dst, "xb") as out:
        writer = Writer(out, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD, enable_crcs=True)
        copier = _Copier(writer)
        started = False
        records = StreamReader(f, emit_chunks=True, record_size_limit=1 << 30).records
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
