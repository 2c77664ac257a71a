"""`livezmp calibrate`: a subject's head-arms-trunk (or tracked thorax) parameters from force-plate trials, written
to a subject file that `livezmp analyze --subject` uses (see :mod:`livezmp.offline.calibrate`)."""

from __future__ import annotations

import argparse

from livezmp.checks import check_number, check_output_paths, given_inputs
from livezmp.model.anthropometry import MAX_AGE_YEARS, MAX_BODY_MASS
from livezmp.model.marker_map import load_marker_map
from livezmp.model.markers import MarkerBodyOptions
from livezmp.model.static_trial import read_walk
from livezmp.offline.calibrate import calibrate, write_subject
from livezmp.offline.gaitlab import LabOptions


def cmd_calibrate(args: argparse.Namespace) -> int:
    check_output_paths((args.output, "-o"), inputs=given_inputs(args))
    check_number(args.age, "--age (years)", 0.0, MAX_AGE_YEARS, lo_open=True)
    check_number(args.mass, "--mass (kg)", 0.0, MAX_BODY_MASS, lo_open=True)
    trials = [read_walk(p, args.static) for p in args.trials]
    markers = MarkerBodyOptions(marker_map=load_marker_map(args.markers) if args.markers else None, bsp=args.bsp,
                                age_years=args.age)
    subject, report = calibrate(trials, LabOptions(mass=args.mass, markers=markers))
    write_subject(subject, args.output, report)
    for note in report["mass_notes"]:
        print(f"  mass: {note}")
    fwd, left, up = (1000 * v for v in subject.offset)
    if subject.segment == "thorax":
        print(f"{args.output}: thorax (tracked) {100 * subject.fraction:.1f} % of the mass, centre of mass "
              f"{fwd:+.0f} mm forward, {left:+.0f} mm left, {up:+.0f} mm up the trunk from its origin")
    else:
        print(f"{args.output}: HAT {100 * subject.fraction:.1f} % of the mass, centre of mass {fwd:+.0f} mm forward, "
              f"{left:+.0f} mm left, {up:.0f} mm above the mid-hip, swaying {subject.hat_sway_gain[0]:.2f} "
              f"(fore-aft) and {subject.hat_sway_gain[1]:.2f} (lateral) times the mid-hip above "
              f"{subject.hat_follow_hz:g} Hz")
    print(f"  ZMP vs CoP RMS over {report['frames']} frames: table {report['rms_table_mm']:.1f} mm, fitted "
          f"{report['rms_fitted_mm']:.1f} mm; held out ({report['folds']}): table "
          f"{report['rms_held_out_table_mm']:.1f} mm, calibrated {report['rms_held_out_fitted_mm']:.1f} mm")
    if "rms_other_trials_fitted_mm" in report:  # several trials: held out is each with the others' calibration
        if report["rms_other_trials_fitted_mm"] > report["rms_other_trials_table_mm"]:
            print("  the others' calibration is worse than the table on the trials it did not see: "
                  "are these takes of one subject?")
    print("  unconstrained (prior off, scored on the frames it is fitted on): "
          f"{report['rms_fitted_unconstrained_mm']:.1f} mm, the least any {subject.segment} parameters reach on "
          "these trials")
    if report["table_kept"]:
        print("  the table's values are kept: no prior weight's fit beat the table on held-out frames both ways round")
        return 0
    sd = dict(zip(report["parameters"], report["parameter_sd"], strict=True))
    print(f"  prior weight {report['prior_weight']:g} (chosen by cross-validation); standard errors (jackknife over "
          f"the blocks): fraction {100 * sd[report['parameters'][0]]:.1f} %, forward/left/up "
          f"{1000 * sd['forward']:.0f}/{1000 * sd['left']:.0f}/{1000 * sd['up']:.0f} mm"
          + (f", sway {sd['sway_fore_aft']:.2f}/{sd['sway_lateral']:.2f}" if "sway_fore_aft" in sd else ""))
    if report["rms_held_out_fitted_mm"] >= report["rms_held_out_table_mm"]:
        print("  the fit does not beat the table on held-out frames: more plate trials are needed")
    return 0
