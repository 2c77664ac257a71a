"""Writing a recording: :class:`Recorder`, and :class:`BackgroundWriter` for real-time threads.

Crash safety: chunks (zstd, CRC of each chunk's data) are closed and handed to the
kernel at least every ``chunk_seconds`` (0.5 s), so a killed monitor loses at most
that much. Such a file has no summary; :func:`livezmp.recording.recover.recover` copies
every intact record into a complete file. A file that can no longer be written (a full
disk, a file size limit, an I/O error) stops the recording, not the session: the first
error is kept (:attr:`Recorder.error`), later messages are counted as not written, and
what reached the file before stays there for ``recover``.

A real-time thread hands its messages to a :class:`BackgroundWriter`, which encodes and
writes them in a thread of its own from a bounded queue, and counts what a full queue
turned away.
"""

from __future__ import annotations

import contextlib
import json
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from livezmp.errors import InputError
from livezmp.model.body_spec import BodySpec
from livezmp.recording import foxglove
from livezmp.recording.schemas import BODY_PREFIX, PROFILE, SCHEMAS, input_message, point_message, result_message

CHUNK_SECONDS = 0.5
IDLE_GUARD_S = 2.5e-4  # a paced writer stops this long before the producer wakes (a message takes < 0.1 ms)
CHUNK_BYTES = 1 << 20
SCENE_HZ = 60.0  # Foxglove scene messages a second at most: a display's rate (/result keeps every frame)


def stopped_note(path: str | Path) -> str:
    """What a recording whose file failed (:attr:`Recorder.error`) still holds, and how to read it."""
    return (f"; the file stopped there, keeping what was written before: `livezmp recover {path} -o FIXED.mcap` "
            "makes it a complete file")


