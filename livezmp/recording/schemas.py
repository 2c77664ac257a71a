"""The channels of a recording, their JSON schemas, and the messages made from results.

- ``/input``: every input frame as received (raw channels, input units);
- ``/result``: per analysed frame, ZMP (raw and clamped), CoM, support, polygon,
  soles, margin (internal frame: z up, metres);
- ``/correction``: the online correction, when enabled;
- ``/alarm``: out-of-support alarms raised and cleared;
- ``/device_error``: faults of the source (bad packets, lost connections).

The live loop (``livezmp run --record``) adds ``/foot_sensors`` (:data:`LOOP_SCHEMAS`):
the robot's foot forces and measured centre of pressure beside the computed ZMP.
"""

from __future__ import annotations

import numpy as np

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
            "gravity": {"description": "gravity in the input's frame, m/s^2, from the IMU (a sloped ground); "
                                       "absent = straight down",
                        "type": "array", "items": {"type": "number"}},
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
            "cop": {**_POINT, "description": "force plates' measured centre of pressure, m (when the source has "
                                             "plates and they are loaded)"},
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
            "t": {"type": "number", "description": "the live loop's time of the event, s, as /input's t (absent in "
                                                   "the monitor's records)"},
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


def input_message(index: int, t: float, channels: np.ndarray, contacts: tuple[bool, bool] | None,
                  gravity: np.ndarray | None = None) -> dict:
    """The ``/input`` message of one frame: raw ``channels``, sensor ``contacts`` or None, and
    ``gravity`` (3,) m/s² where an IMU said where it points."""
    out = {"index": index, "t": t, "channels": channels.tolist(),
           "contacts": None if contacts is None else list(contacts)}
    if gravity is not None:
        out["gravity"] = gravity.tolist()
    return out
