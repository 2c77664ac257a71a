"""Segment inertial parameters of the human body, after de Leva (1996).

P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters",
Journal of Biomechanics 29(9):1223-1230, 1996, table 4 (male subjects).
Mass is a fraction of total body mass; the centre of mass a fraction of segment
length from the proximal end; radii of gyration (sagittal, transverse, longitudinal)
fractions of segment length. Lengths as fractions of stature come from the same
table's mean segment lengths divided by the mean stature (1741 mm).

De Leva places each centre of mass on the line between the segment's end points only. The anteroposterior
position off that line comes from R. Dumas, L. Chèze and J.-P. Verriest, "Adjustments to McConville et al. and
Young et al. body segment inertial parameters", Journal of Biomechanics 40(3):543-553, 2007, table 2 (men, as de
Leva's table; their 3-D scans of the body): the thigh's and the shank's mass lie behind the femur's and the
tibia's joint-centre lines (the gluteal, hamstring and calf muscles), the torso's behind the line from the lumbar
to the cervical joint. The head and neck's are those of the same authors' corrigendum (J Biomech 40(10), 2007),
as Dumas & Wojtusch (2018, "Estimation of the body segment inertial parameters for the rigid body biomechanical
models used in motion analysis", Handbook of Human Motion) tabulate them: 2.0 % of its length ahead of the neck.
Without it a marker body's centre of mass stood 7-10 mm ahead of the plates' CoP at rest and in walking
(docs/validation.md, "The fore-aft bias").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class SegmentParams:
    mass_fraction: float
    com_fraction: float  # from the proximal joint, along the segment
    gyration: tuple[float, float, float]  # sagittal, transverse, longitudinal (fractions of length)
    length_fraction: float  # of stature, used when the skeleton gives no length
    # forward (+) of the segment's joint-centre line, a fraction of its length: Dumas et al. 2007 (module docstring)
    anterior_fraction: float = 0.0


# kind -> parameters. Trunk is split into its three parts (upper, middle, lower).
DE_LEVA_MALE: dict[str, SegmentParams] = {
    "head": SegmentParams(0.0694, 0.5976, (0.362, 0.376, 0.312), 242.9 / 1741, 0.020),
    "upper_trunk": SegmentParams(0.1596, 0.2999, (0.716, 0.454, 0.659), 170.7 / 1741, -0.036),  # Dumas' torso
    "middle_trunk": SegmentParams(0.1633, 0.4502, (0.482, 0.383, 0.468), 215.5 / 1741, -0.036),
    "lower_trunk": SegmentParams(0.1117, 0.6115, (0.615, 0.551, 0.587), 145.7 / 1741, 0.028),  # Dumas' pelvis
    "upper_arm": SegmentParams(0.0271, 0.5772, (0.285, 0.269, 0.158), 281.7 / 1741, 0.017),
    "forearm": SegmentParams(0.0162, 0.4574, (0.276, 0.265, 0.121), 268.9 / 1741, 0.010),
    "hand": SegmentParams(0.0061, 0.7900, (0.628, 0.513, 0.401), 86.2 / 1741, 0.035),
    "thigh": SegmentParams(0.1416, 0.4095, (0.329, 0.329, 0.149), 422.2 / 1741, -0.041),
    "shank": SegmentParams(0.0433, 0.4459, (0.255, 0.249, 0.103), 434.0 / 1741, -0.048),
    # the foot's centre of mass is Winter's, half-way from the ankle to the toe marker (markers.py), not placed here
    "foot": SegmentParams(0.0137, 0.4415, (0.257, 0.245, 0.124), 258.1 / 1741),
}


# Children: segment mass proportions (% of body mass) of boys measured by R. K. Jensen: at 12 years, "Body
# segment mass, radius and radius of gyration proportions of children", J Biomech 19(5):359-368, 1986; at 6 and
# 18 years, "Changes in segment inertia proportions between 4 and 20 years", J Biomech 22(6/7):529-536, 1989
# (the proportions his regressions on age give there; the head's checked against his 1989 quadratic,
# 0.27881 - 0.021152 age + 0.00053168 age^2: 17.1 / 10.2 / 7.0 %). Head includes the neck; trunk is the whole trunk.
JENSEN_MASS_PERCENT: dict[float, dict[str, float]] = {
    6.0: {"head": 17.1, "trunk": 43.0, "upper_arm": 2.4, "forearm": 1.3, "hand": 0.8, "thigh": 8.5, "shank": 4.6,
          "foot": 1.9},
    12.0: {"head": 10.1, "trunk": 41.7, "upper_arm": 3.2, "forearm": 1.7, "hand": 0.9, "thigh": 11.0, "shank": 5.3,
           "foot": 2.1},
    18.0: {"head": 7.0, "trunk": 44.6, "upper_arm": 3.6, "forearm": 1.9, "hand": 0.9, "thigh": 11.4, "shank": 4.8,
           "foot": 1.7},
}
ADULT_AGE = 18.0  # years: by then Jensen's proportions are the adult's (the 18-year column above)
# Median stature (m) by age (years), boys and girls averaged, read from the CDC 2000 stature-for-age growth charts
# (about 1.16 m at 6, 1.50 m at 12, 1.70 m at 18): the age a child's height suggests when the file gives none
MEDIAN_STATURE_M = ((6.0, 1.16), (12.0, 1.50), (18.0, 1.70))
# Height below which a subject is taken for a child: the median stature at about 10 years; an adult this short
# is rare (about 3 standard deviations below the mean adult woman's 1.62 m), while at 10 years Jensen's head
# holds about 13 % of the body mass against de Leva's adult 6.9 %
CHILD_STATURE_M = 1.40
BSP_CHOICES = ("auto", "adult", "child")
MAX_AGE_YEARS = 130.0  # an age (years) at or above this is no subject's: a file's is ignored, a user's refused
MAX_BODY_MASS = 1000.0  # kg: above it no subject's (the heaviest weighed ~640 kg): a file's ignored, a user's refused


@dataclass(frozen=True)
class BspTable:
    """The segment table a body is built with: ``segments`` as :data:`DE_LEVA_MALE`; ``name`` "adult" or
    "child"; ``age_years`` the child's age it was made for; ``reason`` why it was chosen (for summaries)."""

    segments: dict[str, SegmentParams]
    name: str = "adult"
    age_years: float | None = None
    reason: str = "de Leva (1996)"

    def summary(self) -> dict:
        return {"table": self.name, "age_years": None if self.age_years is None else round(self.age_years, 3),
                "source": "de Leva (1996)" if self.name == "adult" else
                "de Leva (1996) scaled by Jensen (1986, 1989) child / adult mass proportions", "reason": self.reason}