class Recorder:
    """Writes one session to ``path`` (see the module docstring). ``session`` holds the
    monitor settings (plain JSON values); ``channel_names`` the body's input channels;
    ``extra_schemas`` further topics (e.g. :data:`LOOP_SCHEMAS`); ``scene``: register the
    Foxglove scene channels that :meth:`result` fills (:mod:`livezmp.recording.foxglove`),
    at most ``scene_hz`` results a second of log time (None: every result). Building and
    writing a frame's scene costs about twice its ``/result`` (0.1 ms); a 1 kHz capture
    needs it no more often than a screen shows it."""

    def __init__(self, path: str | Path, body_spec: BodySpec, session: dict, channel_names: list[str],
                 chunk_seconds: float = CHUNK_SECONDS, chunk_bytes: int = CHUNK_BYTES,
                 extra_schemas: dict[str, tuple[str, dict]] | None = None, scene: bool = True,
                 scene_hz: float | None = SCENE_HZ):
        self.path = Path(path)
        self.scene_period_ns = 0 if scene_hz is None else int(1e9 / scene_hz)
        self._next_scene_ns = None
        try:
            self._file = open(self.path, "xb")  # noqa: SIM115 - closed in close(); never overwrite a session
        except FileExistsError:
            raise InputError(f"{self.path}: already exists; record to a new file") from None
        except OSError as e:
            raise InputError(f"{self.path}: cannot record: {e.strerror}") from None
        self.chunk_seconds = chunk_seconds
        try:  # the file's start: a disk that cannot take it refuses the recording before the session
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
            self.scene_channels = foxglove.register(self.writer) if scene else {}
            self.counts = dict.fromkeys(self.channels, 0) | dict.fromkeys(self.scene_channels, 0)
            self.writer.flush()  # header, body and session on disk before the first frame
        except OSError as e:
            with contextlib.suppress(OSError):  # what it still buffers cannot be written either
                self._file.close()
            raise InputError(f"{self.path}: cannot record: {e.strerror or e}") from None
        self._last_flush = time.monotonic()
        self._closed = False
        self.error: str | None = None  # the file's first write error; nothing is written after it
        self.unwritten = 0  # messages not written because of it

    def _failed(self, e: OSError) -> None:
        """The file cannot take more (disk full, size limit, I/O error): stop writing to it. The MCAP writer's
        chunk in progress stays in memory unwritten, so carrying on would grow it without bound."""
        self.error = self.error or f"{type(e).__name__}: {e}"

    def _usable(self) -> bool:
        if self.error is None:
            return True
        self.unwritten += 1
        return False

    def state(self) -> dict:
        """Messages written per topic, those not written since the file failed, and its error (None: none)."""
        return {"path": str(self.path), "written": dict(self.counts), "unwritten": self.unwritten,
                "file_error": self.error}

    def write(self, topic: str, message: dict, log_time_ns: int | None = None) -> None:
        """Add one message (JSON-able) on ``topic``, logged at ``log_time_ns`` (Unix ns;
        default: the current wall time)."""
        if not self._usable():
            return
        now = time.time_ns() if log_time_ns is None else log_time_ns
        if self._put(self.channels[topic], topic, now, json.dumps(message, separators=(",", ":")).encode()):
            self.tick()

    def _put(self, channel: int, topic: str, now: int, data: bytes) -> bool:
        """Add one encoded message on ``channel`` (``topic``'s) at ``now`` (Unix ns); False when the file has failed
        (now or before: it is then counted unwritten)."""
        if not self._usable():
            return False
        try:
            self.writer.add_message(channel, now, data, now, sequence=self.counts[topic])
        except OSError as e:  # a chunk filled up and could not be written
            self._failed(e)
            return False
        self.counts[topic] += 1
        return True

    def result(self, r, cop: np.ndarray | None = None, log_time_ns: int | None = None) -> None:
        """The ``/result`` of a FrameResult ``r`` and its Foxglove scene (when one is due), with
        the plates' measured centre of pressure ``cop`` (3,) m in the result's frame if any, at
        one log time."""
        now = time.time_ns() if log_time_ns is None else log_time_ns
        message = result_message(r)
        if cop is not None:
            message["cop"] = point_message(cop)
        self.write("/result", message, now)
        if not self.scene_channels or (self._next_scene_ns is not None and now < self._next_scene_ns):
            return
        self._next_scene_ns = now + self.scene_period_ns
        for topic, data in foxglove.scene_messages(r, now, [] if cop is None else [cop]).items():
            if not self._put(self.scene_channels[topic], topic, now, data):
                return

    def input(self, index: int, t: float, channels: np.ndarray, contacts: tuple[bool, bool] | None,
              gravity: np.ndarray | None = None) -> None:
        self.write("/input", input_message(index, t, channels, contacts, gravity))

    def tick(self) -> None:
        """Close the chunk in progress if it is ``chunk_seconds`` old; call it when idle too."""
        now = time.monotonic()
        if self.error is None and now - self._last_flush >= self.chunk_seconds:
            try:
                self.writer.flush()
            except OSError as e:
                self._failed(e)
            self._last_flush = now

    def close(self, totals: dict | None = None) -> None:
        """Finish the file: ``totals`` (plain JSON values, e.g. source counters) as the
        ``livezmp.totals`` metadata record, then summary, indexes, footer."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.error is None:
                if totals:
                    self.writer.add_metadata("livezmp.totals", {k: json.dumps(v) for k, v in totals.items()})
                self.writer.finish()
        except OSError as e:
            self._failed(e)
        try:
            self._file.close()  # flushes what the file object still buffers
        except OSError as e:
            self._failed(e)


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
        """What was written per topic, dropped (full queue) and failed (not encoded, or not written once the
        file failed), the first error, and the file's own (``file_error``: the file stopped there)."""
        rec = self.recorder
        return {"written": dict(rec.counts), "dropped": dict(self.dropped),
                "dropped_total": sum(self.dropped.values()), "failed": self.failed + rec.unwritten,
                "error": self.error or rec.error, "file_error": rec.error}

    def close(self, totals: dict | None = None) -> dict:
        """Write what is queued, stop the thread, finish the file with ``totals`` and this
        writer's own counts (``recording`` key of the ``livezmp.totals`` record); those counts."""
        self._stop.set()
        self._wake.set()
        self._thread.join()
        self._drain()
        self.recorder.close({**(totals or {}), "recording": self.totals()})
        return self.totals()  # again: finishing the file may have failed it
