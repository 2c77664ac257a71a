"""Checks at the edges: every file, option and number from outside passes through here.

One place decides what an input file may be (a regular file, UTF-8 text with or without
a byte-order mark, at most :data:`MAX_FILE_BYTES`), where an output may go (its
directory must exist, checked before any work starts), and which numbers are accepted
(finite, inside limits with a physical meaning). Each refusal is an :class:`InputError`
of one line naming the file, line, option or field.
"""

from __future__ import annotations

import codecs
import math
import os
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from livezmp.errors import InputError

MAX_FILE_BYTES = 1 << 30  # 1 GiB: larger than any take we read (an hour of 120 Hz BVH is ~0.4 GB)
UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")
UTF8_BOM = b"\xef\xbb\xbf"


def check_input_file(path: str | Path, what: str = "file") -> Path:
    """``path`` as a Path if it is a readable regular file (not a directory, FIFO or device)."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise InputError(f"{p}: no such file") from None
    except OSError as e:
        raise InputError(f"{p}: cannot read {what}: {e.strerror}") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{p}: is a directory, not a {what}")
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{p}: not a regular file (a FIFO, socket or device); give a {what}")
    if st.st_size > MAX_FILE_BYTES:
        raise InputError(f"{p}: {st.st_size} bytes, more than the {MAX_FILE_BYTES >> 20} MiB limit for a {what}")
    return p


def decode_text(data: bytes, source: str) -> str:
    """UTF-8 text (a leading byte-order mark, as Excel writes, is dropped); anything else
    is a one-line error naming the line of the first bad byte."""
    if data.startswith(UTF16_BOMS):
        raise InputError(f"{source}:1: UTF-16 text; save it as UTF-8")
    if data.startswith(UTF8_BOM):
        data = data[len(UTF8_BOM):]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise InputError(f"{source}:{line}: not UTF-8 text (byte 0x{data[e.start]:02x}); save it as UTF-8") from None


def read_input_text(path: str | Path, what: str = "file") -> str:
    """The text of an input file, after :func:`check_input_file` and :func:`decode_text`."""
    p = check_input_file(path, what)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise InputError(f"{p}: cannot read {what}: {e.strerror}") from None
    return decode_text(data, str(p))


def read_input_pieces(path: Path, block: int = 1 << 20, what: str = "file") -> Iterator[str]:
    """The text of the input file at ``path`` (already passed :func:`check_input_file`), read and
    decoded as :func:`decode_text` does, with the same messages, ``block`` bytes at a time: pieces
    each ending after a newline (the last at the end of the file), so splitting each into lines
    splits the text as a whole would be, and a long file's text is never held whole."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    lines = 0  # newlines before the current block, for the line of a bad byte
    rest = ""
    try:
        f = open(path, "rb")  # closed by the with below; an error worded first
    except OSError as e:
        raise InputError(f"{path}: cannot read {what}: {e.strerror}") from None
    with f:
        first = True
        while True:
            data = f.read(block)
            if first:
                if data.startswith(UTF16_BOMS):
                    raise InputError(f"{path}:1: UTF-16 text; save it as UTF-8")
                data = data[len(UTF8_BOM):] if data.startswith(UTF8_BOM) else data
                first = False
            try:
                text = rest + decoder.decode(data, final=not data)
            except UnicodeDecodeError as e:
                line = lines + e.object.count(b"\n", 0, e.start) + 1  # e.object: this block (and a split character)
                raise InputError(f"{path}:{line}: not UTF-8 text (byte 0x{e.object[e.start]:02x}); save it as UTF-8") \
                    from None
            lines += data.count(b"\n")
            cut = text.rfind("\n") + 1 if data else len(text)
            if cut:
                yield text[:cut]
            rest = text[cut:]
            if not data:
                return


