"""A cluster set's landmarks from its static trial (``--static``; livezmp.model.static_trial)."""

from __future__ import annotations

import json

import ezc3d
import numpy as np
import pinocchio as pin
import pytest

from livezmp.cli import main
from livezmp.model.static_trial import read_walk
from tests.test_c3d_gaitlab import LEFT, PLATES, _cluster_markers, _markers, _points_c3d, write_lab_c3d

# standing positions (m, z up, facing +x; the right side mirrors the left) of a leg's cluster markers and medial
# landmarks, beside LEFT's standard markers; joint centres the segments turn about
CLUSTERS = {"TH1": (0.03, 0.15, 0.75), "TH2": (0.06, 0.12, 0.66), "TH3": (-0.03, 0.16, 0.62), "TH4": (0.0, 0.17, 0.7),
            "SK1": (0.03, 0.14, 0.36), "SK2": (0.05, 0.11, 0.26), "SK3": (-0.02, 0.14, 0.22)}
MEDIAL = {"KNM": (0.0, 0.04, 0.50), "MMA": (0.0, 0.05, 0.09)}
SEGMENT = {"ASI": "pelvis", "PSI": "pelvis", "TH1": "thigh", "TH2": "thigh", "TH3": "thigh", "TH4": "thigh",
           "KNE": "thigh", "KNM": "thigh", "SK1": "shank", "SK2": "shank", "SK3": "shank", "ANK": "shank",
           "MMA": "shank", "HEE": "foot", "TOE": "foot"}
JOINT = {"pelvis": (0.0, 0.0, 0.9), "thigh": (0.0, 0.08, 0.88), "shank": (0.0, 0.09, 0.50), "foot": (0.0, 0.09, 0.08)}
PARENT = {"thigh": "pelvis", "shank": "thigh", "foot": "shank"}
LANDMARKS = ("LKNE", "LKNM", "LANK", "LMMA", "RKNE", "RKNM", "RANK", "RMMA")


def _rot(axis: str, a: np.ndarray) -> np.ndarray:
    return np.array([pin.utils.rotate(axis, v) for v in a])


def _walk(t: np.ndarray) -> dict[str, np.ndarray]:
    """(F, 3) m per label: pelvis, thighs, shanks and feet each turning on its own (a chain walking along +x: the
    hips flexing 0.4 rad and abducting, the knees flexing up to 1 rad, the ankles 0.25 rad), so that each cluster
    carries its own segment's landmarks only."""
    w = 2 * np.pi * t
    out = {}
    for side, sign in (("L", 1.0), ("R", -1.0)):
        rel = {"pelvis": _rot("z", 0.1 * np.sin(w)) @ _rot("x", 0.05 * np.sin(2 * w)),
               "thigh": _rot("y", sign * 0.4 * np.sin(w)) @ _rot("x", 0.08 * np.sin(w + 1)),
               "shank": _rot("y", 0.5 * (1 - np.cos(w + sign))),
               "foot": _rot("y", -0.25 * np.sin(w))}
        pose = {"pelvis": (rel["pelvis"], np.column_stack([0.8 * t, 0 * t, 0.9 + 0.02 * np.sin(2 * w)]))}
        for seg in ("thigh", "shank", "foot"):
            r, o = pose[PARENT[seg]]
            j = np.array(JOINT[seg]) * (1, sign, 1) - np.array(JOINT[PARENT[seg]]) * (1, sign, 1)
            pose[seg] = (r @ rel[seg], o + r @ j)
        for name, seg in SEGMENT.items():
            p = {**LEFT, **CLUSTERS, **MEDIAL}[name]
            local = np.array(p) * (1, sign, 1) - np.array(JOINT[seg]) * (1, sign, 1)
            r, o = pose[seg]
            out[side + name] = o + r @ local
    return out


def _pair(tmp_path, static_change: dict | None = None):
    """A static trial (standing still, every marker) and a walk (the clusters, pelvis and feet only), as C3Ds;
    the walk's true landmarks. ``static_change``: label -> (3,) m moved in the static trial only."""
    walk = _walk(np.arange(300) / 100.0)
    static = {k: np.repeat(v[:1], 20, axis=0) for k, v in _walk(np.zeros(1)).items()}
    for label, d in (static_change or {}).items():
        static[label] = static[label] + d
    walk["LTH4"][100:140] = np.nan  # a cluster marker lost for a while: the other three carry the knee
    truth = {k: walk.pop(k) for k in LANDMARKS}
    return _points_c3d(tmp_path / "walk.c3d", walk), _points_c3d(tmp_path / "static.c3d", static), truth


