"""Which skeleton joint is which body segment: name patterns and explicit mapping files.

Each BVH joint "owns" the segment from itself to its child. Patterns cover the common
skeletons (Bandai, CMU and its lower-case "lhip", SFU, Mixamo-style); anything else needs a mapping file, a TOML
table ``[segments]`` of ``joint name = "kind"`` (kinds below, plus ``side = "left"`` etc.
inferred from the name or given as ``"thigh:left"``).

Kinds: pelvis, spine (any trunk joint between pelvis and neck), neck, head, collar,
upper_arm, forearm, hand, thigh, shank, foot, toe, and the massless ones: fingers,
root (a static reference joint above the pelvis) and link (a short connector bone such
as CMU's LHipJoint, or a helper bone beside a segment's own: a twist, roll or share bone,
as Reallusion's CC_Base_L_ThighTwist01 and CC_Base_L_KneeShareBone, part of the segment
whose name it carries and not another of its kind).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from livezmp.errors import InputError
from livezmp.tomlfile import read_toml

KINDS = (
    "root", "link", "pelvis", "spine", "neck", "head", "collar", "upper_arm", "forearm", "hand",
    "thigh", "shank", "foot", "toe", "fingers",
)

# Order matters: first match wins. Names are lower-cased with separators removed.
_PATTERNS: list[tuple[str, str]] = [
    (r"(twist|sharebone|roll\d*$)", "link"),  # a limb's helper bones, before the limb's name matches
    (r"(thumb|index|middle|ring|pinky|finger|handend|handtip|hand_?site)", "fingers"),
    (r"(toebase|toe|ball|forefoot)", "toe"),  # the forefoot (metatarsals and toes) is the foot's distal part
    (r"hipjoint", "link"),
    (r"(forearm|lowerarm|elbow|radius|ulna)", "forearm"),
    (r"(upperarm|humerus|^(l|r|left|right)?arm$|arm(l|r|left|right)?$)", "upper_arm"),
    (r"(collar|clavicle|shoulder)", "collar"),
    (r"(hand|wrist)", "hand"),
    (r"(upleg|upperleg|thigh|hip(l|r|left|right)$|^(l|r|left|right)hip$|femur)", "thigh"),
    (r"(lowleg|lowerleg|shin|knee|calf|tibia|^(l|r|left|right)?leg$|leg(l|r|left|right)?$)", "shank"),
    (r"(foot|ankle)", "foot"),
    (r"(head)", "head"),
    (r"(neck)", "neck"),
    (r"(hips|pelvis|hip$|^hip)", "pelvis"),
    (r"(spine|chest|torso|back|abdomen|thorax|waist)", "spine"),
    (r"(root|reference)", "root"),
]
_CENTER_KINDS = ("pelvis", "spine", "neck", "head", "root")


@dataclass(frozen=True)
class SegmentTag:
    kind: str
    side: str  # "left", "right" or "center"


def _clean(name: str) -> str:
    s = name.lower()
    s = re.sub(r"^(mixamorig[:_]?|bip0?1[ _]?|[a-z]+:)", "", s)
    return s


def _side(name: str) -> str:
    """left/right/center from a joint name: 'Left…', '…_L', 'LThigh', 'l_hip', ASF 'lfemur'."""
    low = name.lower()
    if "left" in low:
        return "left"
    if "right" in low:
        return "right"
    tokens = [t.lower() for t in re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])|\d+", name.split(":")[-1])]
    if "l" in tokens:
        return "left"
    if "r" in tokens:
        return "right"
    # One lower-case letter glued to a limb word: ASF/CMU "lfemur", "lhipjoint", the lower-case CMU BVH skeleton's
    # "lhip", "lknee", "rshoulder", "relbow" (its hip joint is the thigh, as in classify). The rest must name a
    # sided segment, so "lowerback" ("owerback": a spine word) and "root" stay centre joints.
    last = re.sub(r"[\s_.\-]", "", name.split(":")[-1])
    if last[:1] in ("l", "r", "L", "R") and last[1:].islower() and _kind_of(last[1:]) not in (None, *_CENTER_KINDS[1:]):
        return "left" if last[0] in "lL" else "right"
    return "center"


def _kind_of(cleaned: str) -> str | None:
    """The first pattern's kind matching a lower-cased, separator-free name, else None."""
    return next((kind for pat, kind in _PATTERNS if re.search(pat, cleaned)), None)


