"""The common gait-lab label conventions, recognised without a mapping file.

A C3D's marker labels are matched to the Plug-in Gait roles the marker body reads (``LASI``, ``RKNE``,
``SACR`` ...). A label is compared in capitals with its separators (``. _ - `` and blanks) removed, after
its side: ``L``/``R`` or ``Left``/``Right`` in front (``LASI``, ``L.ASIS``, ``l_asis``, ``LeftASIS``), or behind
after a separator (``ASIS_L``, ``Knee.Left``). A prefix or suffix shared by every label (``sub01_LASI``,
``LASI_sub01``) is dropped (the ``Subject:`` prefix is already gone, :func:`livezmp.model.c3d.strip_prefix`).

Where each name comes from:

- Plug-in Gait / CGM (Vicon's Plug-in Gait reference; pyCGM2): ``ASI PSI SACR THI KNE TIB ANK HEE TOE``, medial
  ``KNM``/``MED``, trunk ``C7 T10 CLAV STRN``, clavicles ``LCLA RCLA`` (Helen Hayes sets).
- Codamotion: ``L.ASIS L.PSIS L.Knee L.Ankle L.Heel L.Toe`` (Charnwood Dynamics, Coda cx1 User Guide 2004,
  "Gait Analysis II": the marker names its gait model needs; its wands ``L.Ant.Fem.`` ... are not Plug-in Gait's
  THI/TIB and are not read). Motion Analysis (EVaRT / Cortex Helen Hayes templates, as the c3d.org samples
  Walk1, newwalk, Sample_Jump2 write them): sacrum ``VSAC`` (``V.Sacral``), toes ``L.TO``/``R.TO``, medial knee
  and ankle ``R.Knee.Medial``/``R.Ankle.Medial`` (the descriptions of its repeated ``RKNE``/``RANK``, which
  :func:`livezmp.model.c3d.told_apart` gives them as labels).
- CAST (Cappozzo et al. 1995, Clin Biomech 10:171) as Qualisys' gait and running projects (QTM, with Visual3D)
  and OptiTrack's "Conventional Lower" set label it, with the ISB landmark names of Van Sint Jan (2007, Color
  Atlas of Skeletal Landmark Definitions): ``L_IAS L_IPS SACR L_FLE L_FME L_FAL L_TAM L_FCC L_FM2``.
  Trunk: ``CV7``, ``TV10``, incisura jugularis ``IJ`` (Plug-in Gait's CLAV), processus xiphoideus ``PX`` (its
  STRN), sternoclavicular joint ``L_SC`` (the clavicle's sternal end: the Helen Hayes LCLA) (Wu et al. 2005,
  J Biomech 38:981); the same landmarks as a Qualisys sample (ezc3d's ``test/c3dFiles/Qualisys.c3d``: ``CV7 TV8 SNJ
  SXS``) and AnyBody's Qualisys gait set (AMMR ``2014001_C1_01``: ``CV7 TV10 SJN SXS``) write them: the sternum's
  jugular notch ``SNJ``/``SJN``, its xiphisternal joint ``SXS``, and the eighth thoracic spinous process ``TV8``,
  read as T10: ISB's thorax axis starts between PX and T8 where Plug-in Gait's starts between STRN and T10.
- Landmark names seen in the c3d.org samples: ``RLFC`` lateral femoral condyle, ``RLMA`` lateral malleolus,
  ``RCAL`` calcaneus, medial ``RMFC``/``RMMA`` (Innovative Sports Training), ``RLKN``/``RMKN`` lateral / medial
  knee (TYPE-3), ``SACRUM`` (Walking_Hybrid, Capture0002); medial ``MKNE KNEM MFC MEPI ANKM MANK MMAL``
  (read before these conventions). Lateral ``RLMAL`` malleolus and ``RMT2`` second metatarsal head (where Plug-in
  Gait's TOE sits; CAST's FM2), as OpenSim's Stanford walking trials write them (opensim-core
  ``OpenSim/Tests/shared/walking2.c3d``, with ``RLFC RMMAL RCAL``); ``RKneeLateral``/``RAnkleLateral`` with
  ``RHeel RToe RAsis RPsis`` (AnyBody's Qualisys gait and running examples, AMMR ``S3_Gait_Shod_1``,
  ``SlowRun``; their medial ``RKneeMedial`` is the Helen Hayes name above). Lateral knee ``LLKNE`` with
  ``LLMA`` (AnyBody's ``SpecialFeatures`` example, AMMR); ``LKneeLat``/``LAnkleLat`` with ``LHeel LASIS`` (the
  pyorerun running example, ``Running_0002.c3d``); ``R_KNEE_LAT R_KNEE_MED R_ANKLE_LAT R_ANKLE_MED`` (c3d.org's
  sample 26, ``Standing_Hybrid_1``). Femoral condyle and malleolus with the side behind the landmark,
  ``RFCL``/``RFCM`` and ``RMALL``/``RMALM`` lateral / medial, with ``RCAL RMT1 RMT5 RPSI`` (the
  Vicon Nexus set of RealTimeBiomechanics/rtosim's ``data/ViconNexus/walking_1.c3d`` and its subject file
  ``S01.vsk`` write them: ``RFCL`` on its ``rknee`` segment, ``RMALL`` on ``rankle``); the knee's as ``RKNEL``/``RKNEM``
  beside them (keenon/nimblephysics' ``data/osim/Return11`` trial, with ``RHEE RTOE RM5``). Malleoli ``RLM``/``RMM``,
  calcaneus ``RCA``, first and fifth metatarsal heads ``RIMH``/``RVMH`` (the BTS "UNIPD-Fullbody" set of
  RehabEngGroup/MOtoNMS' ``TestData/InputData/Control1_UNIPD``; CGM2's ``RFMH``/``RVMH`` likewise).
- The Davis et al. (1991, Hum Mov Sci 10:575) protocol as BTS Bioengineering's Elite / SMART systems label it, lower
  case with a blank after the side: ``sacrum``, ``r asis``, lateral femoral epicondyle ``r knee 1``, lateral
  malleolus ``r mall``, fifth metatarsal head ``r met`` (the toe's stand-in, below), heel ``r heel`` (static trials),
  shoulders ``r should``, ``c7``; its thigh and shank wands ``r bar 1``/``r bar 2`` and the fibular head ``r knee 2``
  are not Plug-in Gait's markers and are not read. So written by BTKData's ``Input/TDFSamples/gait9.tdf.c3d`` (a BTS
  TDF trial) and BTKCore's ``561xxa01_anonym.C3D`` (a BTS Elite file); in the first, ``knee 1`` lies at the knee,
  55-56 % of the way from the ASIS down to the malleolus, ``knee 2`` 35-47 mm below it, ``met`` 61-75 mm lateral of
  the malleolus and 19-31 mm above the floor (medians over the take).
- Epicondyles: ``RLEPI`` (La Trobe's Vicon set, psbiomech/lasem-data-processing), ``RLE``/``RME`` (the UNIPD set),
  ``RLEP``/``RMEP`` (AnyBody's ``Runner``) name a lateral or medial epicondyle of the femur or of the humerus alike
  (ISB names them apart, ``FLE``/``HLE``): such a label is the knee's only where it lies along its side's leg, at
  least :data:`MIN_KNEE_ALONG_LEG` of the way from the ASIS marker down to the ankle marker (median over the take;
  the knee's lie about half way, an elbow's beside the waist); else it claims nothing (``markers.labels.epicondyles``
  says which and why).

Two labels of a file claiming one role are refused in one line naming both (a marker map's ``[labels]`` then
chooses): which one the lab meant cannot be told from the names. One case is told by position: two labels
claiming one side's lateral knee or ankle marker (``KNE``, ``ANK``) while nothing claims its medial one, which lie
across the body at least :data:`MIN_JOINT_WIDTH_M` apart, more across the body than along it, at most
:data:`MAX_JOINT_WIDTH_M` apart in all, on the same sides of each other in nearly every frame, are the joint's
two markers: the one further from the pelvis' midline is the lateral (a lateral malleolus or
epicondyle lies outside its medial one), the other the medial (c3d.org's TYPE-3: ``LANK`` 90 mm medial of
``LLMA``). The summary's ``markers.labels.by_position`` says so. A label never seen in the take claims nothing.

The toe, by position too: of two or more labels claiming a side's ``TOE`` (its ankle marker claimed once), the
one lying within :data:`MAX_TOE_FROM_ANKLE_M` of the ankle marker in nearly every frame is the toe, the others
are set aside (``markers.labels.toe`` names them and their distance). A toe marker sits on the foot; a name is
only a name: OpenSim's ``jogging.c3d`` labels its femur cluster's middle markers ``RFM1-3``, and ``RFM2`` reads
as CAST's second metatarsal head ``R_FM2``, 660 mm from the ankle. Position rather than "Plug-in Gait's name
wins": a lab may keep ``RTOE`` for something else while naming the true toe otherwise, and the position is
measured, not assumed.

A side with no label claiming the toe (no ``TOE``, ``FM2``, ``MT2``) takes the metatarsal heads' stand-in (each at
the foot as above; ``markers.labels.toe`` says which): the mid-point of the first and fifth heads (``MT1``/``FM1``
and ``MT5``/``FM5``) when the file has both, the second head's neighbourhood that Plug-in Gait's toe marks; else
the fifth head (or a "lateral toe" ``LA_TOE``, tsalemink's AUC set) alone. The heads' mid-point lies 30-34 mm
from CAST's FM2 in AnyBody's 2014001_C1_01, its heel-to-toe line turned under 1 degree; the fifth alone turns
the foot's long axis outward, by 25-27 degrees (88 mm from the toe marker) in AnyBody's GaitNormal_1, and the
ZMP falls outside the support polygon more often: docs/validation.md ("Toe markers").

A toe marker off the foot's long axis gives way to the heads' mid-point: where the one label claiming a side's toe
lies more than :data:`MAX_TOE_OFF_AXIS_DEG` off the line from the heel marker to the first and fifth heads'
mid-point (median over the take), that mid-point is the toe (``markers.labels.toe`` says so, with the angle). The
toe sits on that line (Plug-in Gait's on the second metatarsal head); Qualisys' NewPaf 1 placed its 33 degrees
medial of it and behind the heads, the foot's sole turned with it and its plates' CoP fell off the foot.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

import numpy as np

from livezmp.errors import InputError
from livezmp.model.c3d import C3dTrial

PIG = "Plug-in Gait"
HH = "Helen Hayes as Codamotion / Motion Analysis write it"
CAST = "CAST / ISB landmark names (Qualisys, Visual3D, OptiTrack)"
LAB = "lateral / medial landmark names"
DAVIS = "Davis et al. (1991) as BTS labels it"
# role suffix (after the side letter) -> (name after the side, convention) ...
SIDED: dict[str, tuple[tuple[str, str], ...]] = {
    "ASI": (("ASI", PIG), ("ASIS", HH), ("IAS", CAST)),
    "PSI": (("PSI", PIG), ("PSIS", HH), ("IPS", CAST)),
    "THI": (("THI", PIG),),
    "KNE": (("KNE", PIG), ("KNEE", HH), ("FLE", CAST), ("LFC", LAB), ("LKN", LAB), ("KNEELATERAL", LAB),
            ("LKNE", LAB), ("KNEELAT", LAB), ("FCL", LAB), ("KNEL", LAB), ("KNEE1", DAVIS)),
    "KNM": (("KNM", PIG), ("MKNE", LAB), ("KNEM", LAB), ("FME", CAST), ("MFC", LAB), ("MEPI", LAB), ("MKN", LAB),
            ("KNEEMEDIAL", HH), ("KNEEMED", LAB), ("FCM", LAB)),
    # not Helen Hayes' shank wand (Motion Analysis' RSHA): in Plug-in Gait's ankle chord rule it put Walk1's ankle
    # centres 55-60 mm from the file's own (VLAN, VRAN), 14-19 mm without it (docs/validation.md)
    "TIB": (("TIB", PIG),),
    "ANK": (("ANK", PIG), ("ANKLE", HH), ("FAL", CAST), ("LMA", LAB), ("LMAL", LAB), ("ANKLELATERAL", LAB),
            ("ANKLELAT", LAB), ("MALL", LAB), ("LM", LAB)),
    "MED": (("MED", PIG), ("MMA", LAB), ("ANKM", LAB), ("MANK", LAB), ("MMAL", LAB), ("TAM", CAST),
            ("ANKLEMEDIAL", HH), ("ANKLEMED", LAB), ("MALM", LAB), ("MM", LAB)),
    "HEE": (("HEE", PIG), ("HEEL", HH), ("FCC", CAST), ("CAL", LAB), ("CA", LAB)),
    "TOE": (("TOE", PIG), ("TO", HH), ("FM2", CAST), ("MT2", LAB)),
    "CLA": (("CLA", PIG), ("SC", CAST)),
    # the acromion; Plug-in Gait's own SHO is read by its name (as a role here, a two-person file's LSHO twice over
    # would be refused naming it, where it is refused naming the legs' markers it lacks)
    "SHO": (("SHOULD", DAVIS),),
}
UNSIDED: dict[str, tuple[tuple[str, str], ...]] = {
    "SACR": (("SACR", PIG), ("VSAC", HH), ("VSACRAL", HH), ("SACRUM", LAB)),
    "C7": (("C7", PIG), ("CV7", CAST)),
    # ISB's thorax axis runs from between PX and T8 up to between IJ and C7 (Wu et al. 2005), Plug-in Gait's from
    # between STRN and T10 up to between CLAV and C7: the eighth thoracic spinous process takes T10's place in it
    "T10": (("T10", PIG), ("TV10", CAST), ("TV8", CAST)),
    "CLAV": (("CLAV", PIG), ("IJ", CAST), ("SNJ", CAST), ("SJN", CAST)),
    "STRN": (("STRN", PIG), ("PX", CAST), ("SXS", CAST)),
}
# the forefoot markers that stand in for the toe marker when no label claims it (module docstring)
FOREFOOT_TOE = "toe from the metatarsal heads"
FOREFOOT: dict[str, tuple[tuple[str, str], ...]] = {
    "MT1": (("MT1", LAB), ("FM1", CAST), ("IMH", LAB), ("FMH", LAB)),
    # LATOE: "lateral toe" (tsalemink's AUC set); MET: Davis' fifth metatarsal head (BTS)
    "MT5": (("MT5", LAB), ("FM5", CAST), ("LATOE", LAB), ("VMH", LAB), ("MET", DAVIS)),
}
# an epicondyle's name says not whether it is the femur's or the humerus' (ISB names them apart, FLE / HLE): such a
# label is read as the knee's marker only where it lies along its side's leg (:func:`_epicondyles_on_the_leg`)
EPICONDYLE = "epicondyle told femoral by position"
EPICONDYLES: dict[str, tuple[tuple[str, str], ...]] = {
    "KNE": (("LEPI", EPICONDYLE), ("LEP", EPICONDYLE), ("LE", EPICONDYLE)),
    "KNM": (("MEP", EPICONDYLE), ("ME", EPICONDYLE)),
}
# the knee's epicondyles lie about half way from the ASIS down to the ankle marker (de Leva's thigh and shank are
# 0.245 and 0.246 of the stature), an elbow's beside the waist, near the ASIS' height: a quarter of the way
# tells them apart, with room for a hip flexed in swing or a knee bent
MIN_KNEE_ALONG_LEG = 0.25
# a toe marker further than this off the line from the heel marker to the first and fifth metatarsal heads' mid-point
# (median over the take) is not on the foot's long axis: the toes of the other sets with both heads lie 2-16 deg off
# it (the CGM2 walks of held-out round 4 9-16, cgm24 and c3d.org's pyCGM2 sample 2-4, AnyBody's FM2 4), Qualisys'
# NewPaf 1's 33 deg, medial of it and behind the heads (docs/validation.md, held-out round 4)
MAX_TOE_OFF_AXIS_DEG = 25.0
BY_POSITION = "lateral / medial told by position"
MEDIAL_ROLES = {"KNE": "KNM", "ANK": "MED"}  # a lateral marker's role -> its medial partner's
# two markers of one knee or ankle lie a joint's width (plus a marker's 14 mm) apart across the body: the knee and
# ankle widths the shared trials' files give are 63-109 mm; 30 mm leaves room for the pelvis' lateral axis turned
# against the joint's (a foot toeing out), and is more than two markers meant for one point are apart
MIN_JOINT_WIDTH_M = 0.03
MAX_JOINT_WIDTH_M = 0.16  # the widest knee, 109 mm, plus the markers and room: further apart, not one joint's pair
SAME_SIDE_SHARE = 0.95  # of the frames seeing both, those where the lateral one is the outer
# a toe or metatarsal marker lies within a foot's length of its ankle marker: de Leva's foot is 258 mm long at
# 1.74 m, the ankle marker 50-80 mm forward of its back; the shared trials' are 103-186 mm apart, a thigh cluster's
# 570 mm or more (osim_jogging's RFM2)
MAX_TOE_FROM_ANKLE_M = 0.25
_SIDE_WORDS = (("LEFT", "L"), ("RIGHT", "R"), ("L", "L"), ("R", "R"))
_SEPARATORS = re.compile(r"[._\-\s]+")
_LOOKUP = {name: (role, conv) for role, names in SIDED.items() for name, conv in names}
_LOOKUP_UNSIDED = {name: (role, conv) for role, names in UNSIDED.items() for name, conv in names}
_LOOKUP_FOREFOOT = {name: (role, conv) for role, names in FOREFOOT.items() for name, conv in names}
_LOOKUP_EPICONDYLE = {name: (role, conv) for role, names in EPICONDYLES.items() for name, conv in names}


@dataclass(frozen=True)
class LabelMatch:
    """The roles found: role -> the file's label; the aliases used (role -> label, where the label is not the
    role's own name) and their conventions; roles two or more seen labels claim (role -> labels)."""

    roles: dict[str, str]
    aliases: dict[str, str]
    conventions: tuple[str, ...]
    ambiguous: dict[str, tuple[str, ...]]
    by_position: dict[str, str] = field(default_factory=dict)  # role -> why its label was chosen by position
    toe: dict[str, str] = field(default_factory=dict)  # TOE role -> why its marker was chosen (at the foot, forefoot)
    midpoints: dict[str, tuple[str, ...]] = field(default_factory=dict)  # role -> the labels it is the mean of
    epicondyles: dict[str, str] = field(default_factory=dict)  # epicondyle label -> why it is or is not the knee's

    def summary(self) -> dict:
        return {"conventions": list(self.conventions), "aliases": dict(sorted(self.aliases.items())),
                **({"by_position": dict(sorted(self.by_position.items()))} if self.by_position else {}),
                **({"toe": dict(sorted(self.toe.items()))} if self.toe else {}),
                **({"epicondyles": dict(sorted(self.epicondyles.items()))} if self.epicondyles else {})}

    def check(self, source: str, roles=None) -> None:
        """InputError naming the first of ``roles`` (default: any) that two labels claim."""
        for role, labels in self.ambiguous.items():
            if roles is None or role in roles:
                choices = " or ".join(f'{role} = "{lab}"' for lab in dict.fromkeys(labels))
                raise InputError(f"{source}: {_claimed(labels)} the {role} marker: which one the lab meant "
                                 f"cannot be told from the names (a marker map's [labels] chooses: {choices})")


