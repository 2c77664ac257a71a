"""Segment inertial parameters of the human body, after de Leva (1996).

P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters",
Journal of Biomechanics 29(9):1223-1230, 1996, table 4 (male subjects).
Mass is a fraction of total body mass; the centre of mass a fraction of segment
length from the proximal end; radii of gyration (sagittal, transverse, longitudinal)
fractions of segment length. Lengths as fractions of stature come from the same
table's mean segment lengths divided by the mean stature (1741 mm).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SegmentParams:
    mass_fraction: float
    com_fraction: float  # from the proximal joint, along the segment
    gyration: tuple[float, float, float]  # sagittal, transverse, longitudinal (fractions of length)
    length_fraction: float  # of stature, used when the skeleton gives no length


# kind -> parameters. Trunk is split into its three parts (upper, middle, lower).
DE_LEVA_MALE: dict[str, SegmentParams] = {
    "head": SegmentParams(0.0694, 0.5976, (0.362, 0.376, 0.312), 242.9 / 1741),
    "upper_trunk": SegmentParams(0.1596, 0.2999, (0.716, 0.454, 0.659), 170.7 / 1741),
    "middle_trunk": SegmentParams(0.1633, 0.4502, (0.482, 0.383, 0.468), 215.5 / 1741),
    "lower_trunk": SegmentParams(0.1117, 0.6115, (0.615, 0.551, 0.587), 145.7 / 1741),
    "upper_arm": SegmentParams(0.0271, 0.5772, (0.285, 0.269, 0.158), 281.7 / 1741),
    "forearm": SegmentParams(0.0162, 0.4574, (0.276, 0.265, 0.121), 268.9 / 1741),
    "hand": SegmentParams(0.0061, 0.7900, (0.628, 0.513, 0.401), 86.2 / 1741),
    "thigh": SegmentParams(0.1416, 0.4095, (0.329, 0.329, 0.149), 422.2 / 1741),
    "shank": SegmentParams(0.0433, 0.4459, (0.255, 0.249, 0.103), 434.0 / 1741),
    "foot": SegmentParams(0.0137, 0.4415, (0.257, 0.245, 0.124), 258.1 / 1741),
}
