"""What the live loop records (``livezmp run --record FILE.mcap``), in the monitor's MCAP
format (:mod:`livezmp.recording`), so Foxglove plots the measured centre of pressure and
the computed ZMP side by side:

- ``/input``: every good cycle's sample: ``channels`` = the base placed from the joints
  and the joint positions (m, rad, the body's channel order) as the estimator got them,
  ``contacts`` from the foot sensors when they were used, else null. ``index`` counts
  the loop's samples from 0 over the whole run (a cycle whose read failed leaves a gap);
- ``/result``: every analysed sample (:func:`~livezmp.recording.schemas.result_message`), same
  ``index`` as its input;
- ``/foot_sensors``: the foot sensors read with that sample, the measured CoP in the
  result's world frame and its distance to the computed ZMP (:data:`LOOP_SCHEMAS`);
- ``/correction``: every command sent while correcting: ``offsets`` the correction
  offsets in those goals (joint -> rad, after the safety limits), ``delta`` the
  corrector's root rotation (rad), ``limited`` whether a limit cut them;
- ``/device_error``: every fault the loop met and what it did about it, at its loop time ``t``: a
  read that failed (``read_error``), the port gone (``link_down``) and back (``reconnected``), the
  link unusable, a rejected frame (``stale``, ``corrupted``), a failed write, the watchdog's stop
  and the frames' return (``watchdog``, ``resumed``), a servo's hardware error and the safe stop
  it latched, goals the joints' speed limits cut (``goal_speed``). Repeating kinds are folded as
  the loop tells them (at most one record a second, ``count`` the occurrences it stands for, so the
  counts add up to the summary's).

Messages of one sample share its log time (the run's start on the wall clock plus the
sample's loop time), so the ``/result`` and ``/foot_sensors`` of a sample, written
``lag`` samples after its ``/input``, line up with it. The loop's thread only queues
Python objects; a :class:`~livezmp.recording.writer.BackgroundWriter` encodes them in its own
thread, while the loop sleeps between cycles. Everything queued must stay unchanged
afterwards: the loop hands over arrays it makes fresh every cycle, and results and sensor
readings it never modifies.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from livezmp.balance.pipeline import FrameResult
from livezmp.links.base import FootSensors
from livezmp.model.body_spec import BodySpec
from livezmp.recording.schemas import LOOP_SCHEMAS, input_message, point_message, result_message
from livezmp.recording.writer import BackgroundWriter, Recorder


def _result_at(index: int, r: FrameResult) -> dict:
    return {**result_message(r), "index": index}


def foot_message(index: int, t: float, feet: FootSensors, cop: np.ndarray | None, distance: float | None) -> dict:
    """The ``/foot_sensors`` message of one analysed sample (see :data:`LOOP_SCHEMAS`)."""
    return {"index": index, "t": t, "forces": {s: np.asarray(f, dtype=float).tolist() for s, f in feet.forces.items()},
            "cop_sole": {s: None if c is None else {"x": float(c[0]), "y": float(c[1])} for s, c in feet.cop.items()},
            "load": float(sum(float(np.sum(f)) for f in feet.forces.values())),
            "cop": point_message(cop), "zmp_distance": distance}


class LoopRecorder:
    """The live loop's recording to ``path`` (see module docstring): ``spec`` the body it
    analyses, ``session`` its settings (plain JSON values), ``joint_names`` the link's
    joints; ``capacity`` (messages) and ``period_s`` of the background writer."""

    def __init__(self, path: str | Path, spec: BodySpec, session: dict, channel_names: list[str],
                 joint_names: list[str], capacity: int = 8192, period_s: float = 0.02):
        self.path = Path(path)
        self.joint_names = list(joint_names)
        self.writer = BackgroundWriter(Recorder(path, spec, session, channel_names, extra_schemas=LOOP_SCHEMAS,
                                                scene=False),  # the loop writes JSON only (yet)
                                       capacity, period_s)
        self._origin_ns = time.time_ns()

    def start(self) -> None:
        """Loop time 0 is now (the log times count from here)."""
        self._origin_ns = time.time_ns()

    def _ns(self, t: float) -> int:
        return self._origin_ns + int(t * 1e9)

    def input(self, index: int, t: float, channels: np.ndarray, contacts: tuple[bool, bool] | None,
              gravity: np.ndarray | None = None) -> None:
        self.writer.put("/input", self._ns(t), input_message, index, t, channels, contacts, gravity)

    def result(self, index: int, r: FrameResult) -> None:
        self.writer.put("/result", self._ns(r.t), _result_at, index, r)

    def feet(self, index: int, t: float, feet: FootSensors, cop: np.ndarray | None, distance: float | None) -> None:
        self.writer.put("/foot_sensors", self._ns(t), foot_message, index, t, feet, cop, distance)

    def correction(self, index: int, t: float, delta: np.ndarray, limited: bool, offsets: np.ndarray) -> None:
        self.writer.put("/correction", self._ns(t), self._correction_message, index, t, delta, limited, offsets)

    def _correction_message(self, index: int, t: float, delta: np.ndarray, limited: bool,
                            offsets: np.ndarray) -> dict:
        return {"index": index, "t": t, "delta": point_message(delta), "limited": limited,
                "offsets": dict(zip(self.joint_names, offsets.tolist(), strict=True))}

    def fault(self, t: float, kind: str, message: str, count: int) -> None:
        """A ``/device_error`` record of ``count`` faults of ``kind`` at loop time ``t`` (s)."""
        self.writer.put("/device_error", self._ns(t), self._fault_message, t, kind, message, count)

    def _fault_message(self, t: float, kind: str, message: str, count: int) -> dict:
        return {"t": t, "wall_time": self._origin_ns / 1e9 + t, "kind": kind, "message": message, "count": count}

    def idle(self, seconds: float) -> None:
        """The loop sleeps for ``seconds``: the writer's window (see :meth:`BackgroundWriter.idle`)."""
        self.writer.idle(seconds)

    def close(self, totals: dict | None = None) -> dict:
        """Write what is queued and finish the file (``totals``: e.g. the run's summary);
        what was written, dropped and failed (see :meth:`BackgroundWriter.totals`)."""
        return {"path": str(self.path), **self.writer.close(totals)}