def _claimed(labels: tuple[str, ...]) -> str:
    return ("labels " + " and ".join(map(repr, labels)) + " both name" if len(set(labels)) > 1 else
            f"label {labels[0]!r} is written {len(labels)} times with data, each naming")


def role_of(label: str) -> tuple[str, str] | None:
    """The Plug-in Gait role (e.g. ``LKNE``) a file label names, and its convention; None if none."""
    return _named(label, _LOOKUP, _LOOKUP_UNSIDED)


def _named(label: str, lookup: dict, unsided: dict) -> tuple[str, str] | None:
    """The role (side letter + ``lookup``'s role, or ``unsided``'s) ``label`` names, and its convention."""
    tokens = [t for t in _SEPARATORS.split(label.strip().upper()) if t]
    if not tokens:
        return None
    joined = "".join(tokens)
    if joined in unsided:
        return unsided[joined]
    candidates = [(side, joined[len(word):]) for word, side in _SIDE_WORDS if joined.startswith(word)]
    if len(tokens) > 1:
        candidates += [(side, "".join(tokens[:-1])) for word, side in _SIDE_WORDS if tokens[-1] == word]
    for side, part in candidates:
        if part in lookup:
            role, conv = lookup[part]
            return side + role, conv
    return None


def _common_prefix(labels: list[str]) -> str:
    """A prefix every label shares, up to and including a separator (``sub01_``), else ''."""
    if len(labels) < 2:
        return ""
    head = labels[0]
    for lab in labels[1:]:
        while not lab.startswith(head):
            head = head[:-1]
    cut = max((m.end() for m in _SEPARATORS.finditer(head)), default=0)
    return head[:cut]


