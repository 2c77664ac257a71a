"""Foot contacts and ground height over many frames at once: :class:`livezmp.balance.contacts.ContactDetector`
for a chunk of frames, with the same results and the same state afterwards.

The ground estimate is a per-frame recurrence (warm-up percentile, then a bounded
tracking step) and goes through the detector's own :class:`GroundEstimator`, one
scalar call per frame. The hysteresis / debounce state machine of each foot is
vectorised: its state only changes where a run of ``min_frames`` frames calls for it,
so the loop visits the state changes (a few per step cycle), not the frames.

Frame: world, z up, metres; speeds in m/s (horizontal speed of the lowest sole corner).
"""

from __future__ import annotations

import numpy as np

from livezmp.balance.contacts import ContactConfig, ContactDetector, FootContact
from livezmp.balance.support import SUPPORT_LABELS

# support label code (index into SUPPORT_LABELS) from 2 * left + right
_CODE = np.array([SUPPORT_LABELS.index(s) for s in ("none", "right", "left", "double")], dtype=np.int8)


def _run_lengths(flags: np.ndarray) -> np.ndarray:
    """Number of consecutive True values ending at each index (0 where False)."""
    idx = np.arange(len(flags))
    last_false = np.maximum.accumulate(np.where(flags, -1, idx))
    return idx - last_false


def foot_contacts(state: FootContact, height: np.ndarray, speed: np.ndarray,
                  cfg: ContactConfig) -> tuple[np.ndarray, FootContact]:
    """In-contact flags (C,) of one foot over C frames and its state after them:
    :func:`livezmp.balance.contacts.step_foot` applied frame after frame.

    height (C,): lowest sole point above the ground, m; speed (C,): its horizontal speed, m/s."""
    count = len(height)
    out = np.empty(count, dtype=bool)
    lifts = (height > cfg.height_off) | (speed > cfg.speed_off)
    lands = (height <= cfg.height_on) & (speed <= cfg.speed_on)
    runs = {True: _run_lengths(lifts), False: _run_lengths(lands)}  # by current state: the change's runs
    long_runs = {s: np.flatnonzero(r >= cfg.min_frames) for s, r in runs.items()}
    k = 0
    contact, pending = state.in_contact, state.pending
    if contact is None and count:
        contact, pending = not bool(lifts[0]), 0
        out[0] = contact
        k = 1
    while k < count:
        run = runs[contact]
        # the run under way (pending frames already seen) completes at k + need - 1 if unbroken ...
        need = cfg.min_frames - pending
        j = k + need - 1
        if j < count and run[j] >= need:
            flip = j
        else:
            # ... else the first later run of min_frames frames
            cands = long_runs[contact]
            at = np.searchsorted(cands, k + cfg.min_frames - 1)
            if at == len(cands):
                out[k:] = contact
                last = int(run[count - 1])
                pending = pending + count - k if last >= count - k else last
                return out, FootContact(contact, pending)
            flip = int(cands[at])
        out[k:flip] = contact
        contact, pending = not contact, 0
        out[flip] = contact
        k = flip + 1
    return out, FootContact(contact, pending)


def detect_contacts(detector: ContactDetector, left_low: np.ndarray, left_speed: np.ndarray,
                    right_low: np.ndarray, right_speed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Support label codes (C,) int8 (indices into ``SUPPORT_LABELS``) and ground heights (C,) m
    for C frames, advancing ``detector`` exactly as C calls of its ``update`` would.

    ``left_low``, ``right_low``: z of each foot's lowest sole corner, m; ``left_speed``,
    ``right_speed``: that corner's horizontal speed, m/s."""
    ground_est = detector.ground
    if ground_est.config.override is not None:
        ground = np.full(len(left_low), float(ground_est.config.override))
    else:
        update = ground_est.update
        ground = np.array([update(z) for z in np.minimum(left_low, right_low).tolist()])
    cfg = detector.config
    left, detector.left = foot_contacts(detector.left, left_low - ground, left_speed, cfg)
    right, detector.right = foot_contacts(detector.right, right_low - ground, right_speed, cfg)
    detector.frame += len(ground)
    return _CODE[2 * left + right], ground
