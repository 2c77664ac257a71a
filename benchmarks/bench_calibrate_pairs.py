"""`livezmp calibrate` judged on trials the fit never saw: subjects with a straight walk and a turn.

For each subject with a straight walk and one or more turns (told by the SOURCES.txt
beside the files: a line naming the file and ``/Straight/`` or ``/Turn/``, as biomechZoo's sample study lays them
out): calibrated on the straight walk and each turn analysed with that subject (`analyze --subject`), and the
reverse; the table (`analyze`'s default) beside; each trial's own held-out figure (calibrate's block folds).

    python benchmarks/bench_calibrate_pairs.py /work/extra_c3d/heldout3 /work/extra_c3d/heldout7

With ``--by-name FILES...`` the subjects are told by the file names instead (the name without its trailing trial
number: ``S4-AMGait03`` ... ``S4-AMGait07`` one subject, ``FAILT01_Walk01`` ... ``Walk03`` another), and each trial of
a subject with two or more is analysed with the table and with the subject calibrated on all its other trials
(`calibrate OTHERS...`, then `analyze --subject`), as a subject file is used on a new take:

    python benchmarks/bench_calibrate_pairs.py --by-name /work/extra_c3d/heldout2/tsalemink_*

Figures: ZMP − CoP over each trial's complete frames, RMS mm (bias fore-aft / lateral mm, lag ms; n.d. not
determined); deterministic, so the machine's load changes only the time taken.
"""

from __future__ import annotations

import argparse
import re
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from machine_load import load_averages

from livezmp.errors import InputError
from livezmp.model.c3d import read_c3d
from livezmp.offline.calibrate import Subject, calibrate
from livezmp.offline.gaitlab import LabOptions, analyse_lab_take


def walks(dirs: list[Path]) -> dict[str, dict[str, list[Path]]]:
    """subject -> {"straight": [...], "turn": [...]} from the SOURCES.txt in ``dirs`` (the subject: the folder
    the source's path names before ``Straight/`` or ``Turn/``)."""
    out: dict[str, dict[str, list[Path]]] = {}
    for d in dirs:
        for line in (d / "SOURCES.txt").read_text(encoding="utf-8").splitlines():
            m = re.match(r"\s*(\S+\.c3d)\s.*?([^/\s]+)/(Straight|Turn)/", line)
            if m and (d / m[1]).is_file():
                out.setdefault(m[2], {"straight": [], "turn": []})[m[3].lower()].append(d / m[1])
    return out


def name_groups(paths: list[Path]) -> dict[str, list[Path]]:
    """subject -> its trials (two or more), the subject told by the file name without its trailing trial number."""
    out: dict[str, list[Path]] = defaultdict(list)
    for p in paths:
        out[re.sub(r"[_-]?\d+$", "", p.stem)].append(p)
    return {name: sorted(group) for name, group in out.items() if len(group) > 1}


def leave_one_out(name: str, paths: list[Path]) -> list[tuple[float, float]]:
    """Each of a subject's trials analysed with the table and with the subject calibrated on its other trials; prints
    a row per trial (with the others' calibration: table kept or the weight, the least RMS any parameters reach on
    them, the fitted HAT); returns (table, calibrated) RMS mm per trial calibrated."""
    trials = {p: read_c3d(p) for p in paths}
    out = []
    for p in paths:
        table = scored(p)
        try:
            subject, rep = calibrate([trials[q] for q in paths if q != p])
        except InputError as e:
            print(f"{name[:24]:24s} {p.stem[-12:]:12s} {cell(table)} -> refused: {str(e).split(': ', 1)[-1][:60]}")
            continue
        cal = scored(p, subject)
        out.append((table["rms_mm"], cal["rms_mm"]))
        chosen = "table kept" if rep["table_kept"] else f"weight {rep['prior_weight']:g}"
        print(f"{name[:24]:24s} {p.stem[-12:]:12s} {cell(table)} -> {cell(cal)}   {chosen:10s} "
              f"{rep['rms_fitted_unconstrained_mm']:5.1f}   {100 * subject.fraction:.1f} %, "
              "{:+.0f} / {:+.0f} / {:.0f} mm, ".format(*(1000 * np.array(subject.offset)))
              + "{:.2f} / {:.2f}".format(*subject.hat_sway_gain))
    return out


