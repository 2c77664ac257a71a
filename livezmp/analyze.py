"""`livezmp analyze`: run the per-frame pipeline over a motion file and write the results."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

from livezmp.body_bvh import BvhBodyOptions
from livezmp.body_urdf import UrdfBodyOptions, body_from_urdf
from livezmp.contacts import ContactConfig
from livezmp.demo import demo_robot_path, demo_trajectory
from livezmp.errors import InputError
from livezmp.motion_file import LoadedMotion, load_motion, trajectory_frames
from livezmp.pipeline import Pipeline, PipelineConfig
from livezmp.plot import plot_analysis
from livezmp.report import summarize, write_json, write_zmp_csv
from livezmp.segments import load_mapping

PROGRESS_MIN_FRAMES = 5000


def add_body_options(p: argparse.ArgumentParser) -> None:
    """Options shared by every command that loads a motion."""
    p.add_argument("--robot", help="URDF of the robot (for a joint-trajectory CSV)")
    p.add_argument("--robot-config", help="robot config TOML (default: beside the URDF, or built in)")
    p.add_argument("--mass", type=float, default=70.0, help="total body mass for a BVH skeleton, kg (default 70)")
    p.add_argument("--units", choices=["m", "cm", "mm", "in"], help="BVH length unit (default: detected)")
    p.add_argument("--up", choices=["y", "z"], help="BVH up axis (default: detected)")
    p.add_argument("--mapping", help="TOML file mapping unknown joint names to segments")
    p.add_argument("--sole-width", type=float, help="sole width for a BVH skeleton, m (default 5.5%% of stature)")
    p.add_argument("--ground", type=float, help="ground height in the input frame, m (default: detected)")
    p.add_argument("--mode", choices=["full", "seed"], default="full",
                   help="ZMP of rigid segments (full) or point masses as in the seed paper (seed)")


def load_from_args(args: argparse.Namespace) -> LoadedMotion:
    """The motion named on the command line, or the built-in demo when there is none."""
    urdf_opts = UrdfBodyOptions(config=args.robot_config)
    if args.motion is None:
        body = body_from_urdf(demo_robot_path(), urdf_opts)
        traj = demo_trajectory(body.joint_names)
        return LoadedMotion(body, traj.t, trajectory_frames(body, traj), "<demo>", trajectory=traj)
    mapping = load_mapping(args.mapping) if args.mapping else None
    bvh_opts = BvhBodyOptions(total_mass=args.mass, units=args.units, up_axis=args.up, mapping=mapping,
                              sole_width=args.sole_width)
    return load_motion(args.motion, args.robot, bvh_opts, urdf_opts)


def pipeline_config(args: argparse.Namespace, loaded: LoadedMotion) -> PipelineConfig:
    contacts = ContactConfig.small_robot() if loaded.body.kind == "urdf" else ContactConfig()
    # debounce contacts over ~1/60 s whatever the frame rate (one frame at 30 Hz, two at 120 Hz)
    contacts = replace(contacts, min_frames=max(1, round(loaded.fps / 60)))
    cfg = PipelineConfig(mode=args.mode, contacts=contacts)
    if args.ground is not None:
        up = "xyz".index(loaded.body.up_axis)
        p = np.zeros(3)
        p[up] = args.ground
        cfg = replace(cfg, ground_z=float((loaded.body.world_from_input @ p)[2]))
    return cfg


def run_pipeline(loaded: LoadedMotion, cfg: PipelineConfig, progress: bool = False) -> list:
    """All frames of ``loaded`` through one :class:`Pipeline`; a progress bar if asked."""
    dt = 1.0 / loaded.fps if loaded.fps > 0 else None
    pipe = Pipeline(loaded.body, cfg, nominal_dt=dt)
    if not progress:
        return pipe.run(loaded.times, loaded.frames)
    from rich.progress import Progress

    out = []
    with Progress(transient=True) as bar:
        task = bar.add_task("analysing", total=len(loaded.frames))
        for k in range(len(loaded.frames)):
            r = pipe.step(float(loaded.times[k]), loaded.frames[k])
            if r is not None:
                out.append(r)
            if k % 500 == 0:
                bar.update(task, completed=k)
    return out + pipe.flush()


def cmd_analyze(args: argparse.Namespace) -> int:
    loaded = load_from_args(args)
    if len(loaded.frames) < 2:
        raise InputError(f"{loaded.source}: need at least 2 frames, got {len(loaded.frames)}")
    cfg = pipeline_config(args, loaded)
    show = len(loaded.frames) >= PROGRESS_MIN_FRAMES and sys.stderr.isatty()
    results = run_pipeline(loaded, cfg, progress=show)
    summary = {"source": loaded.source, **summarize(loaded.body, results, loaded.fps, cfg.mode)}
    if args.out:
        write_zmp_csv(loaded.body, results, args.out)
    if args.summary_json:
        write_json(summary, args.summary_json)
    if args.plot:
        plot_analysis(loaded.body, results, args.plot, title=f"{loaded.source} ({cfg.mode} ZMP)")
    inside = summary["inside_fraction"]
    print(f"{loaded.source}: {summary['frames']} frames at {summary['fps']:.1f} Hz, "
          f"{summary['support_frames']} with support, {summary['flight_frames']} flight, "
          f"{summary['out_of_support_frames']} out of support, inside "
          f"{'n/a' if inside is None else f'{100 * inside:.1f} %'}, "
          f"max excursion {1000 * summary['max_excursion_m']:.1f} mm")
    return 0


def add_analyze_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("analyze", help="ZMP, support and balance of a motion file (BVH, or CSV + URDF)")
    p.add_argument("motion", nargs="?", help="motion file (.bvh, or .csv with --robot); default: built-in demo")
    p.add_argument("--out", help="per-frame CSV (zmp.csv)")
    p.add_argument("--summary-json", help="summary JSON")
    p.add_argument("--plot", help="figure (PNG)")
    add_body_options(p)
    p.set_defaults(func=cmd_analyze)