def check_output_path(path: str | Path | None, option: str) -> None:
    """Refuse an output whose directory does not exist, which is a directory, or which exists and is not a
    regular file (before work starts): a result is written beside it and renamed over it (atomically), which
    would replace a device such as /dev/null, or a FIFO, with a plain file."""
    if path is None:
        return
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise InputError(f"{option} {p}: is a directory; give a file name")
    if p.exists() and not p.is_file():
        raise InputError(f"{option} {p}: not a regular file (a device, FIFO or socket); give a file name")
    if not parent.is_dir():
        raise InputError(f"{option} {p}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise InputError(f"{option} {p}: directory {parent} is not writable")


# The options through which a command reads files (its motion, trials, recording, walks, and the files beside them)
INPUT_OPTIONS = ("motion", "recording", "trials", "base_walk", "walk", "others", "features", "static", "subject",
                 "markers", "mapping", "robot", "robot_config", "urdf", "skeleton", "calibration", "manifest")


def given_inputs(args: object) -> list[str]:
    """The files a command's parsed arguments ``args`` name among :data:`INPUT_OPTIONS` (one or a list each)."""
    out = []
    for name in INPUT_OPTIONS:
        value = getattr(args, name, None)
        out += [str(v) for v in (value if isinstance(value, list) else [value]) if v is not None]
    return out


def check_output_paths(*outputs: tuple[str | Path | None, str], inputs: Iterable[str | Path] = ()) -> None:
    """Each ``(path, option)`` output checked by :func:`check_output_path`, and no two options naming one file
    (the same path, or one reached through a link): the one written last would replace the other, e.g. a run's
    summary written over its recording; nor an output that is one of the ``inputs`` (the same file, or a link to
    it): ``calibrate w.c3d -o w.c3d`` replaced the trial with its subject file, exit 0."""
    seen: dict[str, str] = {}
    existing = [i for i in inputs if os.path.isfile(i)]
    for path, option in outputs:
        check_output_path(path, option)
        if path is None:
            continue
        if os.path.exists(path):
            same = next((i for i in existing if os.path.samefile(path, i)), None)
            if same is not None:
                raise InputError(f"{option} {path}: the same file as the input {same}; write the output to a file "
                                 "of its own")
        key = os.path.realpath(path)
        if key in seen:
            raise InputError(f"{option} {path}: the same file as {seen[key]}; give each output a file of its own")
        seen[key] = option


def check_output_dir(path: str | Path, option: str) -> None:
    """Refuse an output directory that is a file, or lies under one, or whose nearest existing directory is
    not writable (before work starts; it is made when the work writes into it)."""
    p = Path(path).absolute()
    existing = next(a for a in (p, *p.parents) if a.exists())
    if not existing.is_dir():
        raise InputError(f"{option} {path}: {existing} is a file, not a directory")
    if not os.access(existing, os.W_OK):
        raise InputError(f"{option} {path}: directory {existing} is not writable")


def check_same_format(motion: str | Path, output: str | Path) -> None:
    """A motion written back in its own format (``correct``, ``gait synth``) needs an output named so: a BVH
    written under ``-o x.csv`` was read back as a CSV without a time column (exit 0 when written)."""
    suffix = Path(motion).suffix.lower()
    if Path(output).suffix.lower() != suffix:
        raise InputError(f"{output}: {motion} is written back in its own format; give -o ending in {suffix}")


# Figure formats Matplotlib writes with its own backends (the suffix chooses the format)
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff")


def check_figure_path(path: str | Path | None, option: str) -> None:
    """:func:`check_output_path`, and a file name whose suffix is a figure format."""
    check_output_path(path, option)
    if path is not None and Path(path).suffix.lower() not in FIGURE_SUFFIXES:
        raise InputError(f"{option} {path}: not a figure file name; end it in one of {', '.join(FIGURE_SUFFIXES)}")


def check_number(value: float | None, what: str, lo: float, hi: float, *, lo_open: bool = False) -> None:
    """``value`` finite and within [lo, hi] (or (lo, hi] with ``lo_open``); None passes."""
    if value is None:
        return
    ok = math.isfinite(value) and (value > lo if lo_open else value >= lo) and value <= hi
    if not ok:
        bracket = "(" if lo_open else "["
        raise InputError(f"{what}: {value:g} is outside {bracket}{lo:g}, {hi:g}]")


def first_out_of_range(values: np.ndarray, limit: float) -> tuple[int, ...] | None:
    """Index of the first value that is not finite or whose magnitude exceeds ``limit``, else None."""
    bad = ~(np.abs(values) <= limit)  # NaN compares False, so it is caught too
    if not bad.any():
        return None
    return tuple(int(i) for i in np.argwhere(bad)[0])


def non_finite_field(doc: object, path: str = "") -> str | None:
    """The first field of a JSON-able document holding NaN or ±inf (e.g. ``summary.max_margin``), else None."""
    if isinstance(doc, float):
        return None if math.isfinite(doc) else path or "value"
    if isinstance(doc, dict):
        items = ((f"{path}.{k}" if path else str(k), v) for k, v in doc.items())
    elif isinstance(doc, (list, tuple)):
        items = ((f"{path}[{i}]", v) for i, v in enumerate(doc))
    else:
        return None
    for p, v in items:
        found = non_finite_field(v, p)
        if found:
            return found
    return None


# Frame periods the estimator can follow: its 0.4 s spline window needs at least 3 samples
# (<= 0.1 s, 10 Hz) and at most a few thousand (>= 0.1 ms, 10 kHz; beyond any mocap or servo bus).
FRAME_PERIOD_RANGE = (1e-4, 0.1)  # s
# Largest magnitude of a channel value in file units (cm, mm, degrees, rad): 10 km in mm,
# thousands of turns; beyond it products in the dynamics overflow rather than mean anything.
MAX_CHANNEL_VALUE = 1e7
MAX_COORDINATE_M = 1000.0  # m from the capture origin (a marker, a force plate's corner): beyond any capture volume


def check_frame_period(dt: float, where: str) -> None:
    """A frame period (s) the estimator can follow, see :data:`FRAME_PERIOD_RANGE`."""
    lo, hi = FRAME_PERIOD_RANGE
    if not (math.isfinite(dt) and lo <= dt <= hi):
        raise InputError(f"{where}: frame period {dt:g} s is outside {lo:g} .. {hi:g} s "
                         f"({1 / hi:g} .. {1 / lo:g} frames per second)")
