"""Where the time of one ``Pipeline.step`` goes: each part timed alone on the inputs of a real
stream, then the whole step (p50 / p99), for the ROBOTIS OP3 (26 channels, 200 Hz) and a Bandai
skeleton (132 channels, 30 Hz).

Each part is replayed over the inputs it saw inside the pipeline (estimates, soles, support
labels), one ``perf_counter`` pair per call; a row gives the median and p99 of those calls in µs.
"glue" is the step's p50 minus the sum of the parts' p50 (all frames): argument handling, moving
the ZMP to the ground plane, building the FrameResult. A second table times the general paths
still in the code (per-channel Kalman covariances, every sole corner's velocity through the
validating ContactDetector.update, the general hull and clamp) side by side with the fast ones.

    python benchmarks/bench_step_parts.py             # about 30 s
    python benchmarks/bench_step_parts.py --frames 2000
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from bench_pipeline import OP3, WALK, latencies, op3_stream

from livezmp.balance.contacts import ContactDetector, GroundConfig
from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.balance.support import clamp_to_polygon, convex_hull, support_and_clamp
from livezmp.balance.zmp import compute_zmp
from livezmp.estimate.estimator import StreamingEstimator
from livezmp.estimate.kalman import ConstantAccelerationKalman
from livezmp.model.body import foot_soles, lowest_sole_points, sole_velocities
from livezmp.model.bvh import read_bvh
from livezmp.model.bvh_body import body_from_bvh
from livezmp.model.urdf_body import body_from_urdf


@dataclass
class Seen:
    """What the parts of one step received, per analysed frame."""

    estimates: list
    soles: list
    supports: list
    zmps: list


def timed(fn, args_list) -> np.ndarray:
    """Seconds of each call ``fn(*args)``, in order."""
    out = np.empty(len(args_list))
    clock = time.perf_counter
    for i, args in enumerate(args_list):
        s = clock()
        fn(*args)
        out[i] = clock() - s
    return out


def record(pipe: Pipeline, t: np.ndarray, frames: np.ndarray, warm: int) -> tuple[np.ndarray, Seen]:
    """Step through the stream; return the step latencies after ``warm`` frames and what the parts saw."""
    seen = Seen([], [], [], [])
    analyse = pipe._analyse

    def spy(est):
        res = analyse(est)
        seen.estimates.append(est)
        seen.soles.append(res.soles)
        seen.supports.append(res.support)
        seen.zmps.append(res.zmp)
        return res

    lat = latencies(pipe, t, frames, warm)
    # a second pass with the spy records the parts' inputs (the first pass is timed without it)
    pipe.flush()
    pipe.contacts = ContactDetector(pipe.config.contacts, GroundConfig(
        warmup_frames=pipe.config.ground_warmup_frames, override=pipe.config.ground_z))
    pipe._analyse = spy
    for k in range(len(t)):
        pipe.step(float(t[k]), frames[k])
    pipe._analyse = analyse
    return lat, seen


def parts(pipe: Pipeline, t: np.ndarray, frames: np.ndarray, seen: Seen, warm: int) -> list[tuple[str, np.ndarray]]:
    """The calls ``Pipeline.step`` makes, each timed alone over the inputs it saw (after ``warm`` frames)."""
    body, model, data = pipe.body, pipe.model, pipe.data
    est = StreamingEstimator(body.nq, body.angle_mask, pipe.estimator.config)
    q_frames = [(float(ti), body.channels_to_q(np.asarray(f, dtype=float))) for ti, f in zip(t, frames, strict=True)]
    rows = [("estimator step", timed(est.step, q_frames)[warm:])]
    ff = pipe.config.flight_fraction
    ests = seen.estimates
    rows.append(("compute_zmp", timed(lambda e: compute_zmp(model, data, e.q, e.qd, e.qdd, 0.0, ff),
                                      [(e,) for e in ests[warm:]])))
    rows.append(("updateFramePlacements", timed(lambda: pin.updateFramePlacements(model, data),
                                                [()] * (len(ests) - warm))))
    soles_t, low_t, lows = [], [], []
    clock = time.perf_counter
    for e in ests:
        compute_zmp(model, data, e.q, e.qd, e.qdd, 0.0, ff)
        pin.updateFramePlacements(model, data)
        s = clock()
        soles = foot_soles(body, data)
        m = clock()
        lows.append(lowest_sole_points(body, model, data, soles))
        soles_t.append(m - s)
        low_t.append(clock() - m)
    rows += [("foot_soles", np.array(soles_t[warm:])), ("lowest_sole_points", np.array(low_t[warm:]))]
    det = ContactDetector(pipe.config.contacts, GroundConfig(
        warmup_frames=pipe.config.ground_warmup_frames, override=pipe.config.ground_z))
    args = [(*low["left"], *low["right"]) for low in lows]
    for a in args[:warm]:  # the ground warm-up is not the steady state
        det.update_lowest(*a)
    rows.append(("contacts.update_lowest", timed(det.update_lowest, args[warm:])))
    sup = [(s["left"], s["right"], lab, None if z is None else z[:2])
           for s, lab, z in zip(seen.soles[warm:], seen.supports[warm:], seen.zmps[warm:], strict=True)]
    rows.append(("support_and_clamp (all frames)", timed(support_and_clamp, sup)))
    for label in ("left", "double"):
        some = [a for a in sup if a[2] == label or (label == "left" and a[2] == "right")]
        if some:
            what = "single support" if label == "left" else "double support"
            rows.append((f"support_and_clamp ({what}, {len(some)} frames)", timed(support_and_clamp, some)))
    return rows


def baselines(pipe: Pipeline, t: np.ndarray, frames: np.ndarray, seen: Seen, warm: int) -> list[tuple[str, ...]]:
    """The same work by the general paths still in the code, side by side with the fast ones:
    rows (label, baseline p50 µs, fast p50 µs)."""
    body, model, data = pipe.body, pipe.model, pipe.data
    cfg = pipe.estimator.config
    # Kalman: per-channel covariances (one channel's noise a hair off keeps them apart) against the shared one.
    ys = [body.channels_to_q(np.asarray(f, dtype=float)) for f in frames]
    dts = [None] + list(np.diff(t))
    ref = StreamingEstimator(body.nq, body.angle_mask, cfg).kalman
    apart = ref.meas_var.copy()
    apart[0] *= 1.0 + 1e-12
    kalman = {}
    for shared, meas_var in ((False, apart), (True, ref.meas_var)):
        kf = ConstantAccelerationKalman(body.angle_mask, ref.jerk_psd[:, 0, 0], meas_var, np.diag(ref.init_cov))
        kalman[shared] = timed(kf.step, list(zip(dts, ys, strict=True)))[warm:]
    rows = [("Kalman step: per-channel | shared covariance", np.median(kalman[False]), np.median(kalman[True]))]
    # Contacts: every corner's velocity, validated by update(), against the lowest corner's floats.
    ff = pipe.config.flight_fraction
    general, fast = [], []
    det_a, det_b = (ContactDetector(pipe.config.contacts, GroundConfig(override=0.0)) for _ in range(2))
    clock = time.perf_counter
    for e in seen.estimates[warm:]:
        compute_zmp(model, data, e.q, e.qd, e.qdd, 0.0, ff)
        pin.updateFramePlacements(model, data)
        soles = foot_soles(body, data)
        s = clock()
        vel = sole_velocities(body, model, data, soles)
        det_a.update(soles["left"], vel["left"], soles["right"], vel["right"])
        m = clock()
        low = lowest_sole_points(body, model, data, soles)
        det_b.update_lowest(*low["left"], *low["right"])
        general.append(m - s)
        fast.append(clock() - m)
    rows.append(("contacts: corner velocities + update | lowest + update_lowest", np.median(general),
                 np.median(fast)))
    # Support: general hull and a validated clamp against the closed-form sole and the combined call.
    single = [(s["left"], s["right"], lab, z[:2]) for s, lab, z in
              zip(seen.soles[warm:], seen.supports[warm:], seen.zmps[warm:], strict=True)
              if lab in ("left", "right") and z is not None]
    if single:
        def general_path(left, right, label, p):
            poly = convex_hull(left if label == "left" else right)
            return poly, clamp_to_polygon(p, poly)

        rows.append(("single support: convex_hull + clamp | support_and_clamp",
                     np.median(timed(general_path, single)), np.median(timed(support_and_clamp, single))))
    return [(label, f"{1e6 * a:8.1f}", f"{1e6 * b:8.1f}") for label, a, b in rows]


def report(name: str, body, rate: float, t: np.ndarray, frames: np.ndarray, warm: int) -> None:
    pipe = Pipeline(body, default_config(body, rate), 1 / rate)
    lat, seen = record(pipe, t, frames, warm)
    rows = parts(pipe, t, frames, seen, warm)
    stance = sum(s != "none" for s in seen.supports[warm:]) / max(1, len(seen.supports) - warm)
    print(f"\n{name}: {len(t)} frames, {100 * stance:.0f} % with support")
    print(f"{'part':50s} {'p50 µs':>8s} {'p99 µs':>8s}")
    total = 0.0
    for label, x in rows:
        p50 = 1e6 * np.median(x)
        if "support" not in label or "all frames" in label:
            total += p50
        print(f"{label:50s} {p50:8.1f} {1e6 * np.percentile(x, 99):8.1f}")
    step50, step99 = 1e6 * np.median(lat), 1e6 * np.percentile(lat, 99)
    print(f"{'sum of parts (p50, all frames)':50s} {total:8.1f}")
    print(f"{'glue (step p50 - sum)':50s} {step50 - total:8.1f}")
    print(f"{'Pipeline.step':50s} {step50:8.1f} {step99:8.1f}")
    print(f"\n{'same work, general path | fast path (p50 µs)':62s} {'general':>8s} {'fast':>8s}")
    for label, general, fast in baselines(pipe, t, frames, seen, warm):
        print(f"{label:62s} {general} {fast}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=6000, help="frames per stream")
    args = ap.parse_args()
    op3 = body_from_urdf(OP3)
    rate = 200.0
    t, q = op3_stream(op3, args.frames, rate)
    report("OP3 (26 ch), 200 Hz", op3, rate, t, q, 200)
    motion = read_bvh(WALK)
    walk = body_from_bvh(motion)
    reps = int(np.ceil(args.frames / len(motion.frames)))
    wf = np.tile(motion.frames, (reps, 1))[: args.frames]
    wt = np.arange(len(wf)) * motion.frame_time
    report("Bandai skeleton (132 ch), 30 Hz", walk, motion.fps, wt, wf, 60)


if __name__ == "__main__":
    main()
