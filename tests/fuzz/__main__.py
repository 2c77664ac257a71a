"""The longer fuzz run: ``python -m tests.fuzz --minutes N [--formats bvh,csv,...]``.

Each format runs in its own child process (so peak memory is per format, under an
address-space limit) for its share of the time, mutating the seed and the corpus at
random; a table per format follows: inputs tried, exit-0 clean, exit-2 one-line,
failures, peak RSS. Failing inputs, and one input per new kind of refusal, are saved in
``tests/fuzz/corpus/FORMAT/`` (the CI part replays them).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FORMATS = ("bvh", "csv", "urdf", "toml", "mcap", "udp", "c3d")  # c3d: mutations of the data set's CGM2.4 walk
CORPUS = Path(__file__).parent / "corpus"
MEMORY_LIMIT = 3 << 30  # bytes of address space per child: a blow-up fails instead of swapping
KEEP_PER_FORMAT = 40


def _kind(message: str) -> str:
    """A refusal's kind: its text without file names and numbers."""
    text = message.split(": ", 2)[-1]
    return re.sub(r"[\d.eE+-]+|'[^']*'|\"[^\"]*\"", "#", text)[:60]


def _save(fmt: str, data: bytes, tag: str) -> None:
    d = CORPUS / fmt
    d.mkdir(parents=True, exist_ok=True)
    if tag != "failure" and len(list(d.iterdir())) >= KEEP_PER_FORMAT:
        return
    name = f"{tag}-{hashlib.sha1(data).hexdigest()[:12]}.{'bin' if fmt == 'udp' else fmt}"
    (d / name).write_bytes(data)


def _child(fmt: str, seconds: float, seed: int) -> dict:
    from tests.data_paths import DATA
    from tests.fuzz.harness import PacketTarget, Tally, check_file, make_seeds, mutate, random_ops

    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    rnd = random.Random(seed)
    tally, kinds = Tally(), set()
    end = time.monotonic() + seconds
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if fmt == "udp":
            target = PacketTarget()
            while time.monotonic() < end:
                batch = []
                for _ in range(200):
                    p = target.seed(rnd.random() < 0.5)
                    batch.append(mutate(p, random_ops(rnd)) if rnd.random() < 0.7 else p)
                o = target.send(batch)
                tally.tried += len(batch) - 1
                tally.add(o)
                if o.kind == "failure":
                    for p in batch:
                        _save(fmt, p, "failure")
            target.close()
            st = target.src.stats
            tally.clean, tally.refused = st.delivered, st.dropped
        else:
            seeds = make_seeds(work / "seeds", DATA / "c3d" / "cgm24_walking01_forceplate.c3d")
            if fmt not in seeds.files:
                raise SystemExit(f"no seed for {fmt}: the data set is not at {DATA}")
            pool = [seeds.files[fmt]] + [p.read_bytes() for p in sorted((CORPUS / fmt).glob("*"))]
            while time.monotonic() < end:
                data = mutate(rnd.choice(pool), random_ops(rnd))
                o = check_file(fmt, data, seeds, work)
                tally.add(o)
                if o.kind == "failure":
                    _save(fmt, data, "failure")
                elif o.kind == "refused" and _kind(o.detail) not in kinds:
                    kinds.add(_kind(o.detail))
                    _save(fmt, data, "refused")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"format": fmt, "tried": tally.tried, "clean": tally.clean, "refused": tally.refused,
            "failures": len(tally.failures), "examples": tally.failures[:5], "peak_rss_mb": round(rss)}


def main() -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=5.0, help="total time, shared by the formats")
    ap.add_argument("--formats", default=",".join(FORMATS))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    formats = args.formats.split(",")
    if args.child:
        print(json.dumps(_child(args.child, args.minutes * 60, args.seed)))
        return 0
    share = args.minutes / len(formats)
    rows = []
    for fmt in formats:
        r = subprocess.run([sys.executable, "-m", "tests.fuzz", "--child", fmt, "--minutes", str(share),
                            "--seed", str(args.seed)], capture_output=True, text=True,
                           cwd=Path(__file__).parents[2])
        try:
            rows.append(json.loads(r.stdout.strip().splitlines()[-1]))
        except (IndexError, ValueError):
            rows.append({"format": fmt, "tried": 0, "clean": 0, "refused": 0, "failures": 1,
                         "examples": [r.stderr[-500:]], "peak_rss_mb": 0})
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}; {args.minutes:g} min in total")
    print(f"{'format':8} {'inputs':>9} {'exit-0 clean':>13} {'exit-2 one-line':>16} {'failures':>9} "
          f"{'peak RSS MB':>12}")
    for r in rows:
        label = "udp pkts" if r["format"] == "udp" else r["format"]
        print(f"{label:8} {r['tried']:>9} {r['clean']:>13} {r['refused']:>16} {r['failures']:>9} "
              f"{r['peak_rss_mb']:>12}")
    for r in rows:
        for e in r["examples"]:
            print(f"{r['format']}: {e}")
    return 1 if any(r["failures"] for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
