"""Lab Streaming Layer live: ``lsl://[NAME][?type=&source_id=&plates=&up=&timeout=&align=]`` through pylsl.

The markers stream is resolved by name (``NAME``), else ``source_id``, else ``type``
(``MoCap`` by default). Its channels are read from the LSL mocap meta-data convention
(``desc/channels/channel``: ``marker`` (else the ``label`` without its ``_X`` suffix),
``type`` PositionX/Y/Z, ``unit`` millimeters/centimeters/meters); the up axis from
``desc/setup/up_axis``, else ``?up=`` (it is never assumed). Force plates come from a
second stream: ``?plates=NAME``, else a stream of type ``Force`` on the markers' host
(``plates=none``: without). Its channels are named by ``plate`` (else the label before
its last ``_``) and ``type`` ForceX/Y/Z (N), MomentX/Y/Z (N·m, or N·mm), CoPX/Y/Z
(length units as above).

Times: each sample's LSL timestamp plus the stream's clock offset (``time_correction``, refreshed
every second) is on this machine's LSL clock, so ``latency`` is the time from the capture's stamp to
the sample's arrival here. Frame numbers are the stamps in frame periods from the first, so drops
(numbers skipped), late samples (stamped before one already delivered) and duplicates are counted
exactly for a stream stamped at its nominal rate. A stamp far ahead, or not after the last, is
dropped as the UDP streams' are (:class:`~livezmp.sources.udp.Timeline`). Plates are paired with the
marker frame of the same number; a marker frame waits at most ``align`` frame periods for its plates
(``?align=``, default 3), then goes without (``plates_missing``): a longer wait delays every frame
whose plate sample is late by as much. LSL re-connects by itself when a stream with the same source
id comes back: data resuming after more than 0.5 s of silence counts as a reconnect. Frames pulled
and not yet read are at most liblsl's own buffer (10 s of frames); more, from a reader that far
behind, are counted as ``overflow``.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import replace
from urllib.parse import urlsplit

import numpy as np

from livezmp.errors import InputError
from livezmp.sources.interface import ErrorLog, SourceStats
from livezmp.sources.mocap_frame import MocapFrame, PlateSamples, parse_up_axis
from livezmp.sources.udp import Timeline
from livezmp.sources.url_query import query_params, query_seconds

LENGTH = {"millimeters": 1e-3, "mm": 1e-3, "centimeters": 1e-2, "cm": 1e-2, "meters": 1.0, "m": 1.0}
MOMENT = {"newton meters": 1.0, "nm": 1.0, "n.m": 1.0, "newton millimeters": 1e-3, "nmm": 1e-3, "n.mm": 1e-3}
FORCE = {"newtons": 1.0, "n": 1.0}
PLATE_KINDS = {"force": ("force", FORCE), "moment": ("moment", MOMENT), "cop": ("cop", LENGTH)}
QUERY_KEYS = {"type", "source_id", "plates", "up", "timeout", "align"}
SILENCE = 0.5
WAIT_S = 0.1  # s: longest single wait inside liblsl for a marker sample


def _channels(info) -> list[dict[str, str]]:
    out = []
    ch = info.desc().child("channels").child("channel")
    while not ch.empty():
        out.append({k: ch.child_value(k) for k in ("label", "marker", "plate", "type", "unit")})
        ch = ch.next_sibling("channel")
    return out


def marker_layout(info, where: str) -> tuple[tuple[str, ...], np.ndarray, float]:
    """Marker labels (n,), channel index (n, 3) of each marker's x, y, z, and metres per
    unit, from a MoCap stream's channel meta-data."""
    chans = _channels(info)
    if len(chans) != info.channel_count():
        raise InputError(f"{where}: {len(chans)} channels described, the stream has {info.channel_count()} "
                         "(no LSL mocap channel meta-data?)")
    labels: list[str] = []
    index: dict[str, list[int]] = {}
    scales = set()
    for i, c in enumerate(chans):
        kind = c["type"].lower()
        if not kind.startswith("position") or kind[-1:] not in "xyz":
            continue
        name = c["marker"] or c["label"].rsplit("_", 1)[0]
        if name not in index:
            labels.append(name)
            index[name] = [-1, -1, -1]
        index[name]["xyz".index(kind[-1])] = i
        unit = c["unit"].lower()
        if unit not in LENGTH:
            raise InputError(f"{where}: channel {i} ({c['label']}): unit {c['unit']!r} is not a length "
                             f"({', '.join(LENGTH)})")
        scales.add(LENGTH[unit])
    incomplete = [n for n in labels if -1 in index[n]]
    if incomplete or not labels:
        raise InputError(f"{where}: marker {incomplete[0]!r} lacks a PositionX/Y/Z channel" if incomplete
                         else f"{where}: no PositionX/Y/Z channels")
    if len(scales) > 1:
        raise InputError(f"{where}: markers in mixed units")
    return tuple(labels), np.array([index[n] for n in labels]), scales.pop()