def _bare(labels: list[str]) -> dict[str, str]:
    """Each label without the prefix and the suffix (from a separator on: ``LASI_sub01``) every label shares."""
    prefix = _common_prefix(labels)
    suffix = _common_prefix([lab[::-1] for lab in labels])[::-1]
    return {lab: lab[len(prefix):len(lab) - len(suffix)] for lab in labels}


def match_labels(trial: C3dTrial, pinned: frozenset[str] = frozenset()) -> LabelMatch:
    """Match ``trial``'s seen labels to roles (see the module docstring). ``pinned``: roles a marker map already
    named (only the label equal to the role fills them)."""
    seen = np.isfinite(trial.points).all(axis=2).any(axis=0)
    labels = [lab for lab, ok in zip(trial.labels, seen, strict=True) if ok]
    bare = _bare(labels)
    claims: dict[str, list[str]] = {}
    convention = {}
    for lab in labels:
        found = role_of(bare[lab])
        if found and (found[0] not in pinned or lab == found[0]):
            claims.setdefault(found[0], []).append(lab)
            convention[lab] = found[1]
    along_leg = _epicondyles_on_the_leg(trial, labels, bare, claims, pinned)
    convention.update({lab: EPICONDYLE for lab in along_leg})  # only those read are looked up (aliases)
    by_position = _lateral_and_medial(trial, claims, pinned)
    convention.update({claims[role][0]: BY_POSITION for role in by_position})
    toe = _toe_at_foot(trial, claims, pinned)
    midpoints = {}
    for side in "LR":
        if side + "TOE" not in pinned:
            chosen = (_forefoot_toe(trial, labels, bare, claims, side) if side + "TOE" not in claims else
                      _toe_off_axis(trial, labels, bare, claims, side))
            if chosen:
                name, why, parts = chosen
                claims[side + "TOE"], convention[name], toe[side + "TOE"] = [name], FOREFOOT_TOE, why
                if len(parts) > 1:
                    midpoints[side + "TOE"] = parts
    ambiguous = {role: tuple(labs) for role, labs in claims.items() if len(labs) > 1}
    roles = {role: labs[0] for role, labs in claims.items() if len(labs) == 1}
    aliases = {role: lab for role, lab in roles.items() if lab != role}
    return LabelMatch(roles, aliases, tuple(dict.fromkeys(convention[lab] for _, lab in sorted(aliases.items()))),
                      ambiguous, by_position, toe, midpoints, along_leg)


