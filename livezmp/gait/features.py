"""The waveform features of one walk: frequency, per-channel DC and amplitude, stride, speed.

Over the whole gait cycles only (see :mod:`.cycles`), every rotation channel is fitted
with the walk's fundamental and its first harmonics (:mod:`.harmonics`): DC is the
fit's constant (the mean over whole cycles, the paper's 1/N Σ f(x_n)); the amplitude
A is sqrt(Σ a_k² + b_k²) = √2 × RMS of the cycle-periodic part about the mean, i.e. the
amplitude of a sinusoid and, for any waveform, a number that scales exactly when the
waveform is scaled about its mean. Speed is the root's ground-plane distance covered
cycle to cycle (sum of per-cycle chords) over the time taken; stride length is
speed / frequency (distance per gait cycle).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from livezmp.gait import harmonics as hm
from livezmp.gait.channels import ChannelTag, reference_channel
from livezmp.gait.cycles import Cycles, detect_cycles, max_harmonics
from livezmp.gait.take import GaitTake

HARMONICS = 5


@dataclass
class WalkFeatures:
    """``frequency`` Hz (gait cycles per second, common to all channels); ``dc`` and
    ``amplitude`` (C,) rad per rotation channel (same order as ``tags``); ``stride_length``
    m per cycle; ``speed`` m/s; ``cycles`` the whole cycles used."""

    source: str
    tags: list[ChannelTag]
    cycles: Cycles
    dc: np.ndarray
    amplitude: np.ndarray
    stride_length: float
    speed: float

    @property
    def frequency(self) -> float:
        return self.cycles.frequency

    def to_json(self) -> dict:
        """Plain JSON data (angles rad, times s), read back by :meth:`from_json`: how a library run
        keeps one take's features on disk between the worker that computed them and the population."""
        return {"source": self.source, "tags": [asdict(t) for t in self.tags],
                "events_s": self.cycles.events.tolist(), "frequency_hz": self.cycles.frequency,
                "dc_rad": self.dc.tolist(), "amplitude_rad": self.amplitude.tolist(),
                "stride_length_m": self.stride_length, "speed_mps": self.speed}

    @classmethod
    def from_json(cls, d: dict) -> WalkFeatures:
        return cls(d["source"], [ChannelTag(**t) for t in d["tags"]],
                   Cycles(np.asarray(d["events_s"], dtype=float), float(d["frequency_hz"])),
                   np.asarray(d["dc_rad"], dtype=float), np.asarray(d["amplitude_rad"], dtype=float),
                   float(d["stride_length_m"]), float(d["speed_mps"]))


def walk_features(take: GaitTake, harmonics: int = HARMONICS) -> WalkFeatures:
    """Features of ``take`` (see module doc). Raises InputError for takes with < 2 cycles."""
    ref = reference_channel(take.tags, take.source)
    angles = take.angles
    cyc = detect_cycles(take.t, angles[:, ref], f"{take.source}: {take.tags[ref].name}", harmonics,
                        min_cycles=take.min_cycles)
    inside = cyc.window(take.t)
    h = max_harmonics(cyc.frequency, 1.0 / float(np.median(np.diff(take.t))), harmonics)
    coef, _ = hm.fit(take.t[inside], angles[inside], cyc.frequency, h)
    dc, amp = hm.mean_and_amplitude(coef, h)
    g = take.ground()
    at_events = np.column_stack([np.interp(cyc.events, take.t, g[:, k]) for k in range(2)])
    distance = float(np.sum(np.linalg.norm(np.diff(at_events, axis=0), axis=1)))
    speed = distance / float(cyc.events[-1] - cyc.events[0])
    return WalkFeatures(take.source, take.tags, cyc, dc, amp, speed / cyc.frequency, speed)
