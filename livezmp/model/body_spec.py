"""What a body model was built from, kept as text so a recording can rebuild it.

A live source knows its body before the first frame (a skeleton BVH, or a URDF and its
robot config). :class:`BodySpec` keeps those inputs as text plus the resolved options
(length unit and up axis as detected, not as guessed again), so ``livezmp replay`` on
another machine builds exactly the same :class:`~livezmp.model.body.BodyModel`.

A skeleton spec keeps the BVH hierarchy lines verbatim and only the frames that body
building reads (the first :data:`~livezmp.model.bvh_body.CALIBRATION_S` seconds calibrate the
feet; the first frame gives the up axis), written at full precision.
"""

from __future__ import annotations

import tempfile
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from livezmp.checks import read_input_text
from livezmp.errors import InputError
from livezmp.model.body import BodyModel, world_from_up_axis
from livezmp.model.bvh import BvhMotion, format_hierarchy, parse_bvh, parse_hierarchy
from livezmp.model.bvh_body import CALIBRATION_S, BvhBodyOptions, body_from_bvh
from livezmp.model.c3d import C3dTrial
from livezmp.model.euler_orders import StreamOrders, gimbal_orders, reexpressed
from livezmp.model.marker_map import MarkerMap
from livezmp.model.markers import MarkerBodyOptions, MarkerTake, body_from_markers, marker_labels
from livezmp.model.rest_pose import without_rest_pose
from livezmp.model.segments import SegmentTag
from livezmp.model.urdf_body import UrdfBodyOptions, body_from_urdf

SKELETON_FILE = "skeleton.bvh"
MARKERS_FILE = "markers.csv"
URDF_FILE = "robot.urdf"
ROBOT_CONFIG_FILE = "robot.toml"


@dataclass(frozen=True)
class BodySpec:
    """``kind`` "bvh", "urdf" or "markers"; ``files`` name → text; ``options`` plain JSON values."""

    kind: str
    files: dict[str, str]
    options: dict = field(default_factory=dict)


@dataclass
class Skeleton:
    """A skeleton file read: ``motion`` (its frames, or for a hierarchy alone one stand-in
    frame at a nominal 30 Hz: the rest pose, rotations zero and position channels equal
    to the offsets they replace), ``hierarchy`` its HIERARCHY lines verbatim,
    ``has_motion`` whether the file had frames (and so a real frame time); ``orders`` {joint index: rotation order}
    of the joints re-expressed clear of gimbal lock (:func:`clear_skeleton`), none as read."""

    motion: BvhMotion
    hierarchy: str
    has_motion: bool
    orders: dict[int, str] = field(default_factory=dict)


def read_skeleton(path: str | Path) -> Skeleton:
    """A BVH file (hierarchy and frames, e.g. a T-pose or a take; a take's leading rest-pose frames held at its first
    moving pose, :mod:`livezmp.model.rest_pose`), or a hierarchy alone."""
    p = Path(path)
    text = read_input_text(p, "skeleton")
    joints, cur = parse_hierarchy(text, str(p))
    lines = text.splitlines()
    hierarchy = "\n".join(lines[: cur.lineno]) + "\n"
    if any(ln.strip() for ln in lines[cur.lineno :]):
        return Skeleton(without_rest_pose(parse_bvh(text, str(p)))[0], hierarchy, True)
    rest = [j.offset["XYZ".index(c[0])] if c.endswith("position") else 0.0 for j in joints for c in j.channels]
    return Skeleton(BvhMotion(joints, 1.0 / 30.0, np.array([rest]), str(p)), hierarchy, False)


def clear_skeleton(skeleton: Skeleton) -> Skeleton:
    """``skeleton`` with its joints near gimbal lock over its frames re-expressed
    (:mod:`livezmp.model.euler_orders`) and its hierarchy text written to match; itself when none is. A file
    replayed whole is re-expressed here; a stream's frames, which come in the file's own orders, row by row by
    :class:`~livezmp.model.euler_orders.StreamOrders` with the result's ``orders``."""
    orders = gimbal_orders(skeleton.motion)
    if not orders:
        return skeleton
    motion = reexpressed(skeleton.motion, orders)
    return Skeleton(motion, format_hierarchy(motion.joints) + "\n", skeleton.has_motion, orders)


