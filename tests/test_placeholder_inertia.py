"""A URDF whose inertias are placeholders (THORMANG3's: diag(1, 1, 1) kg m^2 on 38 links, its 13 g grippers as its
6.9 kg pelvis) is told in one line at load, and in the summaries; the dynamics use it as written; robots whose
inertias are real are not told (livezmp.model.placeholder_inertia)."""

from __future__ import annotations

import json
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest
from data_paths import OP3_URDF
from humanoid_gen import HumanoidSpec, build_humanoid

from livezmp.cli import main
from livezmp.model.demo_robot import demo_robot_path
from livezmp.model.robot import load_robot

NOTE = "with a placeholder inertia"


def with_placeholders(src, dst, value: str = "1", links: set[str] | None = None) -> list[str]:
    """``src``'s URDF written to ``dst`` with ``links``' inertias (None: every link with a mass) set to
    diag(``value``) kg m^2, as THORMANG3's file writes them; the names of those links."""
    root = ET.parse(src).getroot()
    changed = []
    for link in root.findall("link"):
        inertia = link.find("inertial/inertia")
        if inertia is None or (links is not None and link.get("name") not in links):
            continue
        for k in ("ixx", "iyy", "izz"):
            inertia.set(k, value)
        for k in ("ixy", "ixz", "iyz"):
            inertia.set(k, "0")
        changed.append(link.get("name"))
    ET.ElementTree(root).write(dst)
    return changed


def told(path) -> tuple[list[str], tuple[str, ...], pin.Model]:
    """The placeholder notes of loading ``path`` (warnings), the body's placeholder links and its model."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        body = load_robot(str(path), None).body
    return [str(w.message) for w in caught if NOTE in str(w.message)], body.placeholder_inertias, body.model


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """A generated humanoid of THORMANG3's size (1.4 m, 45 kg): 1 kg m^2 is within what its whole body allows."""
    return build_humanoid(tmp_path_factory.mktemp("ph") / "gen.urdf", HumanoidSpec(height=1.4, mass=45.0, seed=80))


def test_placeholder_inertias_are_told_in_one_line_naming_them_and_used_as_written(generated, tmp_path):
    path = tmp_path / "placeholders.urdf"
    names = with_placeholders(generated, path)
    notes, links, model = told(path)
    assert len(names) > 10 and sorted(links) == sorted(names)
    assert len(notes) == 1 and "\n" not in notes[0]
    assert notes[0].startswith(f"{path}: {len(names)} links {NOTE}") and all(n in notes[0] for n in names)
    # the dynamics are not changed: the model has the file's inertias
    inertias = [model.inertias[j].inertia for j in range(1, model.njoints) if model.inertias[j].mass > 0]
    assert any(np.allclose(np.diag(i), 1.0) for i in inertias)


def test_a_round_value_on_a_heavy_link_is_told_where_lighter_links_share_it(generated, tmp_path):
    """1 kg m^2 on the torso alone is within what its size allows (not told); on the torso and the hands it is the
    hands' implausible value, and the torso, carrying the same, is told with them (THORMANG3's pelvis and chest)."""
    root = ET.parse(generated).getroot()
    masses = {link.get("name"): float(link.find("inertial/mass").get("value"))
              for link in root.findall("link") if link.find("inertial") is not None}
    heaviest = max(masses, key=masses.get)
    lightest = sorted(masses, key=masses.get)[:2]
    alone = tmp_path / "alone.urdf"
    with_placeholders(generated, alone, "1", {heaviest})
    assert told(alone)[:2] == ([], ())
    shared = tmp_path / "shared.urdf"
    with_placeholders(generated, shared, "1", {heaviest, *lightest})
    notes, links, _ = told(shared)
    assert len(notes) == 1 and sorted(links) == sorted([heaviest, *lightest])


@pytest.mark.parametrize("urdf", ["mini", "op3", "generated"])
def test_robots_whose_inertias_are_real_are_not_told(urdf, generated):
    path = {"mini": demo_robot_path(), "op3": OP3_URDF, "generated": generated}[urdf]
    assert told(path)[:2] == ([], ())


def test_analyze_and_demo_tell_it_once_and_put_it_in_their_summaries(generated, tmp_path):
    path = tmp_path / "placeholders.urdf"
    names = with_placeholders(generated, path)
    joints = told(path)[2].names[7:]  # the generated robot's joints, after the six of the base (and the universe)
    motion = tmp_path / "stand.csv"
    np.savetxt(motion, np.column_stack([np.arange(50) / 100, np.zeros((50, len(joints)))]), delimiter=",",
               header=",".join(["time", *joints]), comments="")
    for urdf, placeholders in ((path, names), (generated, [])):
        for argv in (["analyze", str(motion), "--robot", str(urdf)],
                     ["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "stand", "--duration", "0.2",
                      "--quiet", "--realtime-priority", "0"]):
            summary = tmp_path / "s.json"
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                assert main([*argv, "--summary-json", str(summary)]) == 0
            notes = [str(w.message) for w in caught if NOTE in str(w.message)]
            assert len(notes) == (1 if placeholders else 0), notes
            assert json.loads(summary.read_text())["placeholder_inertias"] == placeholders
