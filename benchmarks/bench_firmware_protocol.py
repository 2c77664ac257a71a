"""Throughput of the firmware_protocol codecs for a 20-joint JOINT_STATE: Python and the C reference side by side.

    python benchmarks/bench_firmware_protocol.py [--frames N]

Python figures are the best of 5 runs of N frames; the C figures come from
fwp_tool's bench mode, compiled here with cc -O2 (at least 0.3 s each). Both
count process CPU time (time.process_time / clock()), so other load on the
machine does not skew the comparison. "x need" is the multiple of 50 x the
frames of a 1 kHz control loop (the requirement: at least 1.0).
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import firmware_protocol as fp
from firmware_protocol.can_framing import CanDecoder, encode_can
from firmware_protocol.vectors import f32

REQUIRED_FPS = 50 * 1000


def joint_state(n: int = 20) -> fp.JointState:
    rng = random.Random(0)
    def column(lo: float, hi: float) -> tuple[float, ...]:
        return tuple(f32(rng.uniform(lo, hi)) for _ in range(n))

    return fp.JointState(123456, tuple(range(1, n + 1)), column(-3, 3), column(-8, 8), column(0, 2), (0,) * n)


def best_rate(fn, frames: int, repeats: int = 5) -> float:
    """Frames per second of the fastest of ``repeats`` runs of fn()."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return frames / best


def python_rows(msg: fp.JointState, n: int) -> list[tuple[str, str, float]]:
    frames = [fp.encode(msg, i & 0xFFFF, True) for i in range(n)]
    stream = b"".join(frames)
    chunks = [stream[i : i + 4096] for i in range(0, len(stream), 4096)]

    def decode_chunks():
        dec = fp.StreamDecoder("board")
        got = sum(len(dec.feed(c)) for c in chunks)
        assert got == n, got

    def decode_frames():
        dec = fp.StreamDecoder("board")
        got = sum(len(dec.feed(f)) for f in frames)
        assert got == n, got

    can_frames = [[(f.can_id, f.data) for f in encode_can(msg, 1, i % 32, True)] for i in range(n)]

    def can_decode():
        dec = CanDecoder("node")
        got = sum(len(dec.feed(i, d)) for t in can_frames for i, d in t)
        assert got == n, got

    return [
        ("Python", "serial encode", best_rate(lambda: [fp.encode(msg, i & 0xFFFF, True) for i in range(n)], n)),
        ("Python", "serial decode, 4 KiB reads", best_rate(decode_chunks, n)),
        ("Python", "serial decode, one frame per read", best_rate(decode_frames, n)),
        ("Python", "CAN encode (39 frames each)", best_rate(lambda: [encode_can(msg, 1, i % 32, True)
                                                                      for i in range(n)], n)),
        ("Python", "CAN decode (39 frames each)", best_rate(can_decode, n)),
    ]


def c_rows(msg: fp.JointState, n: int) -> list[tuple[str, str, float]]:
    cc = shutil.which("cc")
    if cc is None:
        return [("C", "not measured: no C compiler (cc)", float("nan"))]
    src = Path(fp.__file__).parent / "c"
    with tempfile.TemporaryDirectory() as tmp:
        tool = Path(tmp) / "fwp_tool"
        subprocess.run([cc, "-std=c99", "-O2", *(str(src / f) for f in ("fwp.c", "fwp_can.c", "fwp_tool.c")),
                        "-o", str(tool)], check=True)
        out = subprocess.run([str(tool), "bench", str(min(n, 65536))], input=fp.encode(msg, 0, True).hex(),
                             capture_output=True, text=True, check=True, timeout=60).stdout
    result = json.loads(out)
    return [("C reference", "serial encode", result["encode_fps"]),
            ("C reference", "serial decode", result["decode_fps"])]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=20000, help="frames per run (default 20000)")
    args = parser.parse_args()
    msg = joint_state()
    size = len(fp.encode(msg, 0, True))
    rows = c_rows(msg, args.frames) + python_rows(msg, args.frames)
    print(f"20-joint JOINT_STATE: {len(fp.encode_payload(msg))} B payload, {size} B serial frame, "
          f"{len(encode_can(msg, 1, 0, True))} CAN frames; need {REQUIRED_FPS:,} frames/s (50 x 1 kHz)\n")
    print(f"| {'implementation':<14} | {'operation':<34} | {'frames/s':>11} | {'us/frame':>8} | {'x need':>6} |")
    print(f"|{'-' * 16}|{'-' * 36}|{'-' * 13}|{'-' * 10}|{'-' * 8}|")
    for impl, op, fps in rows:
        print(f"| {impl:<14} | {op:<34} | {fps:>11,.0f} | {1e6 / fps:>8.2f} | {fps / REQUIRED_FPS:>6.1f} |")


if __name__ == "__main__":
    main()
