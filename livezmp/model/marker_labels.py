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
  Walk1, newwalk, Sample_Jump2 write them): sacrum ``VSAC`` (``V.Sacral``), toes ``L.TO``/``R.TO``.
- CAST (Cappozzo et al. 1995, Clin Biomech 10:171) as Qualisys' gait and running projects (QTM, with Visual3D)
  and OptiTrack's "Conventional Lower" set label it, with the ISB landmark names of Van Sint Jan (2007, Color
  Atlas of Skeletal Landmark Definitions): ``L_IAS L_IPS SACR L_FLE L_FME L_FAL L_TAM L_FCC L_FM2``.
  Trunk: ``CV7``, ``TV10``, incisura jugularis ``IJ`` (Plug-in Gait's CLAV), processus xiphoideus ``PX`` (its
  STRN) (Wu et al. 2005, J Biomech 38:981).
- Landmark names seen in the c3d.org samples: ``RLFC`` lateral femoral condyle, ``RLMA`` lateral malleolus,
  ``RCAL`` calcaneus, medial ``RMFC``/``RMMA`` (Innovative Sports Training), ``RLKN``/``RMKN`` lateral / medial
  knee (TYPE-3), ``SACRUM`` (Walking_Hybrid, Capture0002); medial ``MKNE KNEM MFC MEPI ANKM MANK MMAL``
  (read before these conventions).

Two labels of a file claiming one role (``LANK`` and ``LLMA``) are refused in one line naming both: which one
the lab meant cannot be told from the names. A label never seen in the take claims nothing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from livezmp.errors import InputError
from livezmp.model.c3d import C3dTrial

PIG = "Plug-in Gait"
HH = "Helen Hayes as Codamotion / Motion Analysis write it"
CAST = "CAST / ISB landmark names (Qualisys, Visual3D, OptiTrack)"
LAB = "lateral / medial landmark names"
# role suffix (after the side letter) -> (name after the side, convention) ...
SIDED: dict[str, tuple[tuple[str, str], ...]] = {
    "ASI": (("ASI", PIG), ("ASIS", HH), ("IAS", CAST)),
    "PSI": (("PSI", PIG), ("PSIS", HH), ("IPS", CAST)),
    "THI": (("THI", PIG),),
    "KNE": (("KNE", PIG), ("KNEE", HH), ("FLE", CAST), ("LFC", LAB), ("LKN", LAB)),
    "KNM": (("KNM", PIG), ("MKNE", LAB), ("KNEM", LAB), ("FME", CAST), ("MFC", LAB), ("MEPI", LAB), ("MKN", LAB)),
    # not Helen Hayes' shank wand (Motion Analysis' RSHA): in Plug-in Gait's ankle chord rule it put Walk1's ankle
    # centres 55-60 mm from the file's own (VLAN, VRAN), 14-19 mm without it (docs/validation.md)
    "TIB": (("TIB", PIG),),
    "ANK": (("ANK", PIG), ("ANKLE", HH), ("FAL", CAST), ("LMA", LAB)),
    "MED": (("MED", PIG), ("MMA", LAB), ("ANKM", LAB), ("MANK", LAB), ("MMAL", LAB), ("TAM", CAST)),
    "HEE": (("HEE", PIG), ("HEEL", HH), ("FCC", CAST), ("CAL", LAB)),
    "TOE": (("TOE", PIG), ("TO", HH), ("FM2", CAST)),
    "CLA": (("CLA", PIG),),
}
UNSIDED: dict[str, tuple[tuple[str, str], ...]] = {
    "SACR": (("SACR", PIG), ("VSAC", HH), ("VSACRAL", HH), ("SACRUM", LAB)),
    "C7": (("C7", PIG), ("CV7", CAST)),
    "T10": (("T10", PIG), ("TV10", CAST)),
    "CLAV": (("CLAV", PIG), ("IJ", CAST)),
    "STRN": (("STRN", PIG), ("PX", CAST)),
}
_SIDE_WORDS = (("LEFT", "L"), ("RIGHT", "R"), ("L", "L"), ("R", "R"))
_SEPARATORS = re.compile(r"[._\-\s]+")
_LOOKUP = {name: (role, conv) for role, names in SIDED.items() for name, conv in names}
_LOOKUP_UNSIDED = {name: (role, conv) for role, names in UNSIDED.items() for name, conv in names}


@dataclass(frozen=True)
class LabelMatch:
    """The roles found: role -> the file's label; the aliases used (role -> label, where the label is not the
    role's own name) and their conventions; roles two or more seen labels claim (role -> labels)."""

    roles: dict[str, str]
    aliases: dict[str, str]
    conventions: tuple[str, ...]
    ambiguous: dict[str, tuple[str, ...]]

    def summary(self) -> dict:
        return {"conventions": list(self.conventions), "aliases": dict(sorted(self.aliases.items()))}

    def check(self, source: str, roles=None) -> None:
        """InputError naming the first of ``roles`` (default: any) that two labels claim."""
        for role, labels in self.ambiguous.items():
            if roles is None or role in roles:
                raise InputError(f"{source}: {_claimed(labels)} the {role} marker: which one the lab meant "
                                 f"cannot be told from the names (a marker map's [labels] can say: {role} = \"...\")")


def _claimed(labels: tuple[str, ...]) -> str:
    return ("labels " + " and ".join(map(repr, labels)) + " both name" if len(set(labels)) > 1 else
            f"label {labels[0]!r} is written {len(labels)} times with data, each naming")


def role_of(label: str) -> tuple[str, str] | None:
    """The Plug-in Gait role (e.g. ``LKNE``) a file label names, and its convention; None if none."""
    tokens = [t for t in _SEPARATORS.split(label.strip().upper()) if t]
    if not tokens:
        return None
    joined = "".join(tokens)
    if joined in _LOOKUP_UNSIDED:
        return _LOOKUP_UNSIDED[joined]
    candidates = [(side, joined[len(word):]) for word, side in _SIDE_WORDS if joined.startswith(word)]
    if len(tokens) > 1:
        candidates += [(side, "".join(tokens[:-1])) for word, side in _SIDE_WORDS if tokens[-1] == word]
    for side, part in candidates:
        if part in _LOOKUP:
            role, conv = _LOOKUP[part]
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
    ambiguous = {role: tuple(labs) for role, labs in claims.items() if len(labs) > 1}
    roles = {role: labs[0] for role, labs in claims.items() if len(labs) == 1}
    aliases = {role: lab for role, lab in roles.items() if lab != role}
    return LabelMatch(roles, aliases, tuple(dict.fromkeys(convention[lab] for _, lab in sorted(aliases.items()))),
                      ambiguous)


def standard_trial(trial: C3dTrial, pinned: frozenset[str] = frozenset()) -> tuple[C3dTrial, LabelMatch]:
    """``trial`` with its markers under their Plug-in Gait role names (labels claiming no role, or a role other
    labels claim too, keep theirs; a never-seen label named like a role another label fills becomes ``label?``).
    ``pinned`` as for :func:`match_labels`."""
    match = match_labels(trial, pinned)
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
