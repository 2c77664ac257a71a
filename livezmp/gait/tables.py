"""Output of ``gait analyze``: the paper-style tables as CSV, Markdown and JSON, a plot,
and the features JSON that ``gait synth`` reads.

Per variant: a posture table (DC changes) and a size table (amplitude changes), like
the paper's tables 1–3; one walk table with the frequency (the paper's "speed", common
to all joints), stride length and walking speed. CSV and JSON list every parameter;
the Markdown lists the feature parts as the paper does, then names the parameters whose
base value is near zero (no ratio computed).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from livezmp.errors import InputError
from livezmp.gait.population import WALK_PARAMS, ChangeStat, GaitAnalysis, VariantChange

STAT_COLUMNS = ["base", "variant", "mu_percent", "sigma_percent", "cv_percent", "feature", "note"]
KINDS = {"posture": ("dc", "DC (posture)"), "size": ("amplitude", "amplitude A (size)")}


def _stat_row(s: ChangeStat) -> list:
    return [s.base, s.variant, s.mu, s.sigma, s.cv, s.feature, s.note]


def channel_rows(a: GaitAnalysis, v: VariantChange, table: str) -> list[dict]:
    """Rows of the posture or size table of variant ``v`` (every channel)."""
    stats = getattr(v, KINDS[table][0])
    return [{"channel": t.name, "joint": t.joint, "kind": t.kind, "side": t.side, "axis": t.axis, "gimbal": t.gimbal,
             **dict(zip(STAT_COLUMNS, _stat_row(s), strict=True))} for t, s in zip(a.tags, stats, strict=True)]


def walk_rows(a: GaitAnalysis) -> list[dict]:
    """Rows of the walk table: frequency, stride length and speed of every variant."""
    return [{"label": v.label, "condition": v.condition, "parameter": k, "unit": WALK_PARAMS[k][0],
             **dict(zip(STAT_COLUMNS, _stat_row(s), strict=True))} for v in a.variants for k, s in v.walk.items()]


def _fmt(x) -> str:
    return "n/a" if x is None else f"{x:.1f}" if isinstance(x, float) else str(x)


def _markdown(a: GaitAnalysis) -> str:
    out = [f"# Gait analysis: variants against base condition \"{a.base}\"", "",
           f"Feature parts: |CV| ≤ {a.threshold:g} % and |μ| ≥ {a.min_change:g} %. "
           "K = (variant − base) / base × 100 %; μ, σ (1/J) and CV = σ/μ × 100 % over the J pairs. "
           "Angles in degrees; axis = world axis of rotation in the mean pose (paper's X = lateral, "
           "Y = vertical, Z = forward); † = Euler angle near gimbal lock (value not meaningful alone).", "",
           "## Walk frequency, stride length and speed", "",
           "| variant | parameter | base | variant | μ [%] | σ [%] | CV [%] | feature |",
           "|---|---|---|---|---|---|---|---|"]
    for r in walk_rows(a):
        out.append(f"| {r['label']} ({r['condition']}) | {r['parameter']} [{r['unit']}] | {r['base']:.3f} | "
                   f"{r['variant']:.3f} | {_fmt(r['mu_percent'])} | {_fmt(r['sigma_percent'])} | "
                   f"{_fmt(r['cv_percent'])} | {'yes' if r['feature'] else 'no'} |")
    for v in a.variants:
        for table, (_, title) in KINDS.items():
            rows = channel_rows(a, v, table)
            out += ["", f"## {v.label} ({v.condition}) vs {a.base}: {title}", "",
                    f"Pairing: {v.pairing} (J = {v.n_pairs}).", "",
                    "| channel | axis | base [°] | variant [°] | μ [%] | σ [%] | CV [%] |",
                    "|---|---|---|---|---|---|---|"]
            for r in rows:
                if r["feature"]:
                    mark = " †" if r["gimbal"] else ""
                    out.append(f"| {r['channel']}{mark} | {r['axis']} | {r['base']:.1f} | {r['variant']:.1f} | "
                               f"{_fmt(r['mu_percent'])} | {_fmt(r['sigma_percent'])} | {_fmt(r['cv_percent'])} |")
            zero = [r["channel"] for r in rows if r["mu_percent"] is None]
            if zero:
                out += ["", f"Not computed, base ≈ 0 (|base| < {a.min_base_deg:g}°, ratio meaningless): "
                        + ", ".join(zero) + "."]
            out += [f"{sum(r['feature'] for r in rows)} feature parts of {len(rows)} channels."]
    return "\n".join(out) + "\n"


def _plot(a: GaitAnalysis, path: Path) -> None:
    fig = Figure(figsize=(6 * len(a.variants), 12), layout="constrained")
    axes = fig.subplots(2, len(a.variants), squeeze=False)
    for col, v in enumerate(a.variants):
        for row, (table, (_, title)) in enumerate(KINDS.items()):
            rows = [r for r in channel_rows(a, v, table) if r["feature"]]
            ax = axes[row][col]
            y = list(range(len(rows)))
            ax.barh(y, [r["mu_percent"] for r in rows], xerr=[r["sigma_percent"] for r in rows], color="tab:blue")
            ax.set_yticks(y, [f"{r['channel']} ({r['axis'][0]})" for r in rows], fontsize=6)
            ax.invert_yaxis()
            ax.axvline(0, color="k", lw=0.5)
            ax.set_xlabel("μ ± σ of K [%]")
            ax.set_title(f"{v.label} vs {a.base}: {title}", fontsize=9)
    FigureCanvasAgg(fig).print_png(str(path))


def _write_csv(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def write_outputs(a: GaitAnalysis, out_dir: str | Path) -> list[Path]:
    """Write features.json, tables (CSV, tables.md, tables.json) and gait.png into ``out_dir``."""
    d = Path(out_dir)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{d}: cannot create output directory: {e.strerror}") from None
    written = []
    tables: dict[str, list[dict]] = {"walk": walk_rows(a)}
    for v in a.variants:
        for table in KINDS:
            tables[f"{v.label}_{table}"] = channel_rows(a, v, table)
    for name, rows in tables.items():
        _write_csv(d / f"{name}.csv", rows)
        written.append(d / f"{name}.csv")
    (d / "tables.json").write_text(json.dumps(tables, indent=1, ensure_ascii=False), encoding="utf-8")
    (d / "tables.md").write_text(_markdown(a), encoding="utf-8")
    (d / "features.json").write_text(json.dumps(a.to_json(), indent=1, ensure_ascii=False), encoding="utf-8")
    _plot(a, d / "gait.png")
    return written + [d / n for n in ("tables.json", "tables.md", "features.json", "gait.png")]


def read_features(path: str | Path) -> GaitAnalysis:
    """Read a features.json written by :func:`write_outputs`."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except OSError as e:
        raise InputError(f"{p}: cannot read: {e.strerror}") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{p}:{e.lineno}: not JSON: {e.msg}") from None
    return GaitAnalysis.from_json(data, str(p))
