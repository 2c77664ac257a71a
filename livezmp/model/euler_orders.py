"""BVH joints re-expressed in a rotation order that keeps clear of gimbal lock.

A BVH joint's three rotation channels are Euler angles in the file's order (intrinsic: R = R_1(a) R_2(b) R_3(c)).
Where the middle angle b nears ±90° the first and third axes line up: only a ± c stays defined, and the two spin
fast and in opposite directions while the rotation itself turns slowly (one file's `ZXY` knee, flexed past 90° about
its middle axis, went 26° → 134° and −27° → −136° in one frame at 30 Hz while it turned 5°). The body model takes
each channel as a revolute joint and the estimator differentiates each channel on its own, so the two spins' errors
no longer cancel and the ZMP's dynamics explode (accelerations of 10⁶ g, frames taken for flight). A joint whose
middle angle comes within ``GIMBAL_MARGIN_DEG`` of ±90° somewhere in the take is therefore re-expressed, every frame,
in the Tait-Bryan order whose middle angle stays farthest from ±90° over the take: the same rotations (the segments'
poses unchanged to rounding), in other channels, unwrapped so that they run continuously. Angles in degrees, as
BVH writes them; the order is one for the whole take, so a take read in pieces is scanned once first. A live stream
cannot be scanned ahead: its orders are the ones its skeleton file's frames call for, fixed before the first frame
(the body's joints follow them), and each streamed row is re-expressed as it comes (:class:`StreamOrders`).

Away from gimbal lock a file may still jump from one branch of the same rotations to the other (R_a(x) R_b(y) R_c(z)
= R_a(x + 180°) R_b(180° − y) R_c(z + 180°)): Perception Neuron's Axis exports do it at the neck every few frames
(AnyBody's ammr Sit-Stand3_chr00.bvh, 273 jumps in 920 frames, each angle by ~180°), and the estimator, filtering
each channel on its own, mixes the two branches into poses the body never took (the head swinging, a ZMP 529 km
off). A joint whose rows jump so (:func:`branch_jumps`) is re-expressed too: in its own order, which folds the middle
angle into ±90° and so keeps one branch, unless its own order also nears gimbal lock.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable
from dataclasses import replace
from itertools import permutations

import numpy as np
from scipy.spatial.transform import Rotation

from livezmp.model.bvh import BvhJoint, BvhMotion
from livezmp.model.euler import other_branch, wrapped

GIMBAL_MARGIN_DEG = 20.0  # a middle angle within this of ±90° is near gimbal lock
ORDERS = tuple("".join(p) for p in permutations("XYZ"))


def rotation_slots(joint: BvhJoint) -> list[int] | None:
    """Indices (in ``joint.channels``) of its three rotation channels, about three distinct axes; else None."""
    slots = [i for i, c in enumerate(joint.channels) if c.endswith("rotation")]
    if len(slots) != 3 or len({joint.channels[i][0].upper() for i in slots}) != 3:
        return None
    return slots


def _order(joint: BvhJoint, slots: list[int]) -> str:
    return "".join(joint.channels[i][0].upper() for i in slots)


def _rotations(block: np.ndarray, joint: BvhJoint, slots: list[int]) -> Rotation:
    return Rotation.from_euler(_order(joint, slots), block[:, [joint.first_channel + i for i in slots]], degrees=True)


def _euler(rot: Rotation, order: str) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # scipy's "gimbal lock detected": the case handled here
        return rot.as_euler(order, degrees=True)


def near_lock(joints: list[BvhJoint], block: np.ndarray) -> set[int]:
    """Indices of the joints whose middle rotation channel comes within ``GIMBAL_MARGIN_DEG`` of ±90° (mod 180°) in
    some row of ``block`` (F, C) (degrees): a cheap scan of the file's own columns."""
    out = set()
    for k, joint in enumerate(joints):
        if (slots := rotation_slots(joint)) is not None and len(block):
            middle = np.radians(block[:, joint.first_channel + slots[1]])
            if np.min(np.abs(np.cos(middle))) < np.sin(np.radians(GIMBAL_MARGIN_DEG)):
                out.add(k)
    return out


def branch_jumps(joints: list[BvhJoint], block: np.ndarray) -> set[int]:
    """Indices of the joints whose rotation triple, from one row of ``block`` (F, C) (degrees) to the next, is nearer
    the previous row on its other branch than as written: the file jumped between the two branches."""
    out = set()
    for k, joint in enumerate(joints):
        if (slots := rotation_slots(joint)) is not None and len(block) > 1:
            angles = block[:, [joint.first_channel + i for i in slots]]
            prev, nxt = angles[:-1], angles[1:]
            own = (wrapped(nxt - prev, 180.0) ** 2).sum(axis=1)
            other = (wrapped(other_branch(nxt, 180.0) - prev, 180.0) ** 2).sum(axis=1)
            if np.any(other < own):
                out.add(k)
    return out


def middle_extents(joints: list[BvhJoint], block: np.ndarray, only: set[int]) -> dict[int, dict[str, float]]:
    """Per joint index in ``only``, per Tait-Bryan order: the largest |middle angle| (deg, in [0, 90]) over the rows
    of ``block`` (F, C) (degrees)."""
    out = {}
    for k in only:
        rot = _rotations(block, joints[k], rotation_slots(joints[k]))
        out[k] = {o: float(np.max(np.abs(_euler(rot, o)[:, 1]))) for o in ORDERS}
    return out


def merge_extents(a: dict[int, dict[str, float]], b: dict[int, dict[str, float]]) -> dict[int, dict[str, float]]:
    """The extents of two pieces of one take together."""
    out = {k: dict(v) for k, v in a.items()}
    for k, ext in b.items():
        out[k] = {o: max(out.get(k, {}).get(o, 0.0), v) for o, v in ext.items()}
    return out


