"""How close one walk is to others: cycle-normalised joint-angle RMS error.

Each walk's whole cycles (from the same thigh-flexion event, see :mod:`.cycles`) are
resampled to 0–100 % of the cycle and averaged into one mean cycle per rotation channel.
The error between two walks is the RMS over the cycle of the difference of their mean
cycles (wrapped to ±180°, so Euler branches do not count); per joint it is the RMS over
the joint's channels, in total the RMS over all channels (those that are constant and
equal in both walks are left out).
Cadence and speed are compared separately: this measures shape, posture and size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import make_interp_spline

from livezmp.errors import InputError
from livezmp.gait.features import WalkFeatures
from livezmp.gait.take import GaitTake

PHASES = 100
STILL = np.deg2rad(1e-6)  # rad: below this a channel counts as still / equal


def mean_cycle(take: GaitTake, feats: WalkFeatures, phases: int = PHASES) -> np.ndarray:
    """(C, phases) rad: the rotation channels averaged over the whole cycles, phase 0..1."""
    ev = feats.cycles.events
    phi = np.arange(phases) / phases
    times = (ev[:-1, None] + phi * np.diff(ev)[:, None]).ravel()
    vals = make_interp_spline(take.t, take.angles, k=3, axis=0)(times)  # (cycles*phases, C)
    return vals.reshape(len(ev) - 1, phases, -1).mean(axis=0).T


@dataclass
class Comparison:
    """RMS errors in degrees: ``per_channel`` (C,) and ``per_joint``, and ``total``."""

    channels: list[str]
    per_channel: np.ndarray
    per_joint: dict[str, float]
    total: float


def compare(a: GaitTake, fa: WalkFeatures, b: GaitTake, fb: WalkFeatures) -> Comparison:
    """Cycle-normalised RMS error of walk ``a`` against walk ``b`` (same skeleton)."""
    names_a, names_b = [t.name for t in a.tags], [t.name for t in b.tags]
    if names_a != names_b:
        missing = sorted(set(names_a) ^ set(names_b))[:4]
        raise InputError(f"{b.source}: skeleton does not match {a.source} (channels differ: {missing or 'order'})")
    ca, cb = mean_cycle(a, fa), mean_cycle(b, fb)
    diff = np.rad2deg((ca - cb + np.pi) % (2 * np.pi) - np.pi)
    rms = np.sqrt(np.mean(diff**2, axis=1))
    moving = (np.ptp(ca, axis=1) > STILL) | (np.ptp(cb, axis=1) > STILL) | (rms > np.rad2deg(STILL))
    joints: dict[str, list[float]] = {}
    for t, r, m in zip(a.tags, rms, moving, strict=True):
        if m:
            joints.setdefault(t.joint, []).append(float(r))
    per_joint = {j: float(np.sqrt(np.mean(np.square(v)))) for j, v in joints.items()}
    total = float(np.sqrt(np.mean(rms[moving] ** 2))) if moving.any() else 0.0
    return Comparison(names_a, rms, per_joint, total)