def _epicondyles_on_the_leg(trial: C3dTrial, labels: list[str], bare: dict[str, str],
                            claims: dict[str, list[str]], pinned: frozenset[str]) -> dict[str, str]:
    """Add, in place in ``claims``, each epicondyle label (:data:`EPICONDYLES`) lying along its side's leg: its
    median position projected on the line from the side's ASIS marker to its ankle marker (each claimed once) at
    least :data:`MIN_KNEE_ALONG_LEG` of the way down. Returns label -> why, for each so read and each set aside."""
    out = {}
    for lab in labels:
        found = _named(bare[lab], _LOOKUP_EPICONDYLE, {})
        if not found or found[0] in pinned:
            continue
        side = found[0][0]
        asis, ankle = claims.get(side + "ASI", []), claims.get(side + "ANK", [])
        if len(asis) != 1 or len(ankle) != 1:
            continue
        top, leg = trial.marker(asis[0]), trial.marker(ankle[0]) - trial.marker(asis[0])
        with np.errstate(invalid="ignore", divide="ignore"):
            down = np.sum((trial.marker(lab) - top) * leg, axis=1) / np.sum(leg * leg, axis=1)
        down = down[np.isfinite(down)]
        if not down.size:
            continue
        along = float(np.median(down))
        if along >= MIN_KNEE_ALONG_LEG:
            claims.setdefault(found[0], []).append(lab)
            out[lab] = f"{found[0]}: {100 * along:.0f} % of the way from {asis[0]} down to {ankle[0]}"
        else:
            out[lab] = (f"not read ({found[0]}?): {100 * along:.0f} % of the way from {asis[0]} down to {ankle[0]}, "
                        f"not along the leg (an elbow's epicondyle)")
    return out


