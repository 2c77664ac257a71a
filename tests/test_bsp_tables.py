"""Body-segment tables: de Leva's adult table and the child table (Jensen's proportions), chosen from the
file's age or height, tested on a synthetic child walking in the synthetic gait lab."""

from __future__ import annotations

import json

import pytest

from livezmp.cli import main
from livezmp.errors import InputError
from livezmp.model.anthropometry import (
    DE_LEVA_MALE,
    JENSEN_MASS_PERCENT,
    age_for_stature,
    child_segments,
    choose_table,
)
from livezmp.model.markers import TRUNK_FOLLOW_HZ, TRUNK_STEP_GAIN, MarkerBodyOptions
from livezmp.offline.calibrate import load_subject
from tests.test_c3d_gaitlab import C3D, PLATES, Lab, write_lab_c3d


def _total(table) -> float:
    return sum(p.mass_fraction * (1 if k == "head" or k.endswith("trunk") else 2) for k, p in table.items())


def test_child_table_is_de_leva_at_adult_age_and_follows_jensens_changes():
    adult = child_segments(18.0)
    assert {k: p.mass_fraction for k, p in adult.items()} == pytest.approx(
        {k: p.mass_fraction for k, p in DE_LEVA_MALE.items()}, abs=1e-12)
    for age in (4.0, 6.0, 9.0, 12.0, 15.0):
        assert _total(child_segments(age)) == pytest.approx(1.0, abs=1e-12)
    six, j6, j18 = child_segments(6.0), JENSEN_MASS_PERCENT[6.0], JENSEN_MASS_PERCENT[18.0]
    # head over thigh changes as Jensen's does between 6 and 18 (the renormalisation cancels in a ratio)
    ratio = (six["head"].mass_fraction / six["thigh"].mass_fraction) / (
        DE_LEVA_MALE["head"].mass_fraction / DE_LEVA_MALE["thigh"].mass_fraction)
    assert ratio == pytest.approx((j6["head"] / j6["thigh"]) / (j18["head"] / j18["thigh"]), rel=1e-12)
    assert six["head"].mass_fraction > 2.3 * DE_LEVA_MALE["head"].mass_fraction  # 17 % of a 6-year-old
    assert six["shank"].com_fraction == DE_LEVA_MALE["shank"].com_fraction


def test_table_is_chosen_from_what_the_file_says():
    assert choose_table("auto", 9.0, 1.75, 1.7).name == "child"  # the age wins over a height
    assert choose_table("auto", 30.0, 1.30, 1.3).name == "adult"
    child = choose_table("auto", None, 1.16, 1.0)
    assert child.name == "child" and child.age_years == pytest.approx(6.0) and "height 1.16 m" in child.reason
    assert choose_table("auto", None, 1.50, 1.5).name == "adult"  # a short adult stays adult
    none = choose_table("auto", None, None, 1.2)
    assert none.name == "adult" and "no age or height" in none.reason
    assert choose_table("child", None, None, 1.50).age_years == pytest.approx(age_for_stature(1.50)) == 12.0
    assert choose_table("adult", 7.0, 1.2, 1.2).name == "adult"


def test_reason_says_whose_age_and_when_the_table_is_held_at_its_youngest():
    toddler = choose_table("child", 2.0, None, 0.88, "the given")
    assert "the given age 2 years" in toddler.reason and "held at Jensen's youngest, 6 years" in toddler.reason
    assert toddler.segments == child_segments(6.0)  # what "held" means
    assert "held" not in choose_table("auto", 9.0, None, 1.3).reason
    assert "the file's age 9 years" in choose_table("auto", 9.0, None, 1.3).reason


def _bias(path, tmp_path, *extra) -> dict:
    out = tmp_path / "s.json"
    assert main(["analyze", str(path), "--summary-json", str(out), "--out", str(tmp_path / "z.csv"), *extra]) == 0
    return json.loads(out.read_text())


