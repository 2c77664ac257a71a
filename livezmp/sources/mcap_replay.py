"""Replay of a livezmp recording (MCAP): its ``/input`` frames through the recorded body.

The body is rebuilt from the recording's attachments, and frames are read lazily, one
chunk at a time, so a long session replays in bounded memory. Paced like a file
replay (``speed`` 0 = as fast as possible).
"""

from __future__ import annotations

import math

import numpy as np

from livezmp.checks import MAX_CHANNEL_VALUE
from livezmp.errors import InputError
from livezmp.model.body_spec import body_from_spec
from livezmp.recording.reader import damaged_as_input_error, iter_messages, open_recording
from livezmp.sources.file_replay import Pacer
from livezmp.sources.frame_format import MAX_TIME_S
from livezmp.sources.interface import ErrorLog, SourceFrame, SourceStats


class McapReplaySource:
    """Frames of the ``/input`` topic of the recording at ``path``."""

    def __init__(self, path: str, speed: float = 0.0):
        self.recording = open_recording(path)
        self.name = str(path)
        self.body_spec = self.recording.body_spec
        try:
            with damaged_as_input_error(self.recording.path):
                self.body = body_from_spec(self.body_spec)
        except InputError as e:  # the message names a temporary file: name the recording
            raise InputError(f"{path}: the recorded body: {str(e).split(': ', 1)[-1]}") from None
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
        t = m.get("t")
        if type(t) not in (int, float) or not abs(t) <= MAX_TIME_S:
            t = 0.0  # refused with its message below, once due
        if self._t0 is None:
            self._t0 = t
        sent = self.pacer.due(t - self._t0, timeout)
        if sent is None:
            return None
        self._pending = None
        self.stats.delivered += 1
        t, channels, contacts = self._checked(m)
        return SourceFrame(t, channels, contacts, sent, gravity=self._gravity(m))

    def _gravity(self, m: dict) -> np.ndarray | None:
        """An ``/input`` message's gravity (3,) m/s², None when it has none."""
        g = m.get("gravity")
        if g is None:
            return None
        if not isinstance(g, list) or len(g) != 3 or not all(type(v) in (int, float) and abs(v) <= 100 for v in g) \
                or not 1.0 <= math.hypot(*g) <= 100:
            raise InputError(f"{self.name}: /input message {self.stats.delivered - 1}: gravity: need [x, y, z] "
                             "in m/s^2, of 1 to 100 m/s^2")
        return np.array(g, dtype=float)

    def _checked(self, m: dict) -> tuple[float, np.ndarray, tuple[bool, bool] | None]:
        """An ``/input`` message's time, channels and contacts, checked as a UDP frame is."""
        where = f"{self.name}: /input message {self.stats.delivered - 1}"
        t, values, contacts = m.get("t"), m.get("channels"), m.get("contacts")
        if type(t) not in (int, float) or not abs(t) <= MAX_TIME_S:
            raise InputError(f"{where}: t {t!r} is not a finite time"[:200])
        if not isinstance(values, list) or len(values) != self.body.nq or \
                not all(type(v) in (int, float) and abs(v) <= MAX_CHANNEL_VALUE for v in values):
            raise InputError(f"{where}: channels: need {self.body.nq} finite numbers")
        if contacts is not None and (not isinstance(contacts, list) or len(contacts) != 2):
            raise InputError(f"{where}: contacts: need [left, right]")
        return float(t), np.array(values, dtype=float), None if contacts is None else (bool(contacts[0]),
                                                                                        bool(contacts[1]))

    def close(self) -> None:
        self._done = True
        self._messages.close()
