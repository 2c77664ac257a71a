"""The longer fuzz run: ``python -m tests.fuzz [--inputs 10000] [--packets 100000] [--minutes 40]
[--jobs 2] [--shards 1] [--formats bvh,csv,...]``.

Each format runs in its own child processes (so peak memory is per format, under an
address-space limit): ``--shards`` children per format, each with its own random seed and
its share of the count (their tallies are summed), ``--jobs`` children at a time, until it
has tried its count (``--inputs`` per
file format, ``--packets`` UDP packets) or the run's ``--minutes`` are up, mutating the
seed and the corpus at random; the commands run in the child (the CLI's ``main`` with
argv; the CI part also runs a sample as real processes). Two tables follow: per format
inputs tried, exit-0 clean, exit-2 one-line, failures, peak RSS and rate; then the peak
RSS of a fresh ``livezmp`` process on the seed, on the largest accepted and on the
largest refused input of the run. Failing inputs, and one input per new kind of refusal,
are saved in ``tests/fuzz/corpus/FORMAT/`` (the CI part replays them); C3D inputs, made
from the data set's take, are saved as the mutations to apply (``.ops.json``), never as data.
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
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

FORMATS = ("c3d", "udp", "mcap", "csv", "toml", "urdf", "bvh")  # slowest first, so the quick ones fill in
CORPUS = Path(__file__).parent / "corpus"
MEMORY_LIMIT = 3 << 30  # bytes of address space per child: a blow-up fails instead of swapping
KEEP_PER_FORMAT = 40
RECIPES = ("c3d",)  # formats whose seed is third-party data: the corpus keeps the mutations only
ROOT = Path(__file__).parents[2]


def _kind(message: str) -> str:
    """A refusal's kind: its text without file names and numbers."""
    text = message.split(": ", 2)[-1]
    return re.sub(r"[\d.eE+-]+|'[^']*'|\"[^\"]*\"", "#", text)[:60]


def _save(fmt: str, data: bytes, tag: str, ops: list) -> None:
    d = CORPUS / fmt
    d.mkdir(parents=True, exist_ok=True)
    if tag != "failure" and len(list(d.iterdir())) >= KEEP_PER_FORMAT:
        return
    name = f"{tag}-{hashlib.sha1(data).hexdigest()[:12]}"
    if fmt in RECIPES:
        (d / f"{name}.ops.json").write_text(json.dumps(ops) + "\n")
    else:
        (d / f"{name}.{'bin' if fmt == 'udp' else fmt}").write_bytes(data)


_MEASURED = """import sys
from livezmp.cli import main
try:
    code = main(sys.argv[2:])
finally:  # VmHWM: the peak RSS of this program (ru_maxrss would include the forking parent's)
    open(sys.argv[1], "w").write(next(s for s in open("/proc/self/status") if s.startswith("VmHWM")))
sys.exit(code)
"""


def _peak_rss(argv: list, work: Path) -> tuple[float, int, int]:
    """Peak RSS (MB) of a fresh ``livezmp argv`` process, its exit code and its number of stderr lines."""
    hwm = work / "vmhwm"
    r = subprocess.run([sys.executable, "-c", _MEASURED, hwm, *map(str, argv)], stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE, text=True, cwd=ROOT)
    return int(hwm.read_text().split()[1]) / 1024, r.returncode, len(r.stderr.splitlines())


def _rss_rows(fmt: str, inputs: dict[str, bytes], seeds, work: Path) -> dict:
    from tests.fuzz.harness import commands

    rows = {}
    for label, data in inputs.items():
        path = work / f"rss.{fmt}"
        path.write_bytes(data)
        argv = commands(fmt, path, seeds, work)[0][0]
        mb, rc, lines = _peak_rss(argv, work)
        rows[label] = {"bytes": len(data), "rss_mb": round(mb), "exit": rc, "stderr_lines": lines}
    return rows


def _child(fmt: str, count: int, deadline: float, seed: int) -> dict:
    from tests.data_paths import DATA
    from tests.fuzz.harness import PacketTarget, Tally, check_file, make_seeds, mutate, random_ops

    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    rnd = random.Random(seed)
    tally, kinds = Tally(), set()
    largest: dict[str, bytes] = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if fmt == "udp":
            target = PacketTarget()
            start = time.monotonic()
            while time.time() < deadline and tally.tried < count:
                batch = []
                for _ in range(200):
                    p = target.seed(rnd.random() < 0.5)
                    batch.append(mutate(p, random_ops(rnd)) if rnd.random() < 0.7 else p)
                o = target.send(batch)
                tally.tried += len(batch) - 1
                tally.add(o)
                if o.kind == "failure":
                    for p in batch:
                        _save(fmt, p, "failure", [])
            seconds = time.monotonic() - start
            target.close()
            st = target.src.stats
            tally.clean, tally.refused = st.delivered, st.dropped
            rss = {}
        else:
            seeds = make_seeds(work / "seeds", DATA / "c3d" / "cgm24_walking01_forceplate.c3d")
            if fmt not in seeds.files:
                raise SystemExit(f"no seed for {fmt}: the data set is not at {DATA}")
            pool = [seeds.files[fmt]]
            if fmt not in RECIPES:
                pool += [p.read_bytes() for p in sorted((CORPUS / fmt).glob("*"))]
            start = time.monotonic()
            while time.time() < deadline and tally.tried < count:
                ops = random_ops(rnd)
                data = mutate(rnd.choice(pool), ops)
                o = check_file(fmt, data, seeds, work)
                tally.add(o)
                if o.kind == "failure":
                    _save(fmt, data, "failure", ops)
                    continue
                if len(data) > len(largest.get(o.kind, b"")):
                    largest[o.kind] = data
                if o.kind == "refused" and _kind(o.detail) not in kinds:
                    kinds.add(_kind(o.detail))
                    _save(fmt, data, "refused", ops)
            seconds = time.monotonic() - start
            rss = _rss_rows(fmt, {"seed": seeds.files[fmt], **largest}, seeds, work)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"format": fmt, "tried": tally.tried, "clean": tally.clean, "refused": tally.refused,
            "failures": len(tally.failures), "examples": tally.failures[:5], "peak_rss_mb": round(peak),
            "seconds": round(seconds, 1), "rss": rss}


