"""The impairments a simulated capture stream can be told to have, seeded and reproducible."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Impairments:
    """Gaussian noise std ``noise_deg`` (degrees, BVH rotation channels) and ``noise_pos``
    (position: BVH file units, or metres for marker streams); ``gap`` probability per
    marker per frame of an occlusion (sent as missing; marker streams); per frame:
    ``drop`` (never sent), ``late`` (sent after ``late_by`` later frames; not over a BVH
    TCP broadcast), ``duplicate`` (sent twice; UDP only); ``seed`` of the generator."""

    noise_deg: float = 0.0
    noise_pos: float = 0.0
    gap: float = 0.0
    drop: float = 0.0
    late: float = 0.0
    late_by: int = 3
    duplicate: float = 0.0
    seed: int = 0