def _from_ankle(trial: C3dTrial, label: str, ankle: str) -> tuple[bool, float]:
    """Whether ``label`` lies within :data:`MAX_TOE_FROM_ANKLE_M` of the marker ``ankle`` in nearly every frame
    seeing both (:data:`SAME_SIDE_SHARE`), and its median distance (m; NaN: never seen together)."""
    d = np.linalg.norm(trial.marker(label) - trial.marker(ankle), axis=1)
    d = d[np.isfinite(d)]
    if not d.size:
        return False, float("nan")
    return bool(np.mean(d <= MAX_TOE_FROM_ANKLE_M) >= SAME_SIDE_SHARE), float(np.median(d))


def _toe_at_foot(trial: C3dTrial, claims: dict[str, list[str]], pinned: frozenset[str]) -> dict[str, str]:
    """Split, in place in ``claims``, a side's TOE role that two or more labels claim when exactly one of them lies
    at the foot (near its ankle marker, :func:`_from_ankle`): the others are set aside. Returns role -> why."""
    out = {}
    for side in "LR":
        role, ankle = side + "TOE", claims.get(side + "ANK", [])
        labs = claims.get(role, [])
        if len(labs) < 2 or len(set(labs)) < len(labs) or len(ankle) != 1 or role in pinned:
            continue
        where = {lab: _from_ankle(trial, lab, ankle[0]) for lab in labs}
        near = [lab for lab in labs if where[lab][0]]
        if len(near) != 1:
            continue
        claims[role] = near
        apart = "; ".join(f"{lab} set aside: {1000 * where[lab][1]:.0f} mm from {ankle[0]}, not at the foot"
                          for lab in labs if lab != near[0])
        out[role] = f"{near[0]}: at the foot, {1000 * where[near[0]][1]:.0f} mm from {ankle[0]}; {apart}"
    return out


