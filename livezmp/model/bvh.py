"""BVH motion files: parse (hierarchy + motion), write back, and split out channels.

Conventions follow the common BVH reading: a joint's local translation is its OFFSET,
except that position channels, where a joint has them, replace the offset's components
(that is how exporters such as MotionBuilder write them, and how the Bandai data
carries its root translation). Rotation channels apply in the order they are listed,
intrinsically: R = R_c1 · R_c2 · R_c3. Values stay in the file's units (degrees and
file length units) here; the body model converts to SI.
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from livezmp.checks import (
    MAX_CHANNEL_VALUE,
    check_frame_period,
    check_input_file,
    first_out_of_range,
    read_input_pieces,
    read_input_text,
)
from livezmp.errors import InputError

MAX_JOINTS = 256  # joints of a skeleton (so at most 1536 channels); mocap skeletons have 20-170 (hands, faces)
MAX_CHANNELS = 256  # of a body model (its part of the skeleton): Pinocchio's data grows as the cube, ~1 GB at 256
CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")


@dataclass
class BvhJoint:
    """One joint of the hierarchy; ``offset`` in file units, ``end_site`` the End Site offset if any."""

    name: str
    parent: int
    offset: np.ndarray
    channels: list[str]
    end_site: np.ndarray | None = None
    children: list[int] = field(default_factory=list)
    first_channel: int = 0


@dataclass
class BvhMotion:
    """A parsed BVH: joints in file order, ``frames`` (F, C) in file units/degrees."""

    joints: list[BvhJoint]
    frame_time: float
    frames: np.ndarray
    source: str = "<memory>"

    @property
    def n_channels(self) -> int:
        return sum(len(j.channels) for j in self.joints)

    @property
    def fps(self) -> float:
        """Frames a second (Hz), from ``frame_time`` (s)."""
        return 1.0 / self.frame_time

    def joint_index(self, name: str) -> int:
        for i, j in enumerate(self.joints):
            if j.name == name:
                return i
        raise KeyError(name)

    def channel_labels(self) -> list[str]:
        """``Joint.Channel`` for every column of ``frames``."""
        return [f"{j.name}.{c}" for j in self.joints for c in j.channels]


@dataclass(frozen=True)
class BvhPart:
    """The part of a skeleton a body model is built on: ``kept`` the file's indices of its joints (file order, so
    each after its parent), ``joints`` copies of them renumbered within the part (parent, children, first channel;
    offsets, channels and End Sites as the file has them), ``columns`` (C',) the file's channel index of each of the
    part's channels in order: the map from a file's rows to the model's."""

    kept: list[int]
    joints: list[BvhJoint]
    columns: np.ndarray

    def joint(self, i: int) -> BvhJoint:
        """The part's copy of the file's joint ``i`` (one the part keeps)."""
        return self.joints[self.kept.index(i)]


def skeleton_part(joints: list[BvhJoint], needed: set[int]) -> BvhPart:
    """The part of ``joints`` made of the ``needed`` ones and those leading to them (their ancestors); the subtrees
    with none of them are dropped."""
    keep = set()
    for i in needed:
        while i >= 0 and i not in keep:
            keep.add(i)
            i = joints[i].parent
    kept = sorted(keep)
    at = {i: k for k, i in enumerate(kept)}
    part, columns, first = [], [], 0
    for i in kept:
        j = joints[i]
        part.append(BvhJoint(j.name, at.get(j.parent, -1), j.offset, j.channels, j.end_site,
                             [at[c] for c in j.children if c in at], first))
        columns.extend(range(j.first_channel, j.first_channel + len(j.channels)))
        first += len(j.channels)
    return BvhPart(kept, part, np.array(columns, dtype=int))


class _Cursor:
    """Lazy line cursor over (line number, line) pairs, remembering the last line number read
    (for error messages); the hierarchy and the motion rows are read through the same one."""

    def __init__(self, lines: Iterator[tuple[int, str]], source: str):
        self.lines, self.lineno, self.source = lines, 0, source

    def __iter__(self) -> Iterator[tuple[int, str]]:
        for lineno, line in self.lines:
            self.lineno = lineno
            yield lineno, line

    def error(self, msg: str, line: int | None = None) -> InputError:
        return InputError(f"{self.source}:{self.lineno if line is None else line}: {msg}")

    def next_tokens(self) -> list[str]:
        for _, line in self:
            toks = line.split()
            if toks:
                return toks
        raise self.error("unexpected end of file (truncated BVH?)")


def _floats(cur: _Cursor, toks: list[str], what: str) -> np.ndarray:
    try:
        vals = np.array([float(t) for t in toks], dtype=float)
    except ValueError:
        raise cur.error(f"non-numeric value in {what}: {' '.join(toks)!r}") from None
    bad = first_out_of_range(vals, MAX_CHANNEL_VALUE)
    if bad is not None:
        raise cur.error(f"value {toks[bad[0]]} in {what} is not finite or beyond ±{MAX_CHANNEL_VALUE:g}")
    return vals


def _parse_end_site(cur: _Cursor, joint: BvhJoint) -> None:
    name = joint.name
    if cur.next_tokens() != ["{"]:
        raise cur.error(f"joint {name}: expected '{{' after End Site")
    toks = cur.next_tokens()
    if toks[0] != "OFFSET" or len(toks) != 4:
        raise cur.error(f"End Site of {name}: expected 'OFFSET x y z'")
    joint.end_site = _floats(cur, toks[1:], f"End Site of {name}")
    if cur.next_tokens() != ["}"]:
        raise cur.error(f"End Site of {name}: expected '}}'")


def _open_joint(cur: _Cursor, joints: list[BvhJoint], name: str, parent: int, first_channel: int) -> BvhJoint:
    """Read a joint's '{', OFFSET and CHANNELS lines and append it to ``joints``."""
    if len(joints) >= MAX_JOINTS:
        raise cur.error(f"more than {MAX_JOINTS} joints: not a skeleton this tool analyses")
    toks = cur.next_tokens()
    if toks != ["{"]:
        raise cur.error(f"expected '{{' after joint {name}, got {' '.join(toks)!r}")
    toks = cur.next_tokens()
    if toks[0] != "OFFSET" or len(toks) != 4:
        raise cur.error(f"joint {name}: expected 'OFFSET x y z'")
    offset = _floats(cur, toks[1:], f"OFFSET of {name}")
    toks = cur.next_tokens()
    if toks[0] != "CHANNELS":
        raise cur.error(f"joint {name}: expected CHANNELS")
    try:
        count = int(toks[1]) if len(toks[1]) <= 3 else -1
    except (IndexError, ValueError):
        raise cur.error(f"joint {name}: bad channel count") from None
    channels = toks[2:]
    if count != len(channels):
        raise cur.error(f"joint {name}: CHANNELS says {toks[1]} but lists {len(channels)}")
    for c in channels:
        if c not in CHANNEL_NAMES:
            raise cur.error(f"joint {name}: unknown channel {c!r}")
    if len(set(channels)) != len(channels):
        raise cur.error(f"joint {name}: a channel is listed twice")
    joint = BvhJoint(name, parent, offset, channels, first_channel=first_channel)
    if parent >= 0:
        joints[parent].children.append(len(joints))
    joints.append(joint)
    return joint


def _parse_joints(cur: _Cursor, joints: list[BvhJoint], root_name: str) -> None:
    """The joint tree, read with an explicit stack (no recursion limit on deep hierarchies)."""
    _open_joint(cur, joints, root_name, -1, 0)
    stack = [0]
    nxt = len(joints[0].channels)
    while stack:
        idx = stack[-1]
        toks = cur.next_tokens()
        if toks[0] == "}":
            stack.pop()
        elif toks[0] == "JOINT" and len(toks) >= 2:
            j = _open_joint(cur, joints, " ".join(toks[1:]), idx, nxt)
            nxt += len(j.channels)
            stack.append(len(joints) - 1)
        elif toks[0] == "End":
            _parse_end_site(cur, joints[idx])
        else:
            raise cur.error(f"joint {joints[idx].name}: unexpected {' '.join(toks)!r}")


def parse_hierarchy(text: str, source: str = "<stream>") -> tuple[list[BvhJoint], _Cursor]:
    """Parse the HIERARCHY section; returns the joints and the cursor after it (its ``lineno``: the
    hierarchy's last line)."""
    cur = _Cursor(_numbered_lines(_text_pieces(text)), source)
    return _read_hierarchy(cur), cur


def _read_hierarchy(cur: _Cursor) -> list[BvhJoint]:
    # the first line with tokens; a decoding error of the text (not UTF-8) propagates as it is
    toks = next((t for _, line in cur if (t := line.split())), None)
    if toks is None:
        raise InputError(f"{cur.source}:1: empty file, not a BVH")
    if toks != ["HIERARCHY"]:
        raise cur.error("not a BVH file: first line must be HIERARCHY")
    toks = cur.next_tokens()
    if toks[0] != "ROOT" or len(toks) < 2:
        raise cur.error("expected 'ROOT name'")
    joints: list[BvhJoint] = []
    _parse_joints(cur, joints, " ".join(toks[1:]))
    names = [j.name for j in joints]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise cur.error(f"duplicate joint name(s): {', '.join(sorted(dup))}")
    return joints


MOTION_BLOCK_CHARS = 1 << 20  # the text is split into lines this much at a time
MOTION_BLOCK_ROWS = 4096  # rows converted to numbers at a time


def _text_pieces(text: str) -> Iterator[str]:
    """``text`` in pieces of about :data:`MOTION_BLOCK_CHARS`, each ending after a newline (the last
    at the end), so splitting each into lines splits the text as :meth:`str.splitlines` does."""
    start = 0
    while start < len(text):
        end = text.find("\n", start + MOTION_BLOCK_CHARS)
        end = len(text) if end < 0 else end + 1
        yield text[start:end]
        start = end


def _numbered_lines(pieces: Iterator[str]) -> Iterator[tuple[int, str]]:
    """(line number, line) of the text in ``pieces`` (see :func:`_text_pieces`), so a long take's
    text is never held twice."""
    lineno = 0
    for piece in pieces:
        for line in piece.splitlines():
            lineno += 1
            yield lineno, line


@dataclass
class BvhHeader:
    """A BVH's hierarchy and motion header: ``frame_time`` s, ``n_frames`` as the file says."""

    joints: list[BvhJoint]
    frame_time: float
    n_frames: int
    source: str

    @property
    def n_channels(self) -> int:
        return sum(len(j.channels) for j in self.joints)


def _read_header(cur: _Cursor) -> BvhHeader:
    """The hierarchy, then MOTION, ``Frames: N`` and ``Frame Time: s``; the cursor is left on the rows."""
    joints = _read_hierarchy(cur)
    if not any(j.channels for j in joints):  # rows of no values: nothing moves, and nothing to count them by
        raise cur.error("the hierarchy has no channels: no motion to read")
    if cur.next_tokens() != ["MOTION"]:
        raise cur.error("expected MOTION after the hierarchy")
    toks = cur.next_tokens()
    if toks[0] != "Frames:" or len(toks) != 2:
        raise cur.error("expected 'Frames: N'")
    try:
        n_frames = int(toks[1]) if len(toks[1]) <= 12 else -1
    except ValueError:
        raise cur.error(f"bad frame count {toks[1]!r}") from None
    if n_frames <= 0:
        raise cur.error(f"frame count {toks[1]}: zero frames or fewer, nothing to analyse")
    toks = cur.next_tokens()
    if toks[:2] != ["Frame", "Time:"] or len(toks) != 3:
        raise cur.error("expected 'Frame Time: seconds'")
    try:
        frame_time = float(toks[2])
    except ValueError:
        raise cur.error(f"Frame Time {toks[2]!r} is not a number") from None
    check_frame_period(frame_time, f"{cur.source}:{cur.lineno}: Frame Time")
    return BvhHeader(joints, frame_time, n_frames, cur.source)


def _convert_block(block: list[tuple[int, str]], first: int, n_ch: int, source: str) -> np.ndarray:
    """The rows (len(block), n_ch) of the (line number, line) ``block`` (frames ``first``…), or the
    first bad line's error."""
    try:
        data = np.loadtxt(io.StringIO("\n".join(ln for _, ln in block)), ndmin=2)
        if data.shape == (len(block), n_ch) and first_out_of_range(data, MAX_CHANNEL_VALUE) is None:
            return data
    except ValueError:
        pass
    out = np.empty((len(block), n_ch))
    for k, (lineno, line) in enumerate(block):  # find the offending line for the message
        toks = line.split()
        if len(toks) != n_ch:
            raise InputError(f"{source}:{lineno}: frame {first + k} has {len(toks)} values, hierarchy needs {n_ch}")
        try:
            vals = np.array([float(t) for t in toks], dtype=float)
        except ValueError:
            raise InputError(f"{source}:{lineno}: non-numeric value in frame {first + k}: {' '.join(toks)!r}") from None
        bad = first_out_of_range(vals, MAX_CHANNEL_VALUE)
        if bad is not None:
            raise InputError(f"{source}:{lineno}: value {toks[bad[0]]} in frame {first + k} is not finite or beyond "
                             f"±{MAX_CHANNEL_VALUE:g}")
        out[k] = vals
    return out


def _frame_blocks(cur: _Cursor, header: BvhHeader, convert: bool, rows: int) -> Iterator[np.ndarray]:
    """The frames (k, C) after the header, ``rows`` at a time; every row is checked (count, values)
    before the generator ends. With ``convert`` False the rows are only counted (nothing yielded)."""
    n_frames, n_ch, source = header.n_frames, header.n_channels, header.source
    count, block = 0, []
    for lineno, line in cur:
        if not line.strip():
            continue
        if count == n_frames:
            raise InputError(f"{source}:{lineno}: extra rows: header says Frames: {n_frames}, file has "
                             f"{n_frames + 1 + sum(1 for _, ln in cur if ln.strip())} rows")
        count += 1
        if convert:
            block.append((lineno, line))
            if len(block) == rows:
                yield _convert_block(block, count - len(block), n_ch, source)
                block = []
    if count < n_frames:
        raise InputError(f"{source}:{cur.lineno}: truncated: header says Frames: {n_frames}, file has {count} rows")
    if block:
        yield _convert_block(block, count - len(block), n_ch, source)


def _fits(header: BvhHeader, chars: int) -> bool:
    """Whether the header's frames can be in a text of ``chars`` characters: a row takes at least
    2 characters per value (more frames are only counted, for the message, never allocated)."""
    return header.n_frames <= chars // (2 * header.n_channels) + 1


def parse_bvh(text: str, source: str = "<memory>") -> BvhMotion:
    """Parse a whole BVH text. Raises :class:`InputError` naming file and line. Memory: the frames
    array and one block of rows beside the text (the rows are converted a block at a time)."""
    cur = _Cursor(_numbered_lines(_text_pieces(text)), source)
    header = _read_header(cur)
    convert = _fits(header, len(text))
    frames = np.empty((header.n_frames, header.n_channels)) if convert else None
    done = 0
    for block in _frame_blocks(cur, header, convert, MOTION_BLOCK_ROWS):
        frames[done:done + len(block)] = block
        done += len(block)
    return BvhMotion(header.joints, header.frame_time, frames, source)


def read_bvh(path: str | Path) -> BvhMotion:
    """Read a BVH file (see :func:`parse_bvh`)."""
    p = Path(path)
    return parse_bvh(read_input_text(p, "BVH file"), str(p))


def stream_bvh(path: str | Path, rows: int = MOTION_BLOCK_ROWS) -> tuple[BvhHeader, Iterator[np.ndarray]]:
    """A BVH file's header and its frames (k, C) ``rows`` at a time, read lazily: memory is one
    block, whatever the take's length. The rows are checked as :func:`read_bvh` checks them, with
    the same messages, as they come (a bad row ends the iteration with its error; the count of
    rows is checked at the end, so iterate to the end)."""
    p = check_input_file(path, "BVH file")
    cur = _Cursor(_numbered_lines(read_input_pieces(p, MOTION_BLOCK_CHARS)), str(p))
    header = _read_header(cur)
    return header, _frame_blocks(cur, header, _fits(header, p.stat().st_size), rows)


def _fmt(v: np.ndarray) -> str:
    return " ".join(repr(float(x)) for x in v)  # exact: a rebuilt hierarchy is the file's to the last digit


def format_hierarchy(joints: list[BvhJoint]) -> str:
    """The HIERARCHY section for ``joints`` (inverse of :func:`parse_hierarchy`)."""
    out = ["HIERARCHY"]

    def emit(i: int, depth: int) -> None:
        j = joints[i]
        pad = "\t" * depth
        out.append(f"{pad}{'ROOT' if j.parent < 0 else 'JOINT'} {j.name}")
        out.append(pad + "{")
        out.append(f"{pad}\tOFFSET {_fmt(j.offset)}")
        out.append(f"{pad}\tCHANNELS {len(j.channels)} {' '.join(j.channels)}")
        for c in j.children:
            emit(c, depth + 1)
        if j.end_site is not None:
            out.extend([f"{pad}\tEnd Site", pad + "\t{", f"{pad}\t\tOFFSET {_fmt(j.end_site)}", pad + "\t}"])
        out.append(pad + "}")

    emit(0, 0)
    return "\n".join(out) + "\n"


def write_bvh(motion: BvhMotion, path: str | Path) -> None:
    """Write ``motion`` with its hierarchy, frame count and frame time unchanged."""
    with open(path, "w", encoding="utf-8") as f:
        f.write(format_hierarchy(motion.joints))
        f.write(f"MOTION\nFrames: {len(motion.frames)}\nFrame Time: {motion.frame_time:.7g}\n")
        np.savetxt(f, motion.frames, fmt="%.6f")


# "cmu": the CMU Graphics Lab motion capture database's unit, kept by its BVH conversions: its ASF files declare
# `:units length 0.45`, lengths in 1/0.45 inch (0.0564 m; mocap.cs.cmu.edu, the Acclaim ASF/AMC format)
UNIT_SCALES = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "cmu": 0.0254 / 0.45}
HUMAN_STATURE_M = (0.4, 3.0)  # a skeleton's estimated stature in metres, for the unit that makes it a human's
CMU_INCH_SPLIT = 37.0  # file units of stature: 2.09 m in CMU units (taller than any subject), 0.94 m in inches


def detect_length_unit(stature: float, source: str = "") -> str:
    """Guess the file's length unit ('m', 'cm', 'mm', 'in', 'cmu') from a human's estimated stature in file units:
    the unit that makes it a human's (0.4-3 m in metres, 0.8-3 m in cm or mm). The ranges do not overlap: 20-37 CMU
    units are 1.13-2.09 m, 37-80 inches 0.94-2.03 m: a stature of 37-45 is a child in inches rather than a giant of
    2.1-2.5 m in CMU units (AnimatedDrawings' child-sized skeletons, 41 and 44 in). A child under 0.94 m measured in
    inches reads as CMU units: give --units; pass an explicit unit to override."""
    if HUMAN_STATURE_M[0] <= stature <= HUMAN_STATURE_M[1]:
        return "m"
    if 20.0 <= stature < CMU_INCH_SPLIT:
        return "cmu"
    if CMU_INCH_SPLIT <= stature < 80.0:
        return "in"
    if 80.0 <= stature <= 300.0:
        return "cm"
    if 300.0 < stature <= 3000.0:
        return "mm"
    raise InputError(f"{source}: cannot tell the length unit from an estimated stature of {stature:g}; give --units")
