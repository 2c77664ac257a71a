"""Reading a recording back: the body and session it was made with, and its messages."""

from __future__ import annotations

import json
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader

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