class SkeletonStream:
    """A live stream's rows (C,) of a skeleton, as its file writes them (every joint, the file's rotation orders),
    made the channels of ``body`` (built on ``clear``, the skeleton clear of gimbal lock): re-expressed row by row
    into the orders ``clear`` chose (:class:`~livezmp.model.euler_orders.StreamOrders`), then cut to the joints the
    body is built on (:meth:`BodyModel.input_rows`). ``n_channels``: C, the values each row carries;
    :meth:`restart` where the stream's timeline starts over."""

    def __init__(self, skeleton: Skeleton, clear: Skeleton, body: BodyModel):
        self.n_channels, self.body = skeleton.motion.n_channels, body
        self.orders = StreamOrders(skeleton.motion.joints, clear.orders) if clear.orders else None

    def __call__(self, row: np.ndarray) -> np.ndarray:
        return self.body.input_rows(row if self.orders is None else self.orders(row))

    def restart(self) -> None:
        if self.orders is not None:
            self.orders.restart()


def skeleton_body(skeleton: Skeleton, opts: BvhBodyOptions | None = None) -> tuple[BodyModel, BodySpec]:
    """The body of a skeleton (:func:`body_from_bvh`) and its spec."""
    opts = opts or BvhBodyOptions()
    motion = skeleton.motion
    body = body_from_bvh(motion, opts)
    n = min(len(motion.frames), max(1, round(CALIBRATION_S / motion.frame_time)))
    rows = "\n".join(" ".join(repr(float(x)) for x in row) for row in motion.frames[:n])
    text = f"{skeleton.hierarchy}MOTION\nFrames: {n}\nFrame Time: {motion.frame_time!r}\n{rows}\n"
    mapping = {k: f"{v.kind}:{v.side}" for k, v in (opts.mapping or {}).items()}
    options = {"total_mass": opts.total_mass, "units": body.units, "up_axis": body.up_axis,
               "sole_width": opts.sole_width, "heel_back": opts.heel_back, "toe_front": opts.toe_front,
               "mapping": mapping, "hat_fraction": opts.hat_fraction, "source": motion.source}
    return body, BodySpec("bvh", {SKELETON_FILE: text}, options)


def robot_body(urdf: str | Path, opts: UrdfBodyOptions | None = None) -> tuple[BodyModel, BodySpec]:
    """Body and spec of a URDF robot; the spec carries the robot config in use when it is
    a file (given, or beside the URDF); the built-in configs are found again by robot name."""
    opts = opts or UrdfBodyOptions()
    path = Path(urdf)
    body = body_from_urdf(path, opts)
    files = {URDF_FILE: read_input_text(path, "URDF")}
    config = Path(opts.config) if opts.config else path.with_suffix(".toml")
    if config.is_file():
        files[ROBOT_CONFIG_FILE] = read_input_text(config, "robot config")
    options = {"sole_length": opts.sole_length, "sole_width": opts.sole_width, "sole_drop": opts.sole_drop,
               "source": str(path)}
    return body, BodySpec("urdf", files, options)


def marker_body(trial: C3dTrial, opts: MarkerBodyOptions | None = None) -> tuple[MarkerTake, BodySpec]:
    """The marker body of a C3D trial (:func:`body_from_markers`) and its spec: the markers it is built
    from (every frame, at full precision; NaN where unseen) and the subject's parameters."""
    opts = opts or MarkerBodyOptions()
    take = body_from_markers(trial, opts)
    labels = [lab for lab in marker_labels(trial, opts.marker_map) if lab in trial.labels]
    pts = np.stack([trial.marker(lab) for lab in labels], axis=1).reshape(len(trial.points), -1)
    text = ",".join(f"{lab}_{c}" for lab in labels for c in "xyz") + "\n" + "\n".join(
        ",".join(repr(float(v)) for v in row) for row in pts) + "\n"
    options = {"rate": trial.rate, "total_mass": opts.total_mass, "height_m": trial.height_m,
               "widths_m": trial.widths_m, "hat_offset": opts.hat_offset, "hat_fraction": opts.hat_fraction,
               "trunk_fraction": opts.trunk_fraction, "trunk_offset": opts.trunk_offset,
               "floor_z": opts.floor_z, "hat_sway_gain": opts.hat_sway_gain,
               "hat_follow_hz": opts.hat_follow_hz, "source": trial.source,
               "marker_map": None if opts.marker_map is None else asdict(opts.marker_map), "bsp": opts.bsp,
               "age_years": trial.age_years if opts.age_years is None else opts.age_years}
    return take, BodySpec("markers", {MARKERS_FILE: text}, options)