def _heads(trial: C3dTrial, labels: list[str], bare: dict[str, str], claims: dict[str, list[str]],
           side: str) -> dict[str, list[str]]:
    """``side``'s metatarsal-head markers at the foot (near its ankle marker, when one label claims it): role
    (``MT1``, ``MT5``) -> the labels naming it."""
    ankle = claims.get(side + "ANK", [])
    heads: dict[str, list[str]] = {}
    for lab in labels:
        found = _named(bare[lab], _LOOKUP_FOREFOOT, {})
        if found and found[0][0] == side and (len(ankle) != 1 or _from_ankle(trial, lab, ankle[0])[0]):
            heads.setdefault(found[0][1:], []).append(lab)
    return heads


def _toe_off_axis(trial: C3dTrial, labels: list[str], bare: dict[str, str], claims: dict[str, list[str]],
                  side: str) -> tuple[str, str, tuple[str, ...]] | None:
    """The first and fifth metatarsal heads' mid-point in place of ``side``'s toe marker (the one label claiming
    it) when that lies more than :data:`MAX_TOE_OFF_AXIS_DEG` off the line from the heel marker to the mid-point
    (median over the frames seeing all four): as :func:`_forefoot_toe`; None: the toe is kept."""
    heads, toe, heel = _heads(trial, labels, bare, claims, side), claims[side + "TOE"], claims.get(side + "HEE", [])
    mt1, mt5 = heads.get("MT1", []), heads.get("MT5", [])
    if len(toe) != 1 or len(heel) != 1 or len(mt1) != 1 or len(mt5) != 1:
        return None
    back = trial.marker(heel[0])
    mid = (trial.marker(mt1[0]) + trial.marker(mt5[0])) / 2 - back
    ahead = trial.marker(toe[0]) - back
    cos = np.sum(mid * ahead, axis=1) / (np.linalg.norm(mid, axis=1) * np.linalg.norm(ahead, axis=1))
    cos = cos[np.isfinite(cos)]
    off = float(np.degrees(np.arccos(np.clip(np.median(cos), -1.0, 1.0)))) if cos.size else 0.0
    if off <= MAX_TOE_OFF_AXIS_DEG:
        return None
    return (f"{mt1[0]}+{mt5[0]}", f"mid-point of {mt1[0]} and {mt5[0]} ({toe[0]} set aside: {off:.0f} deg off the "
            f"line from {heel[0]} to the metatarsal heads, not on the foot's long axis)", (mt1[0], mt5[0]))