def choose_orders(joints: list[BvhJoint], extents: dict[int, dict[str, float]],
                  jumping: frozenset[int] = frozenset()) -> dict[int, str]:
    """{joint index: new order} for the joints whose own order comes within ``GIMBAL_MARGIN_DEG`` of gimbal lock
    and another keeps farther from it; a joint of ``jumping`` (:func:`branch_jumps`) otherwise keeps its own order,
    re-expressed on one branch."""
    out = {}
    for k, ext in extents.items():
        own = _order(joints[k], rotation_slots(joints[k]))
        best = min(ORDERS, key=lambda o: ext[o])
        if ext[own] > 90.0 - GIMBAL_MARGIN_DEG and ext[best] < ext[own]:
            out[k] = best
        elif k in jumping:
            out[k] = own
    return out


def reordered_joints(joints: list[BvhJoint], orders: dict[int, str]) -> list[BvhJoint]:
    """The hierarchy with each re-expressed joint's rotation channels renamed to its new order (same slots)."""
    out = list(joints)
    for k, order in orders.items():
        channels = list(joints[k].channels)
        for slot, axis in zip(rotation_slots(joints[k]), order, strict=True):
            channels[slot] = f"{axis}rotation"
        out[k] = replace(joints[k], channels=channels)
    return out


def reexpress(joints: list[BvhJoint], block: np.ndarray, orders: dict[int, str],
              previous: np.ndarray | None = None) -> np.ndarray:
    """``block`` (F, C) with each joint of ``orders`` re-expressed in its new order, unwrapped along the rows and
    from ``previous`` (C,), the re-expressed row before the block, when the take is read in pieces."""
    out = block.copy()
    for k, order in orders.items():
        slots = rotation_slots(joints[k])
        cols = [joints[k].first_channel + i for i in slots]
        angles = _euler(_rotations(block, joints[k], slots), order)
        if previous is not None:
            angles = np.unwrap(np.vstack([previous[cols], angles]), period=360.0, axis=0)[1:]
        else:
            angles = np.unwrap(angles, period=360.0, axis=0)
        out[:, cols] = angles
    return out


def gimbal_orders(motion: BvhMotion) -> dict[int, str]:
    """{joint index: new order} for ``motion``'s joints near gimbal lock: :func:`scan_orders` over its one block."""
    return scan_orders(motion.joints, lambda: (motion.frames,))


def reexpressed(motion: BvhMotion, orders: dict[int, str]) -> BvhMotion:
    """``motion`` with the joints of ``orders`` re-expressed (:func:`reexpress`); itself when there are none."""
    if not orders:
        return motion
    return BvhMotion(reordered_joints(motion.joints, orders), motion.frame_time,
                     reexpress(motion.joints, motion.frames, orders), motion.source)


def clear_of_gimbal_lock(motion: BvhMotion) -> BvhMotion:
    """``motion`` with every joint near gimbal lock re-expressed (see the module docstring); itself when none is."""
    return reexpressed(motion, gimbal_orders(motion))


def restore(original: BvhMotion, orders: dict[int, str], frames: np.ndarray) -> np.ndarray:
    """``frames`` (F, C; as many rows as ``original``'s) of ``original``'s hierarchy re-expressed by ``orders``,
    written back in the file's own orders: of the two Euler triples of each rotation and their 360° turns, the one
    nearest the file's own row, so a joint whose rotation was left alone gets its own angles back (to rounding)."""
    out = frames.copy()
    new = reordered_joints(original.joints, orders)
    for k in orders:
        joint = original.joints[k]
        slots = rotation_slots(joint)
        cols = [joint.first_channel + i for i in slots]
        one = _euler(_rotations(frames, new[k], slots), _order(joint, slots))
        other = other_branch(one, 180.0)  # the same rotations
        ref = original.frames[:, cols]
        d_one, d_other = wrapped(one - ref, 180.0), wrapped(other - ref, 180.0)
        nearer = (d_one ** 2).sum(axis=1) <= (d_other ** 2).sum(axis=1)
        out[:, cols] = ref + np.where(nearer[:, None], d_one, d_other)
    return out


def scan_orders(joints: list[BvhJoint], blocks: Callable[[], Iterable[np.ndarray]]) -> dict[int, str]:
    """:func:`choose_orders` for a take read in pieces: ``blocks()`` gives its rows a block at a time, once for the
    cheap scan (each block with the row before it, for the branch jumps between blocks) and, only where a joint nears
    gimbal lock or jumps branch, once more for the orders' extents."""
    flagged: set[int] = set()
    jumping: set[int] = set()
    last = None
    for block in blocks():
        flagged |= near_lock(joints, block)
        jumping |= branch_jumps(joints, block if last is None else np.vstack([last, block]))
        last = block[-1:] if len(block) else last
    if not flagged | jumping:
        return {}
    extents: dict[int, dict[str, float]] = {}
    for block in blocks():
        extents = merge_extents(extents, middle_extents(joints, block, flagged | jumping))
    return choose_orders(joints, extents, frozenset(jumping))


class StreamOrders:
    """A live stream's rows (C,) (degrees, the skeleton file's orders) re-expressed by ``orders`` one at a time, each
    unwrapped from the row before; :meth:`restart` where the stream's timeline starts over."""

    def __init__(self, joints: list[BvhJoint], orders: dict[int, str]):
        self.joints, self.orders = joints, orders
        self._previous: np.ndarray | None = None

    def __call__(self, row: np.ndarray) -> np.ndarray:
        self._previous = reexpress(self.joints, row[None], self.orders, self._previous)[0]
        return self._previous

    def restart(self) -> None:
        self._previous = None