def plate_layout(info, where: str) -> tuple[tuple[str, ...], dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Plate names (p,) and per quantity (force, moment, cop) channel index (p, 3) (-1
    absent) and scale to SI (p, 3), from a Force stream's channel meta-data."""
    chans = _channels(info)
    names: list[str] = []
    idx = {q: [] for q in PLATE_KINDS}
    scale = {q: [] for q in PLATE_KINDS}
    for i, c in enumerate(chans):
        kind = c["type"].lower()
        q = next((q for q in PLATE_KINDS if kind.startswith(q) and kind[len(q):] in ("x", "y", "z")), None)
        if q is None:
            continue
        name = c["plate"] or c["label"].rsplit("_", 1)[0]
        if name not in names:
            names.append(name)
            for k in PLATE_KINDS:
                idx[k].append([-1, -1, -1])
                scale[k].append([1.0, 1.0, 1.0])
        units = PLATE_KINDS[q][1]
        unit = c["unit"].lower()
        if unit not in units:
            raise InputError(f"{where}: channel {i} ({c['label']}): unit {c['unit']!r} for {c['type']} "
                             f"(one of {', '.join(units)})")
        p, a = names.index(name), "xyz".index(kind[-1])
        idx[q][p][a] = i
        scale[q][p][a] = units[unit]
    if not names:
        raise InputError(f"{where}: no ForceX/Y/Z, MomentX/Y/Z or CoPX/Y/Z channels")
    return tuple(names), {q: np.array(v, int) for q, v in idx.items()}, {q: np.array(v) for q, v in scale.items()}


def _resolve(prop: str, value: str, timeout: float):
    import pylsl

    found = pylsl.resolve_byprop(prop, value, 1, timeout)
    return found[0] if found else None


class LslSource:
    """Markers (and plates) from LSL; see the module docstring. ``url`` is the
    ``lsl://`` URL; ``align`` frame periods a marker frame waits for its plates."""

    def __init__(self, url: str, align: float = 3.0, buffer_s: int = 10):
        import pylsl

        self.name = url
        u = urlsplit(url)
        query = query_params(url, QUERY_KEYS)
        timeout = query_seconds(query, "timeout", 5.0, url)
        try:
            align = float(query.get("align", align))
        except ValueError:
            align = math.nan
        if not (math.isfinite(align) and align >= 0):
            raise InputError(f"{url}: align: need frame periods (a number >= 0), got {query.get('align', align)!r}")
        prop, value = (("name", u.netloc + u.path.rstrip("/")) if u.netloc else
                       ("source_id", query["source_id"]) if "source_id" in query else
                       ("type", query.get("type", "MoCap")))
        info = _resolve(prop, value, timeout)
        if info is None:
            raise InputError(f"{url}: no LSL stream with {prop} {value!r} found within {timeout:g} s")
        self.inlet = pylsl.StreamInlet(info, max_buflen=buffer_s, recover=True)
        self.inlet.open_stream(timeout)
        full = self.inlet.info(timeout)
        self.labels, self.index, self.scale = marker_layout(full, url)
        up = full.desc().child("setup").child_value("up_axis") or query.get("up", "")
        if not up:
            raise InputError(f"{url}: the stream does not say its up axis (desc/setup/up_axis); give ?up=z (or y)")
        try:
            self.up = parse_up_axis(up, url)
        except ValueError as e:
            raise InputError(str(e)) from None
        rate = full.nominal_srate()
        if not rate > 0:
            raise InputError(f"{url}: the markers stream has no nominal rate (irregular); need a fixed frame rate")
        self.rate, self.nominal_dt = rate, 1.0 / rate
        self.plates = None
        if query.get("plates", "") != "none":
            self.plates = self._open_plates(query.get("plates"), full.hostname(), timeout, buffer_s)
        self.stats, self.errors = SourceStats(), ErrorLog()
        self.order = Timeline(self.stats, self.errors)
        self.align = align
        self.offset = self.inlet.time_correction(timeout)
        self._offset_at = time.monotonic()
        self._first: float | None = None  # stamp of frame 0, sender's clock
        self._pending: deque[MocapFrame] = deque()  # pulled, not yet read: at most _max_pending
        self._max_pending = max(1, int(buffer_s * rate))  # as many as liblsl's own buffer keeps
        self._plate_rows: dict[int, np.ndarray] = {}
        self._last_data = time.monotonic()
        self._closed = False

    def _open_plates(self, name: str | None, host: str, timeout: float, buffer_s: int):
        import pylsl

        if name:
            info = _resolve("name", name, timeout)
            if info is None:
                raise InputError(f"{self.name}: plates: no LSL stream named {name!r}")
        else:
            found = [i for i in pylsl.resolve_byprop("type", "Force", 0, min(timeout, 1.0)) if i.hostname() == host]
            if not found:
                return None
            info = found[0]
        inlet = pylsl.StreamInlet(info, max_buflen=buffer_s, recover=True)
        inlet.open_stream(timeout)
        self.plate_names, self.plate_index, self.plate_scale = plate_layout(inlet.info(timeout), self.name)
        return inlet

    @property
    def finished(self) -> bool:
        return self._closed

    def _number(self, stamp: float) -> int:
        if self._first is None:
            self._first = stamp
        return int(round((stamp - self._first) * self.rate))

    def _refresh_offset(self, now: float) -> None:
        if now - self._offset_at >= 1.0:
            self._offset_at = now
            try:
                self.offset = self.inlet.time_correction(0.0)
            except Exception:  # pylsl raises TimeoutError/LostError; keep the last offset
                pass

    def _pull(self, wait: float = 0.0) -> None:
        """Take the samples the streams hold; with none there, wait up to ``wait`` s for the next marker
        sample inside liblsl (which lets the interpreter run other threads meanwhile), not by polling."""
        import pylsl

        samples, stamps = self.inlet.pull_chunk(0.0)
        if not stamps and wait > 0:
            row, stamp = self.inlet.pull_sample(wait)
            if stamp is not None:
                more, more_stamps = self.inlet.pull_chunk(0.0)
                samples, stamps = [row, *more], [stamp, *more_stamps]
        received, clock = time.monotonic(), pylsl.local_clock()
        if stamps:
            if received - self._last_data > SILENCE and self.stats.delivered:
                self.stats.reconnects += 1
                self.errors.report("disconnected", f"{self.name}: no data for {received - self._last_data:.1f} s")
            self._last_data = received
        self._refresh_offset(received)
        for row, stamp in zip(samples, stamps, strict=True):
            if not math.isfinite(stamp):  # no frame number: dropped (int(nan) raised out of read())
                self.order.drop("malformed", f"{self.name}: stamp {stamp} is not a finite number of seconds")
                continue
            k = self._number(stamp)
            restart = self.order.admit(k, stamp, self.name)  # the sender's stamps: the offset's refreshes move t
            if restart is None:
                continue
            v = np.asarray(row, float)
            markers = v[self.index] * self.scale
            t = stamp + self.offset
            if len(self._pending) >= self._max_pending:  # the reader is buffer_s behind: drop the newest, as
                self.stats.overflow += 1  # FrameQueue does, so that what is delivered stays in order
                continue
            self._pending.append(MocapFrame(t, received, k, self.labels, markers, self.up, latency=clock - t,
                                            restart=restart))
        if self.plates is not None:
            rows, pstamps = self.plates.pull_chunk(0.0)
            for row, stamp in zip(rows, pstamps, strict=True):
                if math.isfinite(stamp):  # else no frame to pair it with
                    self._plate_rows[self._number(stamp)] = np.asarray(row, float)
            if len(self._plate_rows) > 4 * self.rate:  # bounded: keep the newest few seconds
                for k in sorted(self._plate_rows)[: len(self._plate_rows) - int(2 * self.rate)]:
                    del self._plate_rows[k]

    def _plates_of(self, k: int) -> PlateSamples | None:
        row = self._plate_rows.pop(k, None)
        if row is None:
            return None
        out = {}
        for q in PLATE_KINDS:
            i = self.plate_index[q]
            out[q] = np.where(i >= 0, row[np.maximum(i, 0)] * self.plate_scale[q], np.nan if q == "cop" else 0.0)
        return PlateSamples(self.plate_names, out["force"], out["moment"], out["cop"])

    def _ready(self, now: float) -> MocapFrame | None:
        if not self._pending:
            return None
        f = self._pending[0]
        if self.plates is None:
            return self._pending.popleft()
        plates = self._plates_of(f.frame)
        if plates is None and now - f.received < self.align * self.nominal_dt:
            return None
        self._pending.popleft()
        if plates is None:
            self.errors.report("plates_missing", f"{self.name}: frame {f.frame} without its force-plate sample")
            return f
        return replace(f, plates=plates)

    def read(self, timeout: float) -> MocapFrame | None:
        deadline = time.monotonic() + timeout
        while not self._closed:
            # wait in liblsl for the next marker sample, unless a frame already waits for its plates
            self._pull(0.0 if self._pending else min(max(deadline - time.monotonic(), 0.0), WAIT_S))
            now = time.monotonic()
            f = self._ready(now)
            if f is not None or now >= deadline:
                return f
            if self._pending:  # its plate sample is due within ``align`` periods: poll the plates at 2 kHz
                time.sleep(min(0.0005, max(deadline - now, 0.0)))
        return None

    def close(self) -> None:
        self._closed = True
        self.inlet.close_stream()
        if self.plates is not None:
            self.plates.close_stream()
