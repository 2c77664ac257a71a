"""Walking-speed control: turn a base walk into a slower or faster one (paper 003, §4).

Only the feature parts change, each by its mean change μ (scaled by ``amount``, 0 =
the base walk, 1 = the variant):

- posture: the channel's DC is multiplied by 1 + amount·μ_DC/100 (a constant shift);
- size: the channel's deviation from its DC is scaled by 1 + amount·μ_A/100;
- speed: the whole motion is retimed by 1 + amount·μ_f/100 (frequency), resampled at
  the original frame rate with a cubic spline through the unwrapped angles;
- the root's forward progression (along the take's net walking direction) is
  scaled by the stride-length change (1 + amount·μ_L/100 when stride length is a
  feature part), so the forward speed becomes new stride × new frequency.

Channels are matched to the features by name, else by the skeleton-independent key
``kind:side:axis`` when that key is unique on both sides (e.g. BVH features on a robot).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import make_interp_spline

from livezmp.errors import InputError
from livezmp.gait.channels import ChannelTag
from livezmp.gait.features import WalkFeatures, walk_features
from livezmp.gait.population import ChangeStat, GaitAnalysis, VariantChange
from livezmp.gait.take import GaitTake, turn_root
from livezmp.model.bvh import BvhMotion
from livezmp.model.trajectory_csv import BASE_COLUMNS, JointTrajectory


@dataclass
class SynthPlan:
    """Multipliers per rotation channel (``dc_ratio``, ``amp_ratio``, (C,)) and for the
    walk (``frequency_ratio``, ``stride_ratio``); which channels were matched."""

    frequency_ratio: float
    stride_ratio: float
    dc_ratio: np.ndarray
    amp_ratio: np.ndarray
    unmatched: list[str] = field(default_factory=list)


def _ratio(s: ChangeStat, amount: float) -> float:
    return 1.0 + amount * s.mu / 100.0 if s.feature and s.mu is not None else 1.0


def match_channels(tags: list[ChannelTag], feature_tags: list[ChannelTag]) -> list[int | None]:
    """For each of ``tags``, the index of its channel in ``feature_tags`` (or None)."""
    by_name = {t.name: i for i, t in enumerate(feature_tags)}
    keys = [t.key for t in feature_tags]
    own = [t.key for t in tags]
    out: list[int | None] = []
    for t in tags:
        if t.name in by_name:
            out.append(by_name[t.name])
        elif keys.count(t.key) == 1 and own.count(t.key) == 1:
            out.append(keys.index(t.key))
        else:
            out.append(None)
    return out


def plan(tags: list[ChannelTag], analysis: GaitAnalysis, variant: VariantChange, amount: float,
         source: str = "") -> SynthPlan:
    """What to change in a walk with rotation channels ``tags`` to move ``amount`` of the way
    from the base condition to ``variant`` (0 ≤ amount ≤ 1)."""
    if not 0.0 <= amount <= 1.0:
        raise InputError(f"--amount must be between 0 (base) and 1 (the variant), got {amount:g}")
    idx = match_channels(tags, analysis.tags)
    if all(i is None for i in idx):
        raise InputError(f"{source}: no channel in common with the features' skeleton "
                         f"(e.g. {analysis.tags[0].name}); were they computed on another skeleton?")
    dc = np.array([1.0 if i is None else _ratio(variant.dc[i], amount) for i in idx])
    amp = np.array([1.0 if i is None else _ratio(variant.amplitude[i], amount) for i in idx])
    return SynthPlan(_ratio(variant.walk["frequency"], amount), _ratio(variant.walk["stride_length"], amount),
                     dc, amp, [t.name for t, i in zip(tags, idx, strict=True) if i is None])


def apply_plan(take: GaitTake, feats: WalkFeatures, p: SynthPlan) -> tuple[np.ndarray, np.ndarray]:
    """The changed walk as (t (F',) s, q (F', n) SI), sampled at the take's own frame interval."""
    q = take.q.copy()
    a = take.angle_index
    q[:, a] = feats.dc * p.dc_ratio + (q[:, a] - feats.dc) * p.amp_ratio
    dt = float(np.median(np.diff(take.t)))
    t0, t1 = float(take.t[0]), float(take.t[-1])
    n = int(np.floor((t1 - t0) / (dt * p.frequency_ratio) + 1e-9)) + 1
    t_src = np.minimum(t0 + np.arange(n) * dt * p.frequency_ratio, t1)
    q = make_interp_spline(take.t, q, k=3, axis=0)(t_src)
    cols = take.root_xyz
    if min(cols) >= 0 and p.stride_ratio != 1.0:
        # the take walks along internal +x (see take.py): stretch the forward progression only
        w = take.body.world_from_input
        forward = (q[:, cols] @ w.T)[:, 0]
        q[:, cols] += (p.stride_ratio - 1.0) * (forward - forward[0])[:, None] * w[0]
    return t0 + np.arange(n) * dt, q


def synth_take(take: GaitTake, analysis: GaitAnalysis, label: str, amount: float = 1.0,
               source: str = "") -> tuple[np.ndarray, np.ndarray, SynthPlan]:
    """Features of ``take``, the plan towards variant ``label`` and the changed walk (t, q)."""
    p = plan(take.tags, analysis, analysis.variant(label, source), amount, take.source)
    t, q = apply_plan(take, walk_features(take), p)
    return t, q, p


def to_bvh(take: GaitTake, q: np.ndarray) -> BvhMotion:
    """A changed BVH take's ``q`` back to a BvhMotion (degrees wrapped to (−180°, 180°]); the joints its body drops
    (a face, fingers) held as in the take's first frame."""
    motion = take.origin
    frames = take.body.q_to_channels(turn_root(q, take, take.heading))
    a = take.angle_index
    frames[:, a] = 180.0 - (180.0 - frames[:, a]) % 360.0
    held = np.repeat(motion.frames[:1], len(frames), axis=0)
    return BvhMotion(motion.joints, motion.frame_time, take.body.into_input(held, frames), motion.source)


def to_trajectory(take: GaitTake, t: np.ndarray, q: np.ndarray) -> JointTrajectory:
    """A changed robot take's ``q`` back to a joint trajectory (base only if the input had one)."""
    traj = take.origin
    names = take.body.channel_names
    q = turn_root(q, take, take.heading)
    joints = q[:, [names.index(n) for n in traj.joint_names]]
    base = q[:, [names.index(n) for n in BASE_COLUMNS]] if traj.base is not None else None
    return JointTrajectory(t, joints, list(traj.joint_names), base, traj.source)
