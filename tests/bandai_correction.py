"""Correct a Bandai walk and re-analyse the result: shared by the suite's test on the hardest walks
(tests/test_correction_bandai.py) and the benchmark over all 24 (benchmarks/bench_correction.py --every-walk)."""

from __future__ import annotations

import contextlib
import io
import json
import tempfile
from pathlib import Path


def correct_and_reanalyse(path: str) -> dict:
    """`livezmp correct` on ``path``, then `livezmp analyze` of its output at the correction's estimator cutoff
    (from its report): {"report": the correction's report, "after": the re-analysis' summary}."""
    from livezmp.cli import main

    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):  # the table says it
        out, rep, summ = (str(Path(tmp) / n) for n in ("c.bvh", "r.json", "s.json"))
        assert main(["correct", path, "-o", out, "--report", rep]) == 0
        report = json.loads(Path(rep).read_text())
        assert main(["analyze", out, "--cutoff-hz", str(report["estimator"]["cutoff_hz"]), "--summary-json", summ]) == 0
        return {"report": report, "after": json.loads(Path(summ).read_text())}


def table(results: dict[str, dict]) -> str:
    """One line a walk: frames outside before and after, inside fraction after, largest root rotation (°),
    loaded feet's largest move (mm), the solver's time a frame (ms)."""
    lines = [f"{'walk':24s} {'outside before':>15s} {'after':>6s} {'inside after':>13s} {'max rot °':>10s} "
             f"{'feet mm':>8s} {'ms/frame':>9s}"]
    for f, r in results.items():
        rep, after = r["report"], r["after"]
        lines.append(f"{Path(f).name:24s} {rep['out_of_support_before']:>15d} {after['out_of_support_frames']:>6d} "
                     f"{after['inside_fraction']:>13.4f} {rep['max_root_rotation_deg']:>10.2f} "
                     f"{rep['max_foot_displacement_mm']:>8.3f} {rep['solver_ms_per_frame']:>9.0f}")
    return "\n".join(lines)