def test_a_synthetic_child_needs_the_child_table(tmp_path):
    path = tmp_path / "child.c3d"
    # a 1.20 m child (about 6.7 years) whose plates carry the child table's dynamics exactly
    write_lab_c3d(path, PLATES, body=MarkerBodyOptions(bsp="child"), trunk="top", lab=Lab(height_m=1.20, seconds=3.0))
    auto = _bias(path, tmp_path)
    assert auto["markers"]["bsp"]["table"] == "child" and "height 1.20 m" in auto["markers"]["bsp"]["reason"]
    assert auto["cop_vs_zmp"]["max_mm"] < 1.0
    adult = _bias(path, tmp_path, "--bsp", "adult")
    assert adult["markers"]["bsp"]["reason"] == "asked for (--bsp adult)"
    assert adult["cop_vs_zmp"]["rms_mm"] > 5.0  # the adult table on a child: a measurable error


def test_the_table_options_are_for_c3d_bodies(capsys):
    for argv in (["analyze", "--bsp", "child"], ["analyze", "--age", "8"],
                 ["monitor", "--speed", "0", "--bsp", "adult"],
                 ["analyze", str(C3D / "cgm24_walking01_forceplate.c3d"), "--age", "-3"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and ("--bsp" in err or "--age" in err)


def test_a_subject_file_names_its_table_unless_the_command_line_does(tmp_path):
    path = tmp_path / "subject.toml"
    path.write_text('[subject]\nhat_fraction = 0.5\nhat_offset_m = [0.0, 0.0, 0.3]\nbsp = "child"\nage_years = 8\n')
    subject = load_subject(path)
    opts = subject.marker_options()
    assert (opts.bsp, opts.age_years, opts.hat_fraction) == ("child", 8.0, 0.5)
    assert subject.marker_options(MarkerBodyOptions(bsp="adult", age_years=30.0)).bsp == "adult"
    # written before calibrate fitted the follow frequency: read with the default's (its gains then sway above it)
    assert (opts.hat_sway_gain, opts.hat_follow_hz) == (TRUNK_STEP_GAIN, TRUNK_FOLLOW_HZ)
    path.write_text('[subject]\nhat_fraction = 0.5\nhat_offset_m = [0.0, 0.0, 0.3]\nhat_follow_hz = 0.5\n')
    assert load_subject(path).marker_options().hat_follow_hz == 0.5
    # a misspelt key had been ignored (the table's value used in its place)
    for line, field in (('bsp = "toddler"', "subject.bsp"), ("age_years = -1", "subject.age_years"),
                        ("hat_sway_gains = [0.5, 0.5]", "subject.hat_sway_gains: unknown key"),
                        *((f"hat_follow_hz = {v}", "subject.hat_follow_hz") for v in ("0", "-1", "6", '"1"', "true"))):
        path.write_text(f'[subject]\nhat_fraction = 0.5\nhat_offset_m = [0.0, 0.0, 0.3]\n{line}\n')
        with pytest.raises(InputError, match=field):
            load_subject(path)


@pytest.mark.parametrize(("line", "field"), [
    ("hat_follow_hz = 1e-300", "subject.hat_follow_hz"),  # before: scipy's LinAlgError traceback in the analysis
    ("hat_follow_hz = 0.001", "subject.hat_follow_hz"),
    ("hat_fraction = 0.99999", "subject.hat_fraction"),  # before: each of these analysed without a word
    ("hat_offset_m = [true, false, true]", r"subject.hat_offset_m\[0\] \(forward\)"),
    ("hat_offset_m = [0.0, 0.0, 1.4]", r"subject.hat_offset_m\[2\] \(up\)"),
    ("hat_sway_gain = [true, 0.5]", r"subject.hat_sway_gain\[0\] \(fore_aft\)"),
    ("age_years = true", "subject.age_years"),
])
def test_a_subject_file_is_held_to_numbers_calibrate_can_fit(tmp_path, line, field):
    fields = {"hat_fraction": "0.5", "hat_offset_m": "[0.0, 0.0, 0.3]"}
    key, _, value = line.partition(" = ")
    path = tmp_path / "subject.toml"
    path.write_text("[subject]\n" + "".join(f"{k} = {v}\n" for k, v in {**fields, key: value}.items()))
    with pytest.raises(InputError, match=field):
        load_subject(path)


def test_a_tracked_trunks_subject_file_is_held_to_its_own_range(tmp_path):
    path = tmp_path / "subject.toml"
    path.write_text("[subject]\ntrunk_fraction = 0.35\ntrunk_offset_m = [0.0, 0.0, 1.4]\n")  # before: read
    with pytest.raises(InputError, match=r"subject.trunk_offset_m\[2\] \(up\) must be a number from -0.45 to 0"):
        load_subject(path)