def _forefoot_toe(trial: C3dTrial, labels: list[str], bare: dict[str, str], claims: dict[str, list[str]],
                  side: str) -> tuple[str, str, tuple[str, ...]] | None:
    """The toe marker's stand-in on ``side`` (module docstring): the name it goes by, why, and the labels it is
    the mean of; None without one."""
    heads = _heads(trial, labels, bare, claims, side)
    mt1, mt5 = heads.get("MT1", []), heads.get("MT5", [])
    if len(mt1) == 1 and len(mt5) == 1:
        return (f"{mt1[0]}+{mt5[0]}", f"mid-point of {mt1[0]} and {mt5[0]} (no toe marker: the first and fifth "
                f"metatarsal heads)", (mt1[0], mt5[0]))
    if len(mt5) == 1:
        return (mt5[0], f"{mt5[0]} (no toe marker: the fifth metatarsal head alone, the foot's long axis turned "
                f"outward by it)", (mt5[0],))
    return None


def _across(trial: C3dTrial, claims: dict[str, list[str]], side: str) -> np.ndarray | None:
    """(F, 3) unit vectors from the pelvis' midline out towards ``side`` ("L", "R"): along RASI -> LASI; None
    without both ASIS markers."""
    if len(claims.get("LASI", ())) != 1 or len(claims.get("RASI", ())) != 1:
        return None
    left = trial.marker(claims["LASI"][0]) - trial.marker(claims["RASI"][0])
    with np.errstate(invalid="ignore"):  # ASIS markers on top of each other (type1.C3D's unseen ones): NaN, unread
        left = left / np.linalg.norm(left, axis=1, keepdims=True)
    return left if side == "L" else -left


