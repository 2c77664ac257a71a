"""What a BVH skeleton's massless joints cost and what dropping them leaves: for each file, its channels and the
model's (the joints carrying or leading to a segment's mass, ``livezmp.model.bvh_body.model_part``), the process CPU
time of loading it (parse, body, calibration) and of ``Pipeline.step`` per frame, as the live loop steps it (the take
replayed until ``--frames`` frames have been stepped; the median of per-frame CPU times over 100-frame runs).

    python benchmarks/bench_bvh_part.py /work/extra_bvh/heldout/rgbd_02_03.bvh ...
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from machine_load import load_averages

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.model.motion_file import load_motion


def measure(path: str, frames: int) -> tuple[int, int, float, float]:
    """(file channels, model channels, load CPU s, step CPU ms per frame) of the BVH at ``path``."""
    t0 = time.process_time()
    loaded = load_motion(path)
    load_s = time.process_time() - t0
    pipe = Pipeline(loaded.body, default_config(loaded.body, loaded.fps), nominal_dt=1.0 / loaded.fps)
    n, dt = len(loaded.frames), 1.0 / loaded.fps
    runs, k = [], 0
    while k < frames:
        c0 = time.process_time()
        for i in range(k, k + 100):
            pipe.step(i * dt, loaded.frames[i % n])
        runs.append((time.process_time() - c0) / 100)
        k += 100
    return loaded.bvh.n_channels, loaded.body.nq, load_s, 1e3 * float(np.median(runs))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--frames", type=int, default=2000, help="frames stepped per file")
    args = ap.parse_args()
    print(f"{'file':<28}{'channels':>9}{'model':>7}{'load CPU s':>12}{'step CPU ms':>13}")
    for f in args.files:
        ch, nq, load_s, step_ms = measure(f, args.frames)
        print(f"{Path(f).stem:<28}{ch:>9}{nq:>7}{load_s:>12.2f}{step_ms:>13.3f}")
    print(f"load average: {load_averages()}")


if __name__ == "__main__":
    main()