def stream_marker_body(take: MarkerTake, spec: BodySpec, up: str) -> tuple[BodyModel, BodySpec]:
    """A marker body calibrated on ``take`` (spec ``spec``) for a live stream whose up axis is ``up``
    ("+y"): its outputs go back into the stream's axes; the spec says so, so the body is rebuilt the same."""
    body = replace(take.body, world_from_input=world_from_up_axis(up), up_axis=up.lstrip("+"))
    return body, replace(spec, options={**spec.options, "input_up": up})


def _marker_map(d: dict | None) -> MarkerMap | None:
    """A marker map from its spec form (:func:`dataclasses.asdict`: tuples turned lists)."""
    if d is None:
        return None
    tup = lambda v: tuple(tup(x) for x in v) if isinstance(v, list) else v  # noqa: E731
    return MarkerMap(d["source"], tup(d["labels"]), tup(d["segments"]), tup(d["joints"]), d.get("stature_m"))


def _markers_from_spec(spec: BodySpec) -> BodyModel:
    o = spec.options
    lines = spec.files[MARKERS_FILE].splitlines()
    labels = [h[:-2] for h in lines[0].split(",")[::3]]
    pts = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]]).reshape(len(lines) - 1, len(labels), 3)
    trial = C3dTrial(o.get("source", MARKERS_FILE), labels, pts, o["rate"], o["rate"], 0.0, [], o["total_mass"],
                     "", o.get("height_m"), o.get("widths_m") or {})
    hat, gain, trunk = o.get("hat_offset"), o.get("hat_sway_gain"), o.get("trunk_offset")
    opts = MarkerBodyOptions(total_mass=o["total_mass"], hat_offset=None if hat is None else tuple(hat),
                             hat_fraction=o.get("hat_fraction"), trunk_fraction=o.get("trunk_fraction"),
                             trunk_offset=None if trunk is None else tuple(trunk), floor_z=o.get("floor_z"),
                             hat_sway_gain=None if gain is None else tuple(gain),
                             hat_follow_hz=o.get("hat_follow_hz"), bsp=o.get("bsp", "auto"),
                             age_years=o.get("age_years"), marker_map=_marker_map(o.get("marker_map")))
    body = body_from_markers(trial, opts).body
    if o.get("input_up"):  # a live stream's body: outputs in the stream's axes
        body = replace(body, world_from_input=world_from_up_axis(o["input_up"]), up_axis=o["input_up"].lstrip("+"))
    return body


def body_from_spec(spec: BodySpec) -> BodyModel:
    """Rebuild the body a :class:`BodySpec` describes."""
    o = spec.options
    if spec.kind == "bvh":
        motion = parse_bvh(spec.files[SKELETON_FILE], o.get("source", SKELETON_FILE))
        mapping = {}
        for joint, tag in (o.get("mapping") or {}).items():
            kind, _, side = tag.partition(":")
            mapping[joint] = SegmentTag(kind, side)
        opts = BvhBodyOptions(total_mass=o["total_mass"], units=o["units"], up_axis=o["up_axis"],
                              mapping=mapping or None, sole_width=o.get("sole_width"),
                              heel_back=o.get("heel_back"), toe_front=o.get("toe_front"),
                              hat_fraction=o.get("hat_fraction"))
        return body_from_bvh(motion, opts)
    if spec.kind == "urdf":
        with tempfile.TemporaryDirectory(prefix="livezmp-body-") as tmp:
            for name, text in spec.files.items():
                (Path(tmp) / name).write_text(text, encoding="utf-8")
            config = Path(tmp) / ROBOT_CONFIG_FILE
            opts = UrdfBodyOptions(config=str(config) if config.exists() else None,
                                   sole_length=o.get("sole_length"), sole_width=o.get("sole_width"),
                                   sole_drop=o.get("sole_drop"))
            return body_from_urdf(Path(tmp) / URDF_FILE, opts)
    if spec.kind == "markers":
        return _markers_from_spec(spec)
    raise InputError(f"body spec: unknown body kind {spec.kind!r} (bvh, urdf or markers)")
