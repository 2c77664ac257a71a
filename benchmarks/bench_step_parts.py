"""Where the time of one ``Pipeline.step`` goes: each part timed alone on the inputs of a real
stream, then the whole step (p50 / p99), for the ROBOTIS OP3 (26 channels, 200 Hz) and a Bandai
skeleton (132 channels, 30 Hz).

Each part is replayed over the inputs it saw inside the pipeline (estimates, soles, support
labels), one ``perf_counter`` pair per call; a row gives the median and p99 of those calls in µs.
"glue" is the step's p50 minus the sum of the parts' p50: argument handling, the contact label,
moving the ZMP to the ground plane, building the FrameResult.

    python benchmarks/bench_step_parts.py             # about 30 s
    python benchmarks/bench_step_parts.py --frames 2000
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from bench_pipeline import OP3, WALK, op3_stream

from livezmp.body import foot_soles, sole_velocities
from livezmp.body_bvh import body_from_bvh
from livezmp.body_urdf import body_from_urdf
from livezmp.bvh import read_bvh
from livezmp.contacts import ContactDetector, GroundConfig
from livezmp.estimator import StreamingEstimator
from livezmp.pipeline import Pipeline, default_config
from livezmp.support import clamp_to_polygon, support_polygon
from livezmp.zmp import compute_zmp


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

    lat = np.empty(len(t))
    clock = time.perf_counter
    for k in range(len(t)):
        s = clock()
        pipe.step(float(t[k]), frames[k])
        lat[k] = clock() - s
    # a second pass with the spy records the parts' inputs (the first pass is timed without it)
    pipe.flush()
    pipe.contacts = ContactDetector(pipe.config.contacts, GroundConfig(
        warmup_frames=pipe.config.ground_warmup_frames, override=pipe.config.ground_z))
    pipe._analyse = spy
    for k in range(len(t)):
        pipe.step(float(t[k]), frames[k])
    pipe._analyse = analyse
    return lat[warm:], seen


def parts(pipe: Pipeline, t: np.ndarray, frames: np.ndarray, seen: Seen, warm: int) -> list[tuple[str, np.ndarray]]:
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
    soles_t, vel_t, vels = [], [], []
    clock = time.perf_counter
    for e in ests:
        compute_zmp(model, data, e.q, e.qd, e.qdd, 0.0, ff)
        pin.updateFramePlacements(model, data)
        s = clock()
        soles = foot_soles(body, data)
        m = clock()
        vels.append(sole_velocities(body, model, data, soles))
        soles_t.append(m - s)
        vel_t.append(clock() - m)
    rows += [("foot_soles", np.array(soles_t[warm:])), ("sole_velocities", np.array(vel_t[warm:]))]
    det = ContactDetector(pipe.config.contacts, GroundConfig(
        warmup_frames=pipe.config.ground_warmup_frames, override=pipe.config.ground_z))
    args = [(s["left"], v["left"], s["right"], v["right"]) for s, v in zip(seen.soles, vels, strict=True)]
    for a in args[:warm]:  # the ground warm-up is not the steady state
        det.update(*a)
    rows.append(("contacts.update", timed(det.update, args[warm:])))
    sup = [(s["left"][:, :2], s["right"][:, :2], lab) for s, lab in zip(seen.soles[warm:], seen.supports[warm:],
                                                                         strict=True)]
    rows.append(("support_polygon (all frames)", timed(support_polygon, sup)))
    stance = [a for a in sup if a[2] != "none"]
    if stance:
        rows.append((f"support_polygon (stance, {len(stance)} frames)", timed(support_polygon, stance)))
        polys = [support_polygon(*a) for a in stance]
        zs = [z for z, lab in zip(seen.zmps[warm:], seen.supports[warm:], strict=True) if lab != "none"]
        rows.append(("clamp_to_polygon (stance)", timed(clamp_to_polygon, [(z[:2], p) for z, p in
                                                                           zip(zs, polys, strict=True)])))
    return rows


def report(name: str, body, rate: float, t: np.ndarray, frames: np.ndarray, warm: int) -> None:
    pipe = Pipeline(body, default_config(body, rate), 1 / rate)
    lat, seen = record(pipe, t, frames, warm)
    rows = parts(pipe, t, frames, seen, warm)
    stance = sum(s != "none" for s in seen.supports[warm:]) / max(1, len(seen.supports) - warm)
    print(f"\n{name}: {len(t)} frames, {100 * stance:.0f} % with support")
    print(f"{'part':44s} {'p50 µs':>8s} {'p99 µs':>8s}")
    total = 0.0
    for label, x in rows:
        p50 = 1e6 * np.median(x)
        if not label.startswith("support_polygon (stance") and not label.endswith("(stance)"):
            total += p50
        print(f"{label:44s} {p50:8.1f} {1e6 * np.percentile(x, 99):8.1f}")
    step50, step99 = 1e6 * np.median(lat), 1e6 * np.percentile(lat, 99)
    print(f"{'sum of parts (p50, all frames)':44s} {total:8.1f}")
    print(f"{'glue (step p50 - sum)':44s} {step50 - total:8.1f}")
    print(f"{'Pipeline.step':44s} {step50:8.1f} {step99:8.1f}")


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
