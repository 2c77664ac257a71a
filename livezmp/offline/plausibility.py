"""Is a take's motion physically plausible? Its centre-of-mass accelerations and ZMP–CoM distances
against what force plates measured on real walks.

The references are the largest 99th percentiles over the shared plate trials (a Plug-in Gait walk
and a CGM 2.4 walk; ``python benchmarks/bench_forceplates.py`` prints them), per axis the larger of
the plates' (ground reaction ÷ mass − g, complete frames) and livezmp's own estimate from the
markers (which is what a take is judged by, and is noisier sideways). Two subjects at walking speed: a take of running,
jumping or dancing will exceed them without being wrong, and the verdict says "for walking".
"""

from __future__ import annotations

import numpy as np

from livezmp.offline.validation import walking_axes

# m/s², fore-aft, lateral, vertical (see the module docstring)
WALK_COM_ACC_P99 = (3.4, 1.2, 3.4)
WALK_ZMP_COM_P99_M = 0.30  # m, horizontal CoP-to-CoM distance, same frames
PLAUSIBLE_RATIO = 1.5


def com_accelerations(com: np.ndarray, dt: float) -> np.ndarray:
    """(N, 3) m/s²: the estimated CoM trajectory (smooth: it comes from the estimator's positions)
    differentiated twice by central differences."""
    if len(com) < 3:
        return np.zeros_like(com)
    return np.gradient(np.gradient(com, dt, axis=0), dt, axis=0)


def plausibility(com: np.ndarray, zmp: np.ndarray, has_zmp: np.ndarray, dt: float) -> dict:
    """CoM acceleration p99 (fore-aft, lateral, vertical; m/s²) and ZMP–CoM distance p99 (m) of a take
    (internal frame), their ratios to a real walk's, and a one-line verdict."""
    acc = com_accelerations(com, dt)
    fwd, left = walking_axes(com)
    parts = (acc @ fwd, acc @ left, acc[:, 2])
    p99 = [float(np.percentile(np.abs(x), 99)) for x in parts]
    ratio = [p / r for p, r in zip(p99, WALK_COM_ACC_P99, strict=True)]
    dist = np.linalg.norm(zmp[has_zmp, :2] - com[has_zmp, :2], axis=1)
    d99 = float(np.percentile(dist, 99)) if len(dist) else 0.0
    names = ("fore-aft", "lateral", "vertical")
    worst = int(np.argmax(ratio))
    if ratio[worst] > PLAUSIBLE_RATIO:
        verdict = (f"not physically plausible for walking: {names[worst]} CoM acceleration {ratio[worst]:.1f}x "
                   f"a real walk's (force plates)")
    elif d99 / WALK_ZMP_COM_P99_M > PLAUSIBLE_RATIO:
        ratio_d = d99 / WALK_ZMP_COM_P99_M
        verdict = f"not physically plausible for walking: ZMP-CoM distance {ratio_d:.1f}x a real walk's"
    else:
        verdict = "plausible for walking (CoM accelerations within 1.5x a real walk's)"
    return {"com_acc_p99_mps2": [round(p, 3) for p in p99], "walk_reference_mps2": list(WALK_COM_ACC_P99),
            "ratio": [round(r, 2) for r in ratio], "zmp_com_p99_m": round(d99, 4),
            "walk_reference_zmp_com_m": WALK_ZMP_COM_P99_M, "verdict": verdict}
