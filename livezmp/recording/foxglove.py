"""The balance scene in Foxglove's own schemas, so its 3D panel draws a recording as it is.

Beside the JSON channels, a recording carries protobuf messages of Foxglove's published
schemas (``foxglove-schemas-protobuf``; each schema stored as its FileDescriptorSet):

- ``/foxglove/scene`` (``foxglove.SceneUpdate``): one entity ``balance`` per drawn
  frame (the recorder's ``scene_hz``, 60 a second by default; ``/result`` has them all)
  with the ZMP (red sphere), the clamped ZMP (orange), the CoM (blue) and its plumb line
  to the ground, force-plate centres of pressure (green), the support polygon (white
  loop) and the footprints (grey loops);
- ``/foxglove/zmp``, ``/foxglove/com`` (``foxglove.PoseInFrame``) and ``/foxglove/cop``
  (``foxglove.PosesInFrame``, one pose per loaded plate), for plots and the 3D panel;
- ``/foxglove/tf`` (``foxglove.FrameTransforms``): ``world`` → ``ground`` (the detected
  ground height), so the panel has its frames without a URDF.

Everything is in the result's frame, ``world``: z up, metres (see ``/result``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap_protobuf.schema import build_file_descriptor_set

FRAME = "world"
SCENE_TOPICS = {"/foxglove/scene": SceneUpdate, "/foxglove/zmp": PoseInFrame, "/foxglove/com": PoseInFrame,
                "/foxglove/cop": PosesInFrame, "/foxglove/tf": FrameTransforms}
RED, ORANGE, BLUE, GREEN = (0.9, 0.1, 0.1, 1.0), (1.0, 0.6, 0.0, 1.0), (0.2, 0.4, 1.0, 1.0), (0.1, 0.8, 0.2, 1.0)
WHITE, GREY = (1.0, 1.0, 1.0, 1.0), (0.6, 0.6, 0.6, 1.0)


def register(writer) -> dict[str, int]:
    """Register the schemas and channels on an mcap ``Writer``; topic → channel id."""
    out = {}
    for topic, cls in SCENE_TOPICS.items():
        sid = writer.register_schema(cls.DESCRIPTOR.full_name, "protobuf",
                                     build_file_descriptor_set(cls).SerializeToString())
        out[topic] = writer.register_channel(topic, "protobuf", sid)
    return out


def _color(c, rgba) -> None:
    c.r, c.g, c.b, c.a = rgba


def _sphere(entity, p, size: float, rgba) -> None:
    s = entity.spheres.add()
    s.pose.position.x, s.pose.position.y, s.pose.position.z = (float(v) for v in p)
    s.pose.orientation.w = 1.0
    s.size.x = s.size.y = s.size.z = size
    _color(s.color, rgba)


def _line(entity, points, rgba, kind=LinePrimitive.LINE_LOOP, thickness: float = 0.005) -> None:
    line = entity.lines.add()
    line.type = kind
    line.thickness = thickness
    line.pose.orientation.w = 1.0
    for p in points:
        line.points.append(Point3(x=float(p[0]), y=float(p[1]), z=float(p[2])))
    _color(line.color, rgba)


def _pose(msg, p) -> None:
    msg.position.x, msg.position.y, msg.position.z = (float(v) for v in p)
    msg.orientation.w = 1.0


def scene_messages(r, log_time_ns: int, cops: Sequence[np.ndarray] = ()) -> dict[str, bytes]:
    """The serialised messages of one analysed frame ``r`` (a FrameResult), with the plates'
    centres of pressure ``cops`` (each (3,) m in the result's frame); topic → bytes."""
    ground = float(r.ground_z)
    update = SceneUpdate()
    e = update.entities.add()
    e.timestamp.FromNanoseconds(log_time_ns)
    e.frame_id, e.id = FRAME, "balance"
    if r.zmp is not None:
        _sphere(e, r.zmp, 0.03, RED)
    if r.clamped is not None:
        _sphere(e, r.clamped, 0.02, ORANGE)
    _sphere(e, r.com, 0.05, BLUE)
    _line(e, [r.com, (r.com[0], r.com[1], ground)], BLUE, LinePrimitive.LINE_STRIP, 0.003)
    for c in cops:
        _sphere(e, c, 0.025, GREEN)
    if len(r.polygon):
        _line(e, [(x, y, ground) for x, y in r.polygon], WHITE)
    for pts in r.soles.values():
        if len(pts):
            _line(e, pts, GREY, thickness=0.003)
    out = {"/foxglove/scene": update}
    for topic, p in (("/foxglove/zmp", r.zmp), ("/foxglove/com", r.com)):
        if p is not None:
            m = PoseInFrame(frame_id=FRAME)
            m.timestamp.FromNanoseconds(log_time_ns)
            _pose(m.pose, p)
            out[topic] = m
    poses = PosesInFrame(frame_id=FRAME)
    poses.timestamp.FromNanoseconds(log_time_ns)
    for c in cops:
        _pose(poses.poses.add(), c)
    out["/foxglove/cop"] = poses
    tf = FrameTransforms()
    t = tf.transforms.add()
    t.timestamp.FromNanoseconds(log_time_ns)
    t.parent_frame_id, t.child_frame_id = FRAME, "ground"
    t.translation.z = ground
    t.rotation.w = 1.0
    out["/foxglove/tf"] = tf
    return {k: v.SerializeToString() for k, v in out.items()}
