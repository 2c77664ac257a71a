"""The Bandai walks that leave their support most, balance-corrected and re-analysed with `livezmp analyze` at the
correction's estimator cutoff (from its report): at least 99 % of support frames inside, and the feet that bear
weight (ankle and toe joints) move at most 1 mm. All 24 walks take minutes: `python benchmarks/bench_correction.py
--every-walk` prints the same table for every walk; the suite corrects the HARDEST walks, chosen by analysing all 24
at the correction's cutoff (the frames outside before are what the correction has to move). They run two at a
time (this machine has two cores)."""

from __future__ import annotations

import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from bandai_correction import correct_and_reanalyse, table
from data_paths import BANDAI

from livezmp.cli import main
from livezmp.correct.limits import CORRECTION_CUTOFF_HZ

HARDEST = 6  # walks corrected in the suite


def frames_outside(path: Path, tmp: Path) -> int:
    summary = tmp / f"{path.stem}.json"
    assert main(["analyze", str(path), "--cutoff-hz", str(CORRECTION_CUTOFF_HZ), "--summary-json", str(summary)]) == 0
    return json.loads(summary.read_text())["out_of_support_frames"]


def test_the_hardest_bandai_walks_are_corrected(tmp_path, capsys):
    walks = sorted(BANDAI.glob("*.bvh"))
    assert len(walks) == 24
    with ProcessPoolExecutor(max_workers=2) as pool:  # the choice's 24 analyses two at a time too
        outside = dict(zip(walks, pool.map(frames_outside, walks, [tmp_path] * len(walks)), strict=True))
        files = [str(p) for p in sorted(walks, key=lambda p: -outside[p])[:HARDEST]]
        results = dict(zip(files, pool.map(correct_and_reanalyse, files), strict=True))
    with capsys.disabled():
        print("\n" + table(results))
    for f, r in results.items():
        assert r["report"]["out_of_support_before"] > 0, f  # the chosen walks had something to correct
        assert r["after"]["inside_fraction"] >= 0.99, f
        assert r["report"]["max_foot_displacement_mm"] <= 1.0, f
