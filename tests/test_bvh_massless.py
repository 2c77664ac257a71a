"""Skeletons whose face, finger and toe-tip joints carry no mass: the body is built on the joints that carry or lead
to a segment's mass, and every consumer reads the file's rows through the same column map (the cgspeed
"Daz-friendly" CMU conversions with MakeHuman's face, 498 channels, e.g. AmmarkoV/RGBDAcquisition's Motions/02_03.bvh,
were refused for the model's 256-channel limit)."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from livezmp.cli import main
from livezmp.errors import InputError
from livezmp.model.bvh import BvhJoint, BvhMotion, read_bvh, write_bvh
from livezmp.model.bvh_body import body_from_bvh
from livezmp.sources.factory import SourceOptions, open_source
from livezmp.sources.frame_format import WireFrame, encode_json

ROT = ["Zrotation", "Xrotation", "Yrotation"]
FRAMES, DT = 90, 1 / 30


def _add(joints: list[BvhJoint], name: str, parent: int, offset, channels=ROT, end=None) -> int:
    joints.append(BvhJoint(name, parent, np.array(offset, float), list(channels),
                           None if end is None else np.array(end, float)))
    if parent >= 0:
        joints[parent].children.append(len(joints) - 1)
    return len(joints) - 1


def skeleton(massless: bool) -> list[BvhJoint]:
    """A humanoid in cm, y up, with arms; with ``massless`` its head carries a face (50 joints), each hand five
    three-joint fingers and each foot two more toes (of two joints) beside its ToeBase: 324 channels, 60 of them
    the model's. Without, the head and hands end in End Sites where their longest child began (the segments keep
    their shapes)."""
    js: list[BvhJoint] = []
    hips = _add(js, "Hips", -1, [0, 0, 0], ["Xposition", "Yposition", "Zposition", *ROT])
    spine = _add(js, "Spine", hips, [0, 10, 0])
    head = _add(js, "Head", spine, [0, 50, 0], end=None if massless else [0, 20, 0])
    if massless:
        for k in range(25):
            face = _add(js, f"face{k:02d}", head, [0, 20, 0] if k == 0 else [k % 5 - 2, 8, 6])
            _add(js, f"face{k:02d}b", face, [0, 1, 1], end=[0, 1, 0])
    for side, sx in (("Left", 1), ("Right", -1)):
        collar = _add(js, f"{side}Shoulder", spine, [sx * 5, 45, 0])
        arm = _add(js, f"{side}Arm", collar, [sx * 12, 0, 0])
        fore = _add(js, f"{side}ForeArm", arm, [sx * 28, 0, 0])
        hand = _add(js, f"{side}Hand", fore, [sx * 25, 0, 0], end=None if massless else [sx * 10, 0, 0])
        if massless:
            for f, name in enumerate(("Middle", "Thumb", "Index", "Ring", "Pinky")):
                j = _add(js, f"{side}Hand{name}1", hand, [sx * 10, 0, 0] if f == 0 else [sx * 8, 0, f - 2])
                j = _add(js, f"{side}Hand{name}2", j, [sx * 3, 0, 0])
                _add(js, f"{side}Hand{name}3", j, [sx * 2, 0, 0], end=[sx * 2, 0, 0])
    for side, sx in (("Left", 10), ("Right", -10)):
        thigh = _add(js, f"{side}UpLeg", hips, [sx, -5, 0])
        shank = _add(js, f"{side}Leg", thigh, [0, -42, 0])
        foot = _add(js, f"{side}Foot", shank, [0, -43, 0])
        _add(js, f"{side}ToeBase", foot, [0, -6, 12], end=[0, 0, 5])
        if massless:
            for k in (2, 3):
                toe = _add(js, f"{side}Toe{k}", foot, [k - 1, -6, 10])
                _add(js, f"{side}Toe{k}Tip", toe, [0, 0, 2], end=[0, 0, 1])
    first = 0
    for j in js:
        j.first_channel, first = first, first + len(j.channels)
    return js


def motion(massless: bool) -> BvhMotion:
    """A take swaying over its feet, its trunk swinging ±8° (its ZMP leaves the feet), its arms ±12°; the massless
    joints move at random (one face joint, flexed to 89°, near gimbal lock). The joints both skeletons have move alike
    in both."""
    joints = skeleton(massless)
    bare = {j.name for j in skeleton(False)}
    t = np.arange(FRAMES) * DT
    cols = []
    for j in joints:
        for c in j.channels:
            if j.name not in bare:
                cols.append(np.random.default_rng(sum(map(ord, j.name + c))).uniform(-40, 40, FRAMES))
            elif c == "Yposition":
                cols.append(np.full(FRAMES, 96.0))
            elif c.endswith("position"):
                cols.append(3 * np.sin(2 * np.pi * 0.8 * t) if c[0] == "X" else np.zeros(FRAMES))
            else:
                phase = sum(map(ord, j.name + c)) % 7
                amplitude = 8 if j.name + c == "SpineXrotation" else 12 if "Arm" in j.name else 1
                cols.append(amplitude * np.sin(2 * np.pi * 0.8 * t + phase))
    frames = np.column_stack(cols)
    if massless:
        face = next(j for j in joints if j.name == "face03")
        frames[:, face.first_channel + 1] = 89.0
    return BvhMotion(joints, DT, frames)


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    d = tmp_path_factory.mktemp("massless")
    paths = {k: d / f"{k}.bvh" for k in ("full", "bare")}
    write_bvh(motion(True), paths["full"])
    write_bvh(motion(False), paths["bare"])
    return paths


def test_the_massless_subtrees_are_dropped_and_the_zmp_is_the_bare_takes(takes, tmp_path):
    full, bare = read_bvh(takes["full"]), read_bvh(takes["bare"])
    assert full.n_channels == 324 > 256
    body = body_from_bvh(full)
    assert body.nq == bare.n_channels == 60 and body.channel_names == bare.channel_labels()
    zmp = {}
    for k, path in takes.items():
        out = tmp_path / f"{k}.csv"
        assert main(["analyze", str(path), "--out", str(out)]) == 0
        zmp[k] = np.genfromtxt(out, delimiter=",", names=True)
    for name in ("zmp_x", "zmp_y", "com_x", "com_y", "com_z"):
        assert np.nanmax(np.abs(zmp["full"][name] - zmp["bare"][name])) < 1e-9, name


def test_correct_writes_every_joint_back(takes, tmp_path):
    out = tmp_path / "corrected.bvh"
    assert main(["correct", str(takes["full"]), "-o", str(out)]) == 0
    before, after = read_bvh(takes["full"]), read_bvh(out)
    assert [j.name for j in after.joints] == [j.name for j in before.joints]
    kept = body_from_bvh(before).input_columns
    dropped = np.setdiff1d(np.arange(before.n_channels), kept)
    assert np.array_equal(after.frames[:, dropped], before.frames[:, dropped])  # the face, at 89° too
    assert np.abs(after.frames[:, kept] - before.frames[:, kept]).max() > 0.01  # it corrected something


def test_replay_and_live_streams_read_the_files_rows(takes):
    full, bare = open_source(str(takes["full"])), open_source(str(takes["bare"]))
    first = [s.read(1.0).channels for s in (full, bare)]
    for s in (full, bare):
        s.close()
    assert np.array_equal(first[0], first[1])
    rows = read_bvh(takes["full"]).frames
    src = open_source("udp://127.0.0.1:0", SourceOptions(skeleton=str(takes["full"])))
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            tx.sendto(encode_json(WireFrame(0, 0.0, rows[0])), ("127.0.0.1", src.port))
            frame = src.read(2.0)
    finally:
        src.close()
    assert frame is not None and np.array_equal(frame.channels, first[1])


def test_a_massive_part_over_the_limit_is_refused_in_one_line(tmp_path, capsys):
    """90 spine joints each carry part of the trunk's mass: their 270 channels are the model's."""
    js: list[BvhJoint] = []
    k = _add(js, "Hips", -1, [0, 0, 0], ["Xposition", "Yposition", "Zposition", *ROT])
    for n in range(90):
        k = _add(js, f"Spine{n}", k, [0, 0.5, 0])
    _add(js, "Head", k, [0, 10, 0], end=[0, 20, 0])
    for side, sx in (("Left", 10), ("Right", -10)):
        k = _add(js, f"{side}UpLeg", 0, [sx, -5, 0])
        k = _add(js, f"{side}Leg", k, [0, -42, 0])
        _add(js, f"{side}Foot", k, [0, -43, 0], end=[0, -6, 12])
    first = 0
    for j in js:
        j.first_channel, first = first, first + len(j.channels)
    path = tmp_path / "spines.bvh"
    write_bvh(BvhMotion(js, DT, np.zeros((3, first))), path)
    with pytest.raises(InputError, match=r"spines.bvh: 297 channels carry or lead to a segment's mass, more than "
                                         r"the 256 this tool analyses"):
        body_from_bvh(read_bvh(path))
    capsys.readouterr()
    assert main(["analyze", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "297 channels carry or lead" in err[0], err