def classify(name: str) -> SegmentTag | None:
    """Segment kind and side of a joint name, or None when no pattern matches."""
    s = re.sub(r"[\s_.\-]", "", _clean(name))
    s = re.sub(r"^(left|right)", "", s)
    s = re.sub(r"(left|right)$", "", s)
    side = _side(name)
    kind = _kind_of(s)
    if kind is None:
        return None
    if kind == "pelvis" and side != "center":
        kind = "thigh"  # "LeftHip" names the hip joint, i.e. the thigh segment
    if kind in _CENTER_KINDS:
        side = "center"
    return SegmentTag(kind, side)


def _shoulders_beside_collars(names: list[str], tags: list[SegmentTag], mapping: dict[str, SegmentTag]) -> None:
    """A "shoulder" joint on a side that also has a collar or clavicle joint and no upper-arm joint is the upper
    arm (in place in ``tags``): the lower-case CMU and Daz-friendly skeletons' lcollar → lshoulder → lelbow. Mixamo's
    LeftShoulder → LeftArm has its arm, and stays the collar. Joints named in ``mapping`` keep their tag."""
    for side in ("left", "right"):
        if any((t.kind, t.side) == ("upper_arm", side) for t in tags):
            continue
        collars = [i for i, t in enumerate(tags) if (t.kind, t.side) == ("collar", side) and names[i] not in mapping]
        shoulders = [i for i in collars if "shoulder" in names[i].lower()]
        if shoulders and len(shoulders) < len(collars):
            for i in shoulders:
                tags[i] = SegmentTag("upper_arm", side)


def load_mapping(path: str | Path) -> dict[str, SegmentTag]:
    """Read an explicit mapping file: TOML ``[segments]`` table of joint = "kind[:side]"."""
    p = Path(path)
    data = read_toml(p, "mapping")
    table = data.get("segments")
    if not isinstance(table, dict):
        raise InputError(f"{p}: missing [segments] table")
    out: dict[str, SegmentTag] = {}
    for joint, val in table.items():
        kind, _, side = str(val).partition(":")
        if kind not in KINDS:
            raise InputError(f"{p}: joint {joint!r}: unknown segment kind {kind!r} (one of {', '.join(KINDS)})")
        if side not in ("", "left", "right", "center"):
            raise InputError(f"{p}: joint {joint!r}: side must be left, right or center")
        out[joint] = SegmentTag(kind, side or _side(joint))
    return out


def tag_joints(names: list[str], mapping: dict[str, SegmentTag] | None = None, source: str = "") -> list[SegmentTag]:
    """Tag every joint; joints named in ``mapping`` take its tag, others the patterns.

    Raises InputError when the result is not a usable humanoid (needs a pelvis and two
    legs with thigh, shank and foot) so that unknown skeletons fail loudly.
    """
    mapping = mapping or {}
    tags: list[SegmentTag] = []
    unknown: list[str] = []
    for n in names:
        t = mapping.get(n) or classify(n)
        if t is None:
            unknown.append(n)
            t = SegmentTag("fingers", "center")  # massless until mapped
        tags.append(t)
    _shoulders_beside_collars(names, tags, mapping)
    need = [("pelvis", "center")] + [(k, s) for s in ("left", "right") for k in ("thigh", "shank", "foot")]
    have = {(t.kind, t.side) for t in tags}
    missing = [f"{k}:{s}" if s != "center" else k for k, s in need if (k, s) not in have]
    if missing:
        extra = f"; unrecognised joints: {', '.join(unknown[:8])}" if unknown else ""
        raise InputError(
            f"{source}: unknown skeleton: no joint found for {', '.join(missing)}{extra} "
            "(give a mapping file with --mapping)"
        )
    return tags
