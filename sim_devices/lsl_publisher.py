"""A simulated capture system publishing to Lab Streaming Layer (pylsl outlets).

Two streams, as capture software publishes them:

- markers: type ``MoCap``, 3 float32 channels per marker in millimetres, with the
  channel meta-data of the LSL mocap convention (``desc/channels/channel``: ``label``
  ``NAME_X``, ``marker`` NAME, ``type`` PositionX/Y/Z, ``unit`` millimeters) and the
  lab's up axis in ``desc/setup/up_axis``; nominal rate = the trial's rate;
- force plates: type ``Force``, per plate Fx Fy Fz (newtons), Mx My Mz (newton
  meters), CoPx CoPy CoPz (millimeters), channel ``label`` ``PLATE_Fx``..., ``plate``
  PLATE, one sample per marker frame with the same timestamp.

Each sample is stamped with the frame's due time on the LSL clock (``local_clock`` at
the first frame + t); a late frame keeps its stamp, so the receiver sees it out of
order; a dropped frame is never pushed; an occluded marker is NaN.
"""

from __future__ import annotations

import pylsl

from sim_devices.impairments import Impairments
from sim_devices.mocap_trial import MocapTrial, PlayCounters, TrialFrame, TrialPlayer

PLATE_CHANNELS = (("Fx", "ForceX", "newtons", "force", 0), ("Fy", "ForceY", "newtons", "force", 1),
                  ("Fz", "ForceZ", "newtons", "force", 2), ("Mx", "MomentX", "newton meters", "moment", 0),
                  ("My", "MomentY", "newton meters", "moment", 1), ("Mz", "MomentZ", "newton meters", "moment", 2),
                  ("CoPx", "CoPX", "millimeters", "cop", 0), ("CoPy", "CoPY", "millimeters", "cop", 1),
                  ("CoPz", "CoPZ", "millimeters", "cop", 2))


def marker_info(trial: MocapTrial, name: str, source_id: str) -> pylsl.StreamInfo:
    info = pylsl.StreamInfo(name, "MoCap", 3 * len(trial.labels), trial.rate, pylsl.cf_float32, source_id)
    chans = info.desc().append_child("channels")
    for label in trial.labels:
        for axis in "XYZ":
            c = chans.append_child("channel")
            c.append_child_value("label", f"{label}_{axis}")
            c.append_child_value("marker", label)
            c.append_child_value("type", f"Position{axis}")
            c.append_child_value("unit", "millimeters")
    info.desc().append_child("setup").append_child_value("up_axis", trial.up.upper())
    info.desc().append_child("acquisition").append_child_value("manufacturer", "livezmp sim_devices")
    return info


def plate_info(trial: MocapTrial, name: str, source_id: str) -> pylsl.StreamInfo:
    info = pylsl.StreamInfo(name, "Force", len(PLATE_CHANNELS) * len(trial.plate_names), trial.rate,
                            pylsl.cf_float32, source_id)
    chans = info.desc().append_child("channels")
    for plate in trial.plate_names:
        for suffix, kind, unit, _, _ in PLATE_CHANNELS:
            c = chans.append_child("channel")
            c.append_child_value("label", f"{plate}_{suffix}")
            c.append_child_value("plate", plate)
            c.append_child_value("type", kind)
            c.append_child_value("unit", unit)
    return info


def plate_sample(f: TrialFrame) -> list[float]:
    """One Force-stream sample of frame ``f`` in the channels' units (N, N·m, mm)."""
    arrays = {"force": f.force, "moment": f.moment, "cop": f.cop * 1e3}
    return [float(arrays[a][p, i]) for p in range(len(f.force)) for _, _, _, a, i in PLATE_CHANNELS]


class LslPublisher:
    """Publishes ``trial`` to LSL as ``name`` (markers, source id ``source_id``) and, with
    plates, ``name + " plates"`` (source id ``source_id + "-plates"``); :meth:`run` plays
    it (blocking) until done or ``stop()``."""

    def __init__(self, trial: MocapTrial, name: str = "livezmp-sim", source_id: str = "livezmp-sim",
                 impairments: Impairments | None = None, speed: float = 1.0, loop: bool = False,
                 max_frames: int | None = None, plates: bool = True):
        self.trial = trial
        self.player = TrialPlayer(trial, impairments, speed, loop, max_frames)
        self.markers = pylsl.StreamOutlet(marker_info(trial, name, source_id))
        self.plates = (pylsl.StreamOutlet(plate_info(trial, name + " plates", source_id + "-plates"))
                       if plates and trial.plate_names else None)
        self._t0: float | None = None

    @property
    def counters(self) -> PlayCounters:
        return self.player.counters

    def has_consumers(self) -> bool:
        return self.markers.have_consumers() and (self.plates is None or self.plates.have_consumers())

    def _send(self, f: TrialFrame) -> None:
        markers, plates = self.markers, self.plates  # close() may withdraw them meanwhile
        if markers is None:
            return
        if self._t0 is None:
            self._t0 = pylsl.local_clock() - f.t
        stamp = self._t0 + f.t
        markers.push_sample((f.markers * 1e3).ravel().tolist(), stamp)
        if plates is not None:
            plates.push_sample(plate_sample(f), stamp)

    def run(self) -> PlayCounters:
        return self.player.play(self._send)

    def stop(self) -> None:
        self.player.stop.set()

    def close(self) -> None:
        """Withdraw the streams (a capture PC that goes away)."""
        self.stop()
        self.markers = self.plates = None