def test_landmarks_are_carried_by_their_segments_clusters(tmp_path):
    """Each knee landmark rides its thigh's cluster, each malleolus its shank's, through a walk whose segments
    turn each on its own: the true landmarks to 1e-6 m in every frame (also where a 4-marker cluster sees 3)."""
    walk_path, static_path, truth = _pair(tmp_path)
    walk = read_walk(walk_path, static_path)
    assert sorted(walk.from_static["landmarks"]) == sorted(LANDMARKS)
    assert walk.from_static["landmarks"]["LKNE"] == "thigh_l: LTH1 LTH2 LTH3 LTH4"
    assert walk.from_static["landmarks"]["RMMA"] == "shank_r: RSK1 RSK2 RSK3"
    for label, xyz in truth.items():
        assert np.abs(walk.marker(label) - xyz).max() < 1e-6, label


def _lab_pair(tmp_path, static_change: dict | None = None, drop: tuple[str, ...] = ()):
    """The synthetic lab's walk (its plates from the body's exact dynamics) with thigh and shank clusters and its
    knee and ankle markers unseen, and a static trial of the same markers standing, ``static_change`` label -> (3,)
    m moved in it, ``drop`` left out of it."""
    path = tmp_path / "lab.c3d"
    write_lab_c3d(path, PLATES)
    c3d = ezc3d.c3d(str(path))
    labels = [s.split(":")[-1] for s in c3d["parameters"]["POINT"]["LABELS"]["value"]]
    pts = np.array(c3d["data"]["points"])
    res = np.array(c3d["data"]["meta_points"]["residuals"])
    std = {lab: pts[:3, i].T for i, lab in enumerate(labels)}
    clusters = {k: v for k, v in _cluster_markers(std).items() if k[1:3] in ("TH", "SK")}
    for i, lab in enumerate(labels):
        if lab[1:] in ("KNE", "ANK"):
            pts[:3, i], res[0, i] = 0.0, -1.0
    pts = np.concatenate([pts, np.ones((4, len(clusters), pts.shape[2]))], axis=1)
    pts[:3, len(labels):] = np.stack(list(clusters.values()), axis=1).transpose(2, 1, 0)
    c3d["data"]["points"] = pts
    c3d["data"]["meta_points"] = {"residuals": np.concatenate([res, np.ones((1, len(clusters), res.shape[2]))], 1)}
    c3d["parameters"]["POINT"]["LABELS"]["value"] = labels + list(clusters)
    walk = tmp_path / "walk.c3d"
    c3d.write(str(walk))
    stand = _markers(np.linspace(0.0, 0.2, 20))  # swaying a little as it stands
    stand = {**stand, **{k: v for k, v in _cluster_markers(stand).items() if k[1:3] in ("TH", "SK")}}
    for label, d in (static_change or {}).items():
        stand[label] = stand[label] + d
    return walk, _points_c3d(tmp_path / "static.c3d", {k: v for k, v in stand.items() if k not in drop})


def test_a_cluster_walk_with_its_static_trial_meets_its_plates(tmp_path, capsys):
    """Refused without the static trial in one line that names --static; with it the knee and ankle markers are
    carried from the static trial, the summary says which, and the ZMP meets the plates' CoP within a millimetre."""
    walk, static = _lab_pair(tmp_path)
    assert main(["analyze", str(walk)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "missing LKNE (never seen)" in err and "--static STATIC.c3d" in err
    out = tmp_path / "s.json"
    assert main(["analyze", str(walk), "--static", str(static), "--summary-json", str(out)]) == 0
    assert "from the static trial static.c3d, carried by their clusters: LANK, LKNE, RANK, RKNE" in \
        capsys.readouterr().out
    s = json.loads(out.read_text())
    assert s["markers"]["from_static_trial"]["landmarks"]["LKNE"].startswith("thigh_l: ")
    assert s["cop_vs_zmp"]["frames"] > 250 and s["cop_vs_zmp"]["max_mm"] < 1.0


@pytest.mark.parametrize(("change", "drop", "says"), [
    ({"LTH2": np.array([0.0, 0.0, 0.02])}, (), "left thigh's cluster"),  # placed again: 20 mm lower
    ({}, ("LTH2", "LTH3", "LTHI"), "no 3 markers it shares with"),
])
def test_a_static_trial_not_matching_the_walks_clusters_is_refused_in_one_line(tmp_path, capsys, change, drop,
                                                                                says):
    walk, static = _lab_pair(tmp_path, change, drop)
    assert main(["analyze", str(walk), "--static", str(static)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(static) in err and says in err and "left thigh" in err


def test_monitor_replays_a_cluster_walk_with_its_static_trial_and_others_refuse_it(tmp_path, capsys):
    """`monitor` of a C3D takes --static as `analyze` does (its recording replays the same analysis); with no C3D
    (the demo robot) --static is refused in one line, as by `analyze`."""
    walk, static = _lab_pair(tmp_path)
    rec = tmp_path / "r.mcap"
    assert main(["monitor", str(walk), "--static", str(static), "--speed", "0", "--record", str(rec)]) == 0
    assert "370 frames in, 370 analysed" in capsys.readouterr().out
    assert main(["replay", str(rec)]) == 0
    assert "same analysis" in capsys.readouterr().out
    for command in ("monitor", "analyze"):
        assert main([command, "--static", str(static)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--static is for" in err
