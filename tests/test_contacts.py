"""Contact detection and ground height on synthetic foot trajectories with hand-derived truth."""

import math
from itertools import groupby

import numpy as np
import pytest

from livezmp.balance.contacts import (
    ContactConfig,
    ContactDetector,
    ContactError,
    FootContact,
    GroundConfig,
    GroundEstimator,
    step_foot,
    support_label,
)
from livezmp.errors import InputError

CFG = ContactConfig()  # on: h <= 0.03 m and v <= 0.4 m/s; off: h > 0.05 m or v > 1.0 m/s; 2 frames
GROUND_ZERO = GroundConfig(override=0.0)


def flat_sole(x, y, z, length=0.25, width=0.10):
    """(4, 3) corners of a level heel-to-toe rectangle centred at (x, y), sole at height z."""
    return np.array(
        [[x + sx * length / 2, y + sy * width / 2, z] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    )


def moving(speed):
    """(4, 3) per-corner velocities of a foot translating forward at ``speed`` m/s."""
    return np.tile([speed, 0.0, 0.0], (4, 1))


def run(detector, left, right):
    """Labels for per-frame (height above ground, forward speed) pairs of each foot."""
    return [
        detector.update(flat_sole(0, 0.1, hl), moving(vl), flat_sole(0, -0.1, hr), moving(vr))
        for (hl, vl), (hr, vr) in zip(left, right, strict=True)
    ]


def runs(labels):
    return [(k, len(list(g))) for k, g in groupby(labels)]


# --- one foot ------------------------------------------------------------------------------------


def test_first_frame_decides_at_once():
    # In contact unless beyond the lift-off thresholds: a foot starting still near the ground stands.
    assert step_foot(FootContact(), 0.0, 0.0, CFG).in_contact is True
    assert step_foot(FootContact(), 0.05, 1.0, CFG).in_contact is True
    assert step_foot(FootContact(), 0.06, 0.0, CFG).in_contact is False  # above height_off
    assert step_foot(FootContact(), 0.0, 1.1, CFG).in_contact is False  # above speed_off


def test_hysteresis_band_holds_either_state():
    # 4 cm and 0.7 m/s are between the on and off thresholds: whatever the state, it stays.
    for start in (True, False):
        s = FootContact(start)
        for h, v in [(0.04, 0.0), (0.0, 0.7), (0.04, 0.7)] * 5:
            s = step_foot(s, h, v, CFG)
            assert s == FootContact(start)


def test_debounce_needs_consecutive_frames():
    cfg = ContactConfig(min_frames=3)
    s = FootContact(True)
    s = step_foot(s, 0.10, 0.0, cfg)  # 1st frame above height_off
    s = step_foot(s, 0.10, 0.0, cfg)  # 2nd
    assert s == FootContact(True, 2)
    s = step_foot(s, 0.0, 0.0, cfg)  # back down: the count restarts
    assert s == FootContact(True, 0)
    for _ in range(2):
        s = step_foot(s, 0.10, 0.0, cfg)
        assert s.in_contact
    assert step_foot(s, 0.10, 0.0, cfg) == FootContact(False)  # 3rd consecutive frame


def test_support_labels():
    assert support_label(True, True) == "double"
    assert support_label(True, False) == "left"
    assert support_label(False, True) == "right"
    assert support_label(False, False) == "none"


def test_speed_is_the_lowest_corners():
    # Heel strike: the heel corners rest on the ground and stay put while the foot rotates down
    # about them, the toe corners 8 cm up and moving at 1.5 m/s. Per-corner velocities see a
    # standing heel; one velocity for the whole foot (an ankle at 0.8 m/s) sees a moving foot.
    sole = flat_sole(0.0, -0.1, 0.0)
    sole[[1, 2], 2] = 0.08  # toe corners up
    corner_vel = np.array([[0.0, 0, 0], [1.5, 0, -0.5], [1.5, 0, -0.5], [0.0, 0, 0]])
    standing = flat_sole(0.0, 0.1, 0.0)
    det = ContactDetector(ContactConfig(min_frames=1), GROUND_ZERO)
    assert det.update(flat_sole(0, 0.1, 0.2), moving(3.0), flat_sole(0, -0.1, 0.2), moving(3.0)) == "none"
    assert det.update(standing, moving(0), sole, corner_vel) == "double"
    det = ContactDetector(ContactConfig(min_frames=1), GROUND_ZERO)
    det.update(flat_sole(0, 0.1, 0.2), moving(3.0), flat_sole(0, -0.1, 0.2), moving(3.0))
    assert det.update(standing, moving(0), sole, [0.8, 0.0, -0.3]) == "left"


# --- stepping patterns, exact sequences ----------------------------------------------------------

# One swing, frame by frame: (height of the lowest sole point above the ground in m, speed in m/s).
SWING = [
    (0.01, 0.5),
    (0.03, 1.5),
    (0.08, 3.0),
    (0.12, 4.0),
    (0.08, 3.0),
    (0.04, 1.5),
    (0.02, 0.6),
    (0.01, 0.3),
]
STANCE = (0.0, 0.0)


def walk(cycles, double_frames):
    """4 frames standing, then (left swing, double support, right swing, double support) x cycles."""
    left, right = [STANCE] * 4, [STANCE] * 4
    for _ in range(cycles):
        left += SWING + [STANCE] * double_frames
        right += [STANCE] * (len(SWING) + double_frames)
        left += [STANCE] * (len(SWING) + double_frames)
        right += SWING + [STANCE] * double_frames
    return left, right


def test_walking_sequence_exact():
    # By hand, with the default thresholds and 2-frame debounce:
    #   swing frame 0 (1 cm, 0.5 m/s): below speed_off, the foot stays down (though above speed_on);
    #   frame 1 (1.5 m/s > speed_off) is the 1st lifting frame, frame 2 the 2nd: lifted from frame 2;
    #   frames 3-6 fail height_on or speed_on; frame 7 (1 cm, 0.3 m/s) is the 1st touching frame and
    #   the next (stance) frame the 2nd: down again from the first stance frame.
    # So each swing foot reads lifted for 6 frames (swing frames 2-7), and each double support runs
    # from the first stance frame through swing frames 0-1 of the other foot: 3 + 2 frames.
    left, right = walk(cycles=3, double_frames=3)
    labels = run(ContactDetector(CFG, GROUND_ZERO), left, right)
    expected = [("double", 4 + 2)]
    for _ in range(3):
        expected += [("right", 6), ("double", 3 + 2), ("left", 6), ("double", 3 + 2)]
    expected[-1] = ("double", 3)  # no swing follows the last double support
    assert runs(labels) == expected


def test_walking_sequence_without_debounce():
    # min_frames = 1: lifted at swing frame 1, down at swing frame 7 (same 6 frames, one earlier);
    # double support: swing frame 7 + 3 stance + the other foot's swing frame 0.
    left, right = walk(cycles=1, double_frames=3)
    labels = run(ContactDetector(ContactConfig(min_frames=1), GROUND_ZERO), left, right)
    assert runs(labels) == [
        ("double", 4 + 1),
        ("right", 6),
        ("double", 1 + 3 + 1),
        ("left", 6),
        ("double", 1 + 3),
    ]


def test_running_sequence_has_flight():
    # Running with an 18-frame cycle: each foot is down 6 frames and swings 12, the right foot half a
    # cycle (9 frames) behind, so 3 frames of flight follow each stance. Swing: 1 cm at 0.5 m/s,
    # then 10 frames high and fast, then 1 cm at 0.3 m/s.
    swing = [(0.01, 0.5)] + [(0.10, 4.0)] * 10 + [(0.01, 0.3)]

    def foot(k):
        phase = k % 18
        return STANCE if phase < 6 else swing[phase - 6]

    n = 3 * 18
    labels = run(
        ContactDetector(CFG, GROUND_ZERO), [foot(k) for k in range(n)], [foot(k - 9) for k in range(n)]
    )
    # As in walking, a foot reads down from its first stance frame through swing frame 1 (8 frames),
    # so 3 - 2 = 1 frame of flight is left between stances. Frame 0 decides at once: left down
    # (stance), right up (swing frame 3); the right foot's last swing frame (8) is its 1st touching one.
    assert runs(labels) == [("left", 8), ("none", 1), ("right", 8), ("none", 1)] * 3


def test_small_robot_stepping_in_place():
    # An OP3-like robot stepping in place at 125 Hz: each swing lasts 30 frames and lifts the sole
    # 0.04 sin(pi k / 30) m without moving horizontally; 8 frames of double support in between.
    swing = [(0.04 * math.sin(math.pi * k / 30), 0.0) for k in range(30)]
    left, right = [STANCE] * 8, [STANCE] * 8
    for _ in range(2):
        left += swing + [STANCE] * 8 + [STANCE] * 38
        right += [STANCE] * 38 + swing + [STANCE] * 8
    labels = run(ContactDetector(ContactConfig.small_robot(), GROUND_ZERO), left, right)
    # Lift-off needs h > 2 cm: sin(pi k / 30) > 1/2 first at k = 6 (k = 5 is exactly 1/2), debounced
    # to k = 7. Touch-down needs h <= 1 cm: sin(pi k / 30) <= 1/4 first at k = 28 (30 (1 - asin(1/4)
    # / pi) = 27.6), debounced to k = 29. Lifted for k = 7..28: 22 frames.
    expected = [("double", 8 + 7)]
    for _ in range(2):
        expected += [("right", 22), ("double", 1 + 8 + 7), ("left", 22), ("double", 1 + 8 + 7)]
    expected[-1] = ("double", 1 + 8)
    assert runs(labels) == expected
    # The human defaults need 5 cm to lift off: this robot would never leave double support.
    assert set(run(ContactDetector(CFG, GROUND_ZERO), left, right)) == {"double"}


# --- noise ---------------------------------------------------------------------------------------


def smooth_walk(fps, cycles, ground=0.0, noise=None, seed=0):
    """A 1 s walking cycle: left swing over [0, 0.4) s, right over [0.5, 0.9) s. Mid-swing the sole
    is 12 cm up and moves at 4.5 m/s, both rising as sin^2 from and falling back to zero, so the
    thresholds are crossed slowly. noise = (height sigma in m, velocity sigma in m/s) per corner.
    Returns per-frame (left sole, left corner velocities, right sole, right corner velocities)."""
    rng = np.random.default_rng(seed)
    frames = []
    for k in range(int(cycles * fps)):
        t = (k / fps) % 1.0
        feet = []
        for start, y in ((0.0, 0.1), (0.5, -0.1)):  # left, right
            u = (t - start) / 0.4
            lift = math.sin(math.pi * u) ** 2 if 0.0 <= u < 1.0 else 0.0
            sole, vel = flat_sole(0.0, y, ground + 0.12 * lift), moving(4.5 * lift)
            if noise is not None:
                sole[:, 2] += rng.normal(0.0, noise[0], 4)
                vel = vel + rng.normal(0.0, noise[1], (4, 3))
            feet += [sole, vel]
        frames.append(feet)
    return frames


def detect(frames, config=CFG, ground=GROUND_ZERO):
    det = ContactDetector(config, ground)
    return [det.update(*f) for f in frames]


def change_frames(labels):
    return [k for k in range(1, len(labels)) if labels[k] != labels[k - 1]]


@pytest.mark.parametrize("fps", [30, 60, 120])
@pytest.mark.parametrize("seed", range(4))
def test_no_chatter_under_noise(fps, seed):
    clean = detect(smooth_walk(fps, cycles=5))
    # A walk: double and single supports alternate, never flight, 4 changes per cycle.
    assert [k for k, _ in runs(clean)][:5] == ["double", "right", "double", "left", "double"]
    assert "none" not in clean and len(change_frames(clean)) == 4 * 5
    # Sole heights with 3 mm noise per corner; velocities as noisy as finite differences of
    # positions with 1 mm noise (0.0015 * fps m/s), the worst an unsmoothed feed gives.
    noisy = detect(smooth_walk(fps, cycles=5, noise=(0.003, 0.0015 * fps), seed=seed))
    # Same supports in the same order, each change within 50 ms (or 2 frames) of the noise-free one.
    assert [k for k, _ in runs(noisy)] == [k for k, _ in runs(clean)]
    assert np.abs(np.subtract(change_frames(noisy), change_frames(clean))).max() <= max(2, 0.05 * fps)


@pytest.mark.parametrize("seed", range(4))
def test_without_hysteresis_and_debounce_the_same_data_chatters(seed):
    noisy = smooth_walk(120, cycles=5, noise=(0.003, 0.18), seed=seed)
    bare = ContactConfig(height_on=0.04, height_off=0.04, speed_on=0.7, speed_off=0.7, min_frames=1)
    assert len(change_frames(detect(noisy))) == 4 * 5
    assert len(change_frames(detect(noisy, bare))) > 4 * 5


# --- ground height -------------------------------------------------------------------------------


def test_ground_found_on_a_walk_with_a_known_offset():
    ground = 0.137  # e.g. a capture volume whose floor is not at z = 0
    frames = smooth_walk(120, cycles=10, ground=ground, noise=(0.001, 0.05), seed=1)
    det = ContactDetector(CFG)  # ground estimated from the feet
    labels, heights = [], []
    for f in frames:
        labels.append(det.update(*f))
        heights.append(det.ground_height)
    heights = np.array(heights)
    # From the first frame on within 5 mm: the 5th percentile of the lowest of 4-8 corners with
    # 1 mm noise sits about 2.5 mm low, and the tracker jitters around it.
    assert np.abs(heights - ground).max() < 0.005
    # The labels agree with those for the true ground given up front.
    known = detect(frames, ground=GroundConfig(override=ground))
    assert np.mean(np.array(labels) == np.array(known)) > 0.99
    # Assuming the floor at z = 0 instead, every foot looks 13.7 cm up: flight throughout.
    assert set(detect(frames, ground=GROUND_ZERO)) == {"none"}


def test_ground_follows_slow_drift():
    # The floor seen by the capture drifts up 3 cm over 20 s (a calibration creeping).
    frames = smooth_walk(120, cycles=20, noise=(0.001, 0.05), seed=2)
    det = ContactDetector(CFG)
    errors = []
    for k, (ls, lv, rs, rv) in enumerate(frames):
        drift = 0.03 * k / len(frames)
        det.update(ls + [0, 0, drift], lv, rs + [0, 0, drift], rv)
        errors.append(det.ground_height - drift)
    assert np.abs(errors).max() < 0.005


def test_ground_after_warmup_moves_at_most_track_step_per_frame():
    est = GroundEstimator(GroundConfig(warmup_frames=10, percentile=5.0, track_step=0.002))
    for _ in range(10):
        est.update(0.0)
    assert est.height == 0.0
    # The floor drops 5 cm at once (stepping off a platform): the estimate comes down by
    # (1 - 0.05) * 2 mm = 1.9 mm per frame, reaching -5 cm within ceil(0.05 / 0.0019) = 27 frames.
    path = [est.update(-0.05) for _ in range(40)]
    steps = np.diff([0.0, *path])
    np.testing.assert_allclose(steps[:26], -0.0019)
    assert abs(path[26] + 0.05) < 0.0019 and abs(path[-1] + 0.05) < 0.0019
    # A foot far above the floor (a jump) raises it by only 0.05 * 2 mm = 0.1 mm per frame.
    before = est.height
    after = [est.update(0.5) for _ in range(10)][-1]
    assert after - before == pytest.approx(10 * 0.0001)


def test_ground_override():
    est = GroundEstimator(GroundConfig(override=0.25))
    assert est.height == 0.25
    assert [est.update(z) for z in (0.0, -1.0, 3.0)] == [0.25, 0.25, 0.25]
    det = ContactDetector(CFG, GroundConfig(override=0.25))
    assert det.update(flat_sole(0, 0.1, 0.26), moving(0), flat_sole(0, -0.1, 0.40), moving(0)) == "left"
    assert det.ground_height == 0.25


def test_ground_warmup_is_a_percentile():
    # During warm-up the estimate is the 5th percentile of the lowest points seen so far
    # (numpy's linear interpolation: for 0..99 mm that is 4.95 mm).
    est = GroundEstimator(GroundConfig(warmup_frames=100))
    for z in np.random.default_rng(3).permutation(100) / 1000:
        est.update(z)
    assert est.height == pytest.approx(0.00495)


# --- contacts from outside -----------------------------------------------------------------------


def test_contacts_from_sensors_override_detection():
    det = ContactDetector(CFG, GROUND_ZERO)
    up, down = flat_sole(0, 0.1, 0.3), flat_sole(0, -0.1, 0.0)
    # Force sensors say left only, though the geometry says right only.
    assert det.update(up, moving(0), down, moving(0), contacts=(True, False)) == "left"
    assert det.update(up, moving(0), down, moving(0), contacts=(False, False)) == "none"
    # Detection resumes from the sensors' states: the right foot needs its 2 debounce frames.
    assert det.update(up, moving(0), down, moving(0)) == "none"
    assert det.update(up, moving(0), down, moving(0)) == "right"


def test_sensor_sequence_gives_the_same_labels_as_detection():
    left, right = walk(cycles=2, double_frames=3)
    detected = run(ContactDetector(CFG, GROUND_ZERO), left, right)
    flags = [(lab in ("left", "double"), lab in ("right", "double")) for lab in detected]
    det = ContactDetector(CFG, GROUND_ZERO)
    sensed = [
        det.update(flat_sole(0, 0.1, 0.5), moving(3), flat_sole(0, -0.1, 0.5), moving(3), contacts=c)
        for c in flags
    ]
    assert sensed == detected


# --- errors --------------------------------------------------------------------------------------


def test_bad_frames_name_frame_and_field():
    det = ContactDetector(CFG, GROUND_ZERO)
    sole = flat_sole(0, 0, 0)
    det.update(sole, moving(0), sole, moving(0))
    det.update(sole, moving(0), sole, moving(0))
    with pytest.raises(ContactError, match=r"frame 2: right sole: expected \(k, 3\).*\(4, 2\)"):
        det.update(sole, moving(0), sole[:, :2], moving(0))
    bad = sole.copy()
    bad[3, 2] = np.nan
    with pytest.raises(ContactError, match="frame 2: left sole: row 3 has a non-finite"):
        det.update(bad, moving(0), sole, moving(0))
    with pytest.raises(ContactError, match="frame 2: left velocity: non-finite"):
        det.update(sole, [np.inf, 0.0], sole, moving(0))
    with pytest.raises(
        ContactError, match=r"frame 2: right velocity: expected .*\(4, 3\).*got shape \(3, 3\)"
    ):
        det.update(sole, moving(0), sole, np.zeros((3, 3)))
    with pytest.raises(ContactError, match="frame 2: contacts: expected"):
        det.update(sole, moving(0), sole, moving(0), contacts=(True,))
    assert det.frame == 2  # rejected frames do not count
    assert issubclass(ContactError, InputError)


def test_pure_steps_reject_non_finite_input():
    with pytest.raises(ContactError, match="foot: height nan m"):
        step_foot(FootContact(True), float("nan"), 0.0, CFG)
    with pytest.raises(ContactError, match="ground: lowest sole point z must be finite"):
        GroundEstimator().update(float("inf"))


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: ContactConfig(height_on=0.06), r"ContactConfig.height_off: must be a number in \[0.06"),
        (lambda: ContactConfig(speed_on=-0.1), "ContactConfig.speed_on"),
        (lambda: ContactConfig(speed_off=float("nan")), "ContactConfig.speed_off"),
        (lambda: ContactConfig(min_frames=0), "ContactConfig.min_frames: must be an integer >= 1"),
        (lambda: ContactConfig(min_frames=1.5), "ContactConfig.min_frames"),
        (lambda: ContactConfig(height_on="3cm"), "ContactConfig.height_on"),
        (lambda: GroundConfig(percentile=150), "GroundConfig.percentile"),
        (lambda: GroundConfig(warmup_frames=0), "GroundConfig.warmup_frames"),
        (lambda: GroundConfig(override=float("inf")), "GroundConfig.override"),
    ],
)
def test_bad_config(make, match):
    with pytest.raises(ContactError, match=match):
        make()


def test_a_frame_the_estimator_refuses_leaves_no_contacts_for_a_later_frame(mini):
    """Foot-sensor contacts given with a frame the estimator refuses (a time not after the last) belong to no frame:
    the frames after it keep their own contacts."""
    from livezmp.balance.pipeline import Pipeline, default_config
    from livezmp.estimate.estimator import EstimatorError

    rate = 100.0
    pipe = Pipeline(mini, default_config(mini, rate), 1 / rate)
    rows = np.zeros(mini.nq)
    said = {True: (True, False), False: (False, True)}  # even frames left, odd frames right
    out = []
    for k in range(60):
        if k == 30:
            with pytest.raises(EstimatorError):
                pipe.step((k - 1) / rate, rows, contacts=(True, True))  # not after the last frame: refused
        out += [r for r in [pipe.step(k / rate, rows, contacts=said[k % 2 == 0])] if r is not None]
    out += pipe.flush()
    assert len(out) == 60 and [r.support for r in out] == ["left" if k % 2 == 0 else "right" for k in range(60)]