def _lateral_and_medial(trial: C3dTrial, claims: dict[str, list[str]], pinned: frozenset[str]) -> dict[str, str]:
    """Split, in place in ``claims``, a side's lateral knee or ankle role that two labels claim while nothing
    claims its medial role, by position (module docstring); returns role -> why, for each role so filled."""
    out = {}
    for side in "LR":
        for lateral, medial in MEDIAL_ROLES.items():
            lat, med = side + lateral, side + medial
            labs = claims.get(lat, [])
            if len(labs) != 2 or labs[0] == labs[1] or med in claims or {lat, med} & pinned:
                continue
            out_dir = _across(trial, claims, side)
            if out_dir is None:
                continue
            d = trial.marker(labs[0]) - trial.marker(labs[1])
            seen = np.isfinite(d).all(axis=1) & np.isfinite(out_dir).all(axis=1)
            if not seen.any():
                continue
            gap = np.sum(d[seen] * out_dir[seen], axis=1)  # across the body, + where the first is the outer
            along = np.linalg.norm(d[seen] - gap[:, None] * out_dir[seen], axis=1)
            width = abs(float(np.median(gap)))
            if not (MIN_JOINT_WIDTH_M <= width and float(np.median(np.linalg.norm(d[seen], axis=1))) <=
                    MAX_JOINT_WIDTH_M and width >= float(np.median(along))
                    and np.mean(np.sign(gap) == np.sign(np.median(gap))) >= SAME_SIDE_SHARE):
                continue
            outer, inner = labs if np.median(gap) > 0 else labs[::-1]
            claims[lat], claims[med] = [outer], [inner]
            mm = 1000 * width
            out[lat] = f"{outer}: {mm:.0f} mm lateral of {inner}"
            out[med] = f"{inner}: {mm:.0f} mm medial of {outer}"
    return out


def standard_trial(trial: C3dTrial, pinned: frozenset[str] = frozenset()) -> tuple[C3dTrial, LabelMatch]:
    """``trial`` with its markers under their Plug-in Gait role names (labels claiming no role, or a role other
    labels claim too, keep theirs; a never-seen label named like a role another label fills becomes ``label?``).
    ``pinned`` as for :func:`match_labels`."""
    match = match_labels(trial, pinned)
    if match.midpoints:  # the toe's stand-in as a marker of its own: the mean of the metatarsal heads
        means = [np.mean([trial.marker(lab) for lab in labs], axis=0) for labs in match.midpoints.values()]
        trial = replace(trial, labels=trial.labels + [match.roles[r] for r in match.midpoints],
                        points=np.concatenate([trial.points, np.stack(means, axis=1)], axis=1))
    by_label = {lab: role for role, lab in match.roles.items()}
    seen = np.isfinite(trial.points).all(axis=2).any(axis=0)
    out = []
    for lab, ok in zip(trial.labels, seen, strict=True):
        if ok and lab in by_label:
            out.append(by_label[lab])
        elif lab in match.roles or (not ok and lab in by_label):
            out.append(lab + "?")  # a never-seen copy, or a role's name another label fills
        else:
            out.append(lab)
    return replace(trial, labels=out), match
