"""Every Bandai walk, balance-corrected and re-analysed with `livezmp analyze` at the correction's
estimator cutoff (from its report): at least 99 % of support frames inside, and the feet that bear
weight (ankle and toe joints) move at most 1 mm. The walks run two at a time (this machine has two cores)."""

from __future__ import annotations

import json
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from data_paths import BANDAI


def correct_and_reanalyse(path: str) -> dict:
    from livezmp.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        out, rep, summ = (str(Path(tmp) / n) for n in ("c.bvh", "r.json", "s.json"))
        assert main(["correct", path, "-o", out, "--report", rep]) == 0
        report = json.loads(Path(rep).read_text())
        # re-analysed with the estimator settings the correction judged the motion with (its report's)
        assert main(["analyze", out, "--cutoff-hz", str(report["estimator"]["cutoff_hz"]), "--summary-json", summ]) == 0
        return {"report": report, "after": json.loads(Path(summ).read_text())}


def test_every_bandai_walk_is_corrected(capsys):
    files = sorted(str(p) for p in BANDAI.glob("*.bvh"))
    assert len(files) == 24
    with ProcessPoolExecutor(max_workers=2) as pool:
        results = dict(zip(files, pool.map(correct_and_reanalyse, files), strict=True))
    lines = [f"{'walk':24s} {'outside before':>15s} {'after':>6s} {'inside after':>13s} {'max rot °':>10s} "
             f"{'feet mm':>8s} {'ms/frame':>9s}"]
    for f, r in results.items():
        rep, after = r["report"], r["after"]
        lines.append(f"{Path(f).name:24s} {rep['out_of_support_before']:>15d} {after['out_of_support_frames']:>6d} "
                     f"{after['inside_fraction']:>13.4f} {rep['max_root_rotation_deg']:>10.2f} "
                     f"{rep['max_foot_displacement_mm']:>8.3f} {rep['solver_ms_per_frame']:>9.0f}")
    with capsys.disabled():
        print("\n" + "\n".join(lines))
    for f, r in results.items():
        assert r["after"]["inside_fraction"] >= 0.99, f
        assert r["report"]["max_foot_displacement_mm"] <= 1.0, f
