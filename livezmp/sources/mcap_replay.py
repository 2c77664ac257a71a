"""Replay of a livezmp recording (MCAP): its ``/input`` frames through the recorded body.

The body is rebuilt from the recording's attachments, and frames are read lazily, one
chunk at a time, so a long session replays in bounded memory. Paced like a file
replay (``speed`` 0 = as fast as possible).
"""

from __future__ import annotations

import numpy as np

from livezmp.errors import InputError
from livezmp.model.body_spec import body_from_spec
from livezmp.recording.reader import iter_messages, open_recording
from livezmp.sources.file_replay import Pacer
from livezmp.sources.interface import ErrorLog, SourceFrame, SourceStats


class McapReplaySource:
    """Frames of the ``/input`` topic of the recording at ``path``."""

    def __init__(self, path: str, speed: float = 0.0):
        self.recording = open_recording(path)
        self.name = str(path)
        self.body_spec = self.recording.body_spec
        self.body = body_from_spec(self.body_spec)
        fps = self.recording.session.get("fps")
        if not isinstance(fps, int | float) or not fps > 0:
            raise InputError(f"{path}: the recording's session has no frame rate (livezmp.session fps)")
        self.nominal_dt = 1.0 / fps
        self.pacer = Pacer(speed, self.name)
        self.stats, self.errors = SourceStats(), ErrorLog()
        self._messages = iter_messages(path, "/input")
        self._pending: dict | None = None
        self._t0: float | None = None
        self._done = False

    @property
    def finished(self) -> bool:
        return self._done

    def read(self, timeout: float) -> SourceFrame | None:
        if self._done:
            return None
        if self._pending is None:
            self._pending = next(self._messages, None)
            if self._pending is None:
                self._done = True
                return None
        m = self._pending
        if self._t0 is None:
            self._t0 = m["t"]
        sent = self.pacer.due(m["t"] - self._t0, timeout)
        if sent is None:
            return None
        self._pending = None
        self.stats.delivered += 1
        contacts = m.get("contacts")
        return SourceFrame(m["t"], np.array(m["channels"], dtype=float),
                           None if contacts is None else (bool(contacts[0]), bool(contacts[1])), sent)

    def close(self) -> None:
        self._done = True
        self._messages.close()