def _run_child(fmt: str, shard: int, args, deadline: float) -> dict:
    count = -(-(args.packets if fmt == "udp" else args.inputs) // args.shards)
    seed = args.seed + 1000 * shard  # shards mutate differently, so their inputs add up
    r = subprocess.run([sys.executable, "-m", "tests.fuzz", "--child", fmt, "--count", str(count),
                        "--deadline", str(deadline), "--seed", str(seed)], capture_output=True, text=True,
                       cwd=ROOT)
    try:
        return json.loads(r.stdout.strip().splitlines()[-1])
    except (IndexError, ValueError):
        return {"format": fmt, "tried": 0, "clean": 0, "refused": 0, "failures": 1,
                "examples": [f"child exit {r.returncode} (a negative exit: killed by that signal): {r.stderr[-500:]}"],
                "peak_rss_mb": 0, "seconds": 0, "rss": {}}


def _merge(shards: list[dict]) -> dict:
    """One format's row from its shards' rows: counts summed, peaks and wall time the largest, the RSS
    table of the first shard that has one."""
    row = dict(shards[0])
    for key in ("tried", "clean", "refused", "failures"):
        row[key] = sum(s[key] for s in shards)
    row["examples"] = [e for s in shards for e in s["examples"]][:5]
    row["peak_rss_mb"] = max(s["peak_rss_mb"] for s in shards)
    row["seconds"] = max(s["seconds"] for s in shards)
    row["rss"] = next((s["rss"] for s in shards if s["rss"]), {})
    return row


def _print(rows: list[dict], args, wall: float, load_before: tuple) -> None:
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"load average {' '.join(f'{x:.2f}' for x in load_before)} at the start, {load} at the end; "
          f"{wall / 60:.1f} min wall, {args.jobs} children at a time, {args.shards} per format")
    print(f"{'format':9} {'inputs':>8} {'exit-0 clean':>13} {'exit-2 one-line':>16} {'failures':>9} "
          f"{'peak RSS MB':>12} {'inputs/s':>9}  (inputs/s: wall time of the mutation loop, on a shared machine)")
    for r in rows:
        label = "udp pkts" if r["format"] == "udp" else r["format"]
        rate = r["tried"] / r["seconds"] if r["seconds"] else 0.0
        print(f"{label:9} {r['tried']:>8} {r['clean']:>13} {r['refused']:>16} {r['failures']:>9} "
              f"{r['peak_rss_mb']:>12} {rate:>9.1f}")
    print("\nPeak RSS of a fresh livezmp process (MB; bytes of the input; exit code, stderr lines):")
    print(f"{'format':9} {'seed (valid)':>24} {'largest accepted':>26} {'largest refused':>26}")
    for r in rows:
        if not r["rss"]:
            continue
        cells = []
        for label in ("seed", "clean", "refused"):
            c = r["rss"].get(label)
            cells.append(f"{c['rss_mb']} MB; {c['bytes']} B; {c['exit']},{c['stderr_lines']}" if c else "-")
        print(f"{r['format']:9} {cells[0]:>24} {cells[1]:>26} {cells[2]:>26}")
    for r in rows:
        for e in r["examples"]:
            print(f"{r['format']}: {e}")


def main() -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__.splitlines()[0])
    ap.add_argument("--inputs", type=int, default=10_000, help="inputs per file format")
    ap.add_argument("--packets", type=int, default=100_000, help="UDP packets")
    ap.add_argument("--minutes", type=float, default=40.0, help="wall time cap of the whole run")
    ap.add_argument("--jobs", type=int, default=2, help="children run at a time")
    ap.add_argument("--shards", type=int, default=1, help="children per format, each with its own seed")
    ap.add_argument("--formats", default=",".join(FORMATS))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--count", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--deadline", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(_child(args.child, args.count, args.deadline, args.seed)))
        return 0
    start, load = time.time(), os.getloadavg()
    deadline = start + 60 * args.minutes - 60  # a minute kept for the RSS table
    formats = args.formats.split(",")
    with ThreadPoolExecutor(args.jobs) as pool:
        runs = list(pool.map(lambda fs: _run_child(*fs, args, deadline),
                             [(f, k) for f in formats for k in range(args.shards)]))
    rows = [_merge(runs[i * args.shards:(i + 1) * args.shards]) for i in range(len(formats))]
    _print(rows, args, time.time() - start, load)
    return 1 if any(r["failures"] for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
