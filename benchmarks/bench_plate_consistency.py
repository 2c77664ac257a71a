"""Is a trial's ZMP - CoP gap in the plates or in the markers? Per C3D trial, at `livezmp analyze`'s defaults:

1. The plates' whole force / mass (the plates' side of the CoM acceleration, low-passed as analyze does),
   integrated twice over the longest run of frames where they carry the load (their vertical force at least
   FORCE_SEEN of m (g + a_z), a_z the markers', as for complete frames), against the markers' CoM with its start
   position and velocity fitted, per axis: the RMS residual, the same with the plates' axis negated, and the
   CoM's own excursion there (peak to peak, start position and velocity taken out), mm. A plate axis read with
   the wrong sign, scale or channel leaves a residual of the order of the excursion.
2. The vertical load (g + a_z) / g over the scored frames, and the lateral ZMP - CoP RMS as it is and scaled to
   a 1 g load: a lateral acceleration error moves the ZMP by h da / (g + a_z), so a bouncy walk magnifies it.
3. The same trial with its trunk markers (C7 T10 CLAV STRN) unread, the head, arms and trunk then placed from
   the pelvis: RMS, bias fore-aft / lateral, lateral RMS (mm).

Usage: python benchmarks/bench_plate_consistency.py TRIAL.c3d ...
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from bench_forceplates import runs

from livezmp.balance.plates import G
from livezmp.model.c3d import read_c3d
from livezmp.offline.gaitlab import FORCE_SEEN, LabOptions, analyse_lab_take
from livezmp.offline.plausibility import com_accelerations
from livezmp.offline.validation import walking_axes

TRUNK = ("C7", "T10", "CLAV", "STRN")


def longest_run(mask: np.ndarray) -> slice:
    """The longest run of True in ``mask`` (N,) as a slice (empty when none)."""
    spans = runs(mask)
    if not spans:
        return slice(0, 0)
    start, stop = max(spans, key=lambda s: s[1] - s[0])  # the first of the longest, as argmax
    return slice(int(start), int(stop))


def rms_mm(x: np.ndarray) -> float:
    """RMS of ``x`` (m) in mm."""
    return float(1000 * np.sqrt(np.mean(x ** 2)))


def twice_integrated(acc: np.ndarray, dt: float) -> np.ndarray:
    """(n,) position from acceleration ``acc`` (n,) m/s2 by the trapezoidal rule, starting at rest at 0."""
    vel = np.r_[0.0, np.cumsum((acc[1:] + acc[:-1]) / 2) * dt]
    return np.r_[0.0, np.cumsum((vel[1:] + vel[:-1]) / 2) * dt]


def integration_check(a, dt: float) -> str:
    """Per axis (fore-aft, lateral, vertical): the markers' CoM against the plates' acceleration integrated twice
    (start position and velocity fitted), over the longest run where the plates carry the load: residual RMS,
    residual with the plates' axis negated, the CoM's excursion (mm)."""
    r, mass = a.result, a.summary["mass"]["used_kg"]
    az = com_accelerations(r.com, dt)[:, 2]
    run = longest_run((a.plates.force[:, 2] >= FORCE_SEEN * mass * (G + az)) & r.has_zmp)
    if run.stop - run.start < 10:
        return "no run of 10 frames with the load on the plates"
    fwd, left = walking_axes(r.com)
    t = np.arange(run.stop - run.start) * dt
    base = np.c_[np.ones_like(t), t]

    def detrended(x: np.ndarray) -> np.ndarray:
        return x - base @ np.linalg.lstsq(base, x, rcond=None)[0]

    cells = []
    for axis, g in ((fwd, 0.0), (left, 0.0), (np.array([0.0, 0.0, 1.0]), G)):
        com = r.com[run] @ axis
        plate = twice_integrated(a.plates.force[run] @ axis / mass - g, dt)
        negated = twice_integrated(-(a.plates.force[run] @ axis / mass - g), dt)
        rms = [rms_mm(detrended(com - p)) for p in (plate, negated)]
        cells.append(f"{rms[0]:4.1f} (negated {rms[1]:5.1f}) of {1000 * np.ptp(detrended(com)):5.1f}")
    return f"{t[-1]:.2f} s: " + " | ".join(cells)


def load_check(a, dt: float) -> str:
    """The vertical load over the scored frames and the lateral ZMP - CoP RMS, as is and scaled to 1 g."""
    r = a.result
    rows = a.complete & r.has_zmp & np.isfinite(a.plates.cop).all(axis=1)
    _, left = walking_axes(r.com)
    load = (G + com_accelerations(r.com, dt)[rows, 2]) / G
    lat = (r.zmp[rows] - a.plates.cop[rows]) @ left
    return (f"load min {load.min():.2f} median {np.median(load):.2f}, below 0.6 g {100 * np.mean(load < 0.6):3.0f} %; "
            f"lateral RMS {rms_mm(lat):5.1f}, at 1 g {rms_mm(lat * load):5.1f}")


def score(a) -> str:
    """RMS, bias fore-aft / lateral and lateral RMS (mm) of the ZMP against the plates' CoP."""
    cv = a.summary["cop_vs_zmp"]
    r = a.result
    rows = a.complete & r.has_zmp & np.isfinite(a.plates.cop).all(axis=1)
    _, left = walking_axes(r.com)
    lat = rms_mm((r.zmp[rows] - a.plates.cop[rows]) @ left)
    return f"{cv['rms_mm']:5.1f} ({cv['bias_mm'][0]:+5.1f} / {cv['bias_mm'][1]:+5.1f}), lateral {lat:5.1f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trials", nargs="+")
    args = parser.parse_args()
    for path in args.trials:
        trial = read_c3d(path)
        dt = 1.0 / trial.rate
        a = analyse_lab_take(trial, LabOptions())
        print(f"{path}\n  the plates' acceleration integrated twice against the markers' CoM, mm, fore-aft | "
              f"lateral | vertical: "
              f"{integration_check(a, dt)}\n  {load_check(a, dt)}\n  ZMP vs CoP mm: {score(a)}", end="")
        if all(trial.marker(m) is not None for m in TRUNK):
            unread = dataclasses.replace(trial, labels=[f"unread_{x}" if x in TRUNK else x for x in trial.labels])
            print(f"; trunk markers unread: {score(analyse_lab_take(unread, LabOptions()))}")
        else:
            print()


if __name__ == "__main__":
    main()