ADULT = BspTable(DE_LEVA_MALE)


def _jensen(age: float) -> dict[str, float]:
    """Jensen's mass proportions (%) at ``age`` years, linear between his ages (6, 12, 18), held outside them."""
    ages = sorted(JENSEN_MASS_PERCENT)
    return {k: float(np.interp(age, ages, [JENSEN_MASS_PERCENT[a][k] for a in ages])) for k in JENSEN_MASS_PERCENT[6.0]}


def child_segments(age: float) -> dict[str, SegmentParams]:
    """De Leva's table with each segment's mass fraction scaled by Jensen's proportion at ``age`` years over his
    adult (18-year) one, then all scaled to sum to the whole body: the two studies cut the body differently
    (Jensen's thigh is 11.4 % of an adult, de Leva's 14.2 %), so only Jensen's change with age is taken, and the
    table is de Leva's at 18. Centres of mass, radii of gyration and lengths stay de Leva's (Jensen 1986: the
    centroid and gyration proportions change with age far less than the masses)."""
    now, adult = _jensen(age), _jensen(ADULT_AGE)
    scaled = {k: p.mass_fraction * now[_JENSEN_PART.get(k, k)] / adult[_JENSEN_PART.get(k, k)]
              for k, p in DE_LEVA_MALE.items()}
    total = sum(f * (1 if k == "head" or k.endswith("trunk") else 2) for k, f in scaled.items())
    return {k: replace(p, mass_fraction=scaled[k] / total) for k, p in DE_LEVA_MALE.items()}


_JENSEN_PART = {"upper_trunk": "trunk", "middle_trunk": "trunk", "lower_trunk": "trunk"}


def age_for_stature(stature_m: float) -> float:
    """The age (years) at which the median child is ``stature_m`` tall (:data:`MEDIAN_STATURE_M`, held at its ends)."""
    return float(np.interp(stature_m, [s for _, s in MEDIAN_STATURE_M], [a for a, _ in MEDIAN_STATURE_M]))


def choose_table(request: str, age_years: float | None, height_m: float | None, stature_m: float,
                 age_from: str = "the file's") -> BspTable:
    """The segment table for ``request`` ("auto", "adult" or "child"): "auto" takes the child table when the file
    says the subject is a child (its age under :data:`ADULT_AGE`, else its height under :data:`CHILD_STATURE_M`)
    and de Leva's adult table otherwise, saying why. A child's age: ``age_years`` (``age_from`` says whose, for the
    reason), else the one the file's height (else ``stature_m``, m, estimated from the markers) has as a median
    (:func:`age_for_stature`). Below Jensen's youngest age the table is his 6-year one, and the reason says so."""
    if request not in BSP_CHOICES:
        raise ValueError(f"unknown body-segment table {request!r}")
    if age_years is not None:
        age, said = age_years, f"{age_from} age {age_years:g} years"
    elif height_m is not None:
        age, said = age_for_stature(height_m), f"the file's height {height_m:.2f} m"
    else:
        age, said = age_for_stature(stature_m), None
    if request == "adult":
        return replace(ADULT, reason="asked for (--bsp adult)")
    youngest = min(JENSEN_MASS_PERCENT)
    held = f" (proportions held at Jensen's youngest, {youngest:g} years)" if age < youngest else ""
    if request == "child":
        return BspTable(child_segments(age), "child", age, f"asked for (--bsp child); age {age:.1f} years from "
                        + (said or f"the stature {stature_m:.2f} m measured from the markers") + held)
    if said is None:
        return replace(ADULT, reason="the file gives no age or height: adult (--bsp child for a child)")
    child = age_years < ADULT_AGE if age_years is not None else height_m < CHILD_STATURE_M
    if not child:
        return replace(ADULT, reason=f"{said}: adult")
    return BspTable(child_segments(age), "child", age, f"{said}: a child" +
                    ("" if age_years is not None else f" (under {CHILD_STATURE_M:.2f} m), about {age:.1f} years")
                    + held)