def by_name(paths: list[Path]) -> None:
    """The ``--by-name`` table: every subject's trials, each with the others' calibration (see the docstring)."""
    print(f"{'subject':24s} {'trial':12s} {'table':22s} -> {'calibrated on the others':22s}   {'chosen':10s} "
          "floor   fraction, CoM fwd / left / up, sway fore-aft / lateral (the others' fit)")
    rows = [r for name, group in sorted(name_groups(paths).items()) for r in leave_one_out(name, group)]
    a = np.array(rows)
    print(f"median over {len(a)} trials: table {np.median(a[:, 0]):.1f} mm -> calibrated on the others "
          f"{np.median(a[:, 1]):.1f} mm; better {int(np.sum(a[:, 1] < a[:, 0] - 0.05))}, worse "
          f"{int(np.sum(a[:, 1] > a[:, 0] + 0.05))}; within 25 mm {int(np.sum(a[:, 0] <= 25))} -> "
          f"{int(np.sum(a[:, 1] <= 25))}")


def scored(path: Path, subject: Subject | None = None) -> dict:
    """`analyze` (with ``subject``): RMS, bias and lag against the plates."""
    lab = analyse_lab_take(read_c3d(path), LabOptions(markers=subject.marker_options()) if subject else None)
    return lab.summary["cop_vs_zmp"]


def cell(cv: dict) -> str:
    lag = "n.d." if cv["lag_ms"] is None else f"{cv['lag_ms']:+.0f}"
    return f"{cv['rms_mm']:5.1f} ({cv['bias_mm'][0]:+3.0f} / {cv['bias_mm'][1]:+3.0f}, {lag:>4s})"


def calibrated(path: Path) -> tuple[Subject | None, str]:
    """The subject calibrated on ``path`` and its own held-out figure (or why it is refused)."""
    try:
        subject, rep = calibrate([read_c3d(path)])
    except InputError as e:
        return None, "refused: " + str(e).split(": ", 1)[-1][:40]
    kept = " (table kept)" if rep["table_kept"] else f" (weight {rep['prior_weight']:g})"
    return subject, f"{rep['rms_held_out_table_mm']:.1f} -> {rep['rms_held_out_fitted_mm']:.1f}{kept}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dirs", nargs="+", type=Path, help="directories holding the trials and their SOURCES.txt "
                    "(with --by-name: the trials' files)")
    ap.add_argument("--by-name", action="store_true", help="subjects told by the file names (see the docstring)")
    args = ap.parse_args()
    t0 = time.process_time()
    print(f"load average {load_averages(' ')}")
    if args.by_name:
        by_name(args.dirs)
        print(f"({time.process_time() - t0:.1f} s of CPU)")
        return
    print(f"{'subject':8s} {'straight -> turn':22s} {'turn: table -> calibrated on the straight walk':52s} "
          f"{'straight: table -> calibrated on the turn':52s} own held out: straight; turn")
    forward, reverse = [], []
    for name, w in sorted(walks(args.dirs).items()):
        for straight in w["straight"][:1]:
            s_subject, s_own = calibrated(straight)
            s_table = scored(straight)
            for turn in w["turn"]:
                t_subject, t_own = calibrated(turn)
                t_table = scored(turn)
                fwd = scored(turn, s_subject) if s_subject else None
                rev = scored(straight, t_subject) if t_subject else None
                if fwd:
                    forward.append((t_table["rms_mm"], fwd["rms_mm"]))
                if rev:
                    reverse.append((s_table["rms_mm"], rev["rms_mm"]))
                pair = f"{straight.stem.removeprefix('zoo_')} -> {turn.stem.removeprefix('zoo_')}"
                print(f"{name:8s} {pair:22s} {cell(t_table)} -> "
                      f"{cell(fwd) if fwd else 'not calibrated':22s}   {cell(s_table)} -> "
                      f"{cell(rev) if rev else 'not calibrated':22s}   {s_own}; {t_own}")
    for what, pairs in (("turn, calibrated on the straight walk", forward),
                        ("straight walk, calibrated on the turn", reverse), ("both", forward + reverse)):
        a = np.array(pairs)
        print(f"median {what}: table {np.median(a[:, 0]):.1f} mm -> calibrated {np.median(a[:, 1]):.1f} mm over "
              f"{len(a)} pairs; better {int(np.sum(a[:, 1] < a[:, 0] - 0.05))}, worse "
              f"{int(np.sum(a[:, 1] > a[:, 0] + 0.05))}; within 25 mm {int(np.sum(a[:, 0] <= 25))} -> "
              f"{int(np.sum(a[:, 1] <= 25))}")
    print(f"({time.process_time() - t0:.1f} s of CPU)")


if __name__ == "__main__":
    main()
