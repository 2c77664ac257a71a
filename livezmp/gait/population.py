"""Changes common across people: K, μ, σ, CV and the feature parts (paper 003, §2.3–2.4).

For parameter i and pair j (a subject, or a variant take when subjects are unknown):
K_ij = (V_ij − G_ij) / G_ij × 100 %, with G the base (e.g. normal) value and V the
variant's (slow or fast); μ_i and σ_i are the mean and population standard deviation
(1/J) of K_ij over j, CV_i = σ_i / μ_i × 100 % (it takes μ's sign, as in the paper), and
a parameter is a *feature part* when |CV_i| ≤ the threshold (paper: 250 %). We also
require |μ_i| ≥ a minimum change (default 1 %; 0 follows the paper exactly): a change
of a few millionths of a percent is no change, yet its CV can be anything.

Pairing is never silent: with subjects known, each subject's variant takes are paired
with the same subject's base takes (several takes of one condition are averaged);
without subjects, each variant take is paired with the mean over all base takes. Where
a base value is near zero the ratio is meaningless, and the parameter is reported as
such instead of a huge number.

Angles (DC, amplitude) are stored in degrees, frequency in Hz, stride length in m,
speed in m/s. DCs of different takes are first put on the same Euler branch (whole
turns added to match the first base take).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from livezmp.errors import InputError
from livezmp.gait.channels import ChannelTag
from livezmp.gait.features import WalkFeatures
from livezmp.gait.takeset import TakeSpec

FORMAT = "livezmp-gait-features"
WALK_PARAMS = {"frequency": ("Hz", 1e-6), "stride_length": ("m", 1e-3), "speed": ("m/s", 1e-3)}


@dataclass
class ChangeStat:
    """One parameter's change over J pairs: mean ``base``/``variant`` values, K per pair (%),
    μ, σ, CV (%; None when undefined, see ``note``), ``feature`` = |CV| ≤ threshold."""

    base: float
    variant: float
    k: list[float]
    mu: float | None
    sigma: float | None
    cv: float | None
    feature: bool
    note: str = ""


def change_stat(base: np.ndarray, variant: np.ndarray, threshold: float, min_base: float,
                min_change: float = 1.0) -> ChangeStat:
    """Stats of K_j = (variant_j − base_j) / base_j × 100 over pairs j (arrays (J,)); a feature
    part needs |CV| ≤ ``threshold`` % and |μ| ≥ ``min_change`` %."""
    gb, gv = float(np.mean(base)), float(np.mean(variant))
    if np.any(np.abs(base) < min_base):
        return ChangeStat(gb, gv, [], None, None, None, False, f"base ≈ 0 (|base| < {min_base:g}): ratio meaningless")
    k = (variant - base) / base * 100.0
    mu, sigma = float(np.mean(k)), float(np.std(k))
    if mu == 0.0:
        return ChangeStat(gb, gv, k.tolist(), mu, sigma, None, False, "μ = 0: CV undefined")
    cv = sigma / mu * 100.0
    small = abs(mu) < min_change
    return ChangeStat(gb, gv, k.tolist(), mu, sigma, cv, abs(cv) <= threshold and not small,
                      f"|μ| < {min_change:g} %: no real change" if small else "")


@dataclass
class VariantChange:
    """Changes from the base condition to one variant: ``walk`` holds frequency,
    stride_length and speed; ``dc`` and ``amplitude`` one stat per rotation channel."""

    label: str
    condition: str
    pairing: str
    n_pairs: int
    walk: dict[str, ChangeStat]
    dc: list[ChangeStat]
    amplitude: list[ChangeStat]


@dataclass
class GaitAnalysis:
    """The result of ``gait analyze``: what ``gait synth`` reads (see :func:`to_json`)."""

    base: str
    threshold: float
    min_base_deg: float
    min_change: float
    tags: list[ChannelTag]
    variants: list[VariantChange]
    takes: list[dict] = field(default_factory=list)

    def variant(self, label: str, source: str = "") -> VariantChange:
        for v in self.variants:
            if v.label == label:
                return v
        have = ", ".join(v.label for v in self.variants)
        raise InputError(f"{source}: no variant {label!r} in the features (have: {have})")

    def to_json(self) -> dict:
        return {"format": FORMAT, "version": 1, "base": self.base, "threshold_cv_percent": self.threshold,
                "min_base_deg": self.min_base_deg, "min_change_percent": self.min_change, "angle_unit": "deg",
                "tags": [asdict(t) for t in self.tags], "takes": self.takes,
                "variants": [asdict(v) for v in self.variants]}

    @classmethod
    def from_json(cls, d: dict, source: str) -> GaitAnalysis:
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise InputError(f"{source}: not a livezmp gait features file (format field)")
        try:
            variants = [VariantChange(v["label"], v["condition"], v["pairing"], v["n_pairs"],
                                      {k: ChangeStat(**s) for k, s in v["walk"].items()},
                                      [ChangeStat(**s) for s in v["dc"]], [ChangeStat(**s) for s in v["amplitude"]])
                        for v in d["variants"]]
            tags = [ChannelTag(**t) for t in d["tags"]]
            out = cls(d["base"], float(d["threshold_cv_percent"]), float(d["min_base_deg"]),
                      float(d["min_change_percent"]), tags, variants, d.get("takes", []))
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(f"{source}: malformed gait features file: {type(e).__name__} {e}") from None
        for v in out.variants:
            if len(v.dc) != len(tags) or len(v.amplitude) != len(tags):
                raise InputError(f"{source}: variant {v.label}: {len(v.dc)} channel stats for {len(tags)} channels")
        return out


def _check_skeletons(items: list[tuple[TakeSpec, WalkFeatures]]) -> None:
    ref_spec, ref = items[0]
    names = [t.name for t in ref.tags]
    for spec, feats in items[1:]:
        other = [t.name for t in feats.tags]
        if other != names:
            missing = sorted(set(names) - set(other))[:4]
            extra = sorted(set(other) - set(names))[:4]
            raise InputError(f"{spec.path}: skeleton does not match {ref_spec.path} "
                             f"(missing {missing or 'none'}, extra {extra or 'none'}, or a different order)")


Pairs = list[tuple[list[int], list[int]]]


def _pairs(specs: list[TakeSpec], base: str, condition: str, where: str) -> tuple[Pairs, str]:
    """(base take indices, variant take indices) per pair, and how they were paired."""
    b = [i for i, s in enumerate(specs) if s.condition == base]
    v = [i for i, s in enumerate(specs) if s.condition == condition]
    known = [specs[i].subject is not None for i in b + v]
    if all(known):
        subjects = sorted({specs[i].subject for i in b} & {specs[i].subject for i in v})
        left = sorted({specs[i].subject for i in b + v} - set(subjects))
        pairs = [([i for i in b if specs[i].subject == s], [i for i in v if specs[i].subject == s]) for s in subjects]
        text = (f"by subject: each subject's {condition} takes vs the same subject's {base} takes "
                f"({len(subjects)} subjects)")
        if left:
            text += f"; left out (missing a condition): {', '.join(left)}"
    elif not any(known):
        pairs = [(b, [i]) for i in v]
        text = (f"subjects unknown: each {condition} take ({len(v)}) vs the mean of all {len(b)} {base} takes; "
                "σ and CV then measure take-to-take spread, not person-to-person")
    else:
        raise InputError(f"{where}: subject given for some takes and not others; give it for all or none")
    if len(pairs) < 2:
        raise InputError(f"{where}: {condition} vs {base}: {len(pairs)} pair(s); "
                         "need at least two to measure variation")
    return pairs, text


def _pair_means(values: np.ndarray, pairs: Pairs) -> tuple[np.ndarray, np.ndarray]:
    """Per pair, the mean base value and the mean variant value of ``values`` (takes, ...)."""
    return (np.array([values[b].mean(axis=0) for b, _ in pairs]), np.array([values[v].mean(axis=0) for _, v in pairs]))


def _channel_stats(values: np.ndarray, pairs: Pairs, threshold: float, min_base: float,
                   min_change: float) -> list[ChangeStat]:
    g, v = _pair_means(values, pairs)
    return [change_stat(g[:, i], v[:, i], threshold, min_base, min_change) for i in range(values.shape[1])]


def analyze(items: list[tuple[TakeSpec, WalkFeatures]], base: str, variants: dict[str, str], threshold: float = 250.0,
            min_base_deg: float = 1.0, min_change: float = 1.0, where: str = "") -> GaitAnalysis:
    """K, μ, σ, CV and feature parts of each variant (label → condition) against ``base``.

    ``items`` are the takes with their features; ``where`` names the take set in errors.
    """
    found = sorted({s.condition for s, _ in items})
    for cond in [base, *variants.values()]:
        if cond not in found:
            raise InputError(f"{where}: no takes for condition {cond!r} (found: {', '.join(found)})")
    items = [it for it in items if it[0].condition in {base, *variants.values()}]
    items.sort(key=lambda it: it[0].condition != base)  # the first base take is the reference
    _check_skeletons(items)
    specs = [s for s, _ in items]
    feats = [f for _, f in items]
    ref = feats[0].dc
    dc = np.rad2deg(np.array([f.dc + 2 * np.pi * np.round((ref - f.dc) / (2 * np.pi)) for f in feats]))
    amp = np.rad2deg(np.array([f.amplitude for f in feats]))
    walk = {"frequency": np.array([f.frequency for f in feats]),
            "stride_length": np.array([f.stride_length for f in feats]),
            "speed": np.array([f.speed for f in feats])}
    out = []
    for label, cond in variants.items():
        pairs, text = _pairs(specs, base, cond, where)
        w = {k: change_stat(*_pair_means(a, pairs), threshold, WALK_PARAMS[k][1], min_change)
             for k, a in walk.items()}
        out.append(VariantChange(label, cond, text, len(pairs), w,
                                 _channel_stats(dc, pairs, threshold, min_base_deg, min_change),
                                 _channel_stats(amp, pairs, threshold, min_base_deg, min_change)))
    takes = [{"path": str(s.path), "subject": s.subject, "condition": s.condition, "frequency_hz": f.frequency,
              "stride_length_m": f.stride_length, "speed_m_s": f.speed, "cycles": f.cycles.n_cycles}
             for s, f in items]
    return GaitAnalysis(base, threshold, min_base_deg, min_change, list(feats[0].tags), out, takes)
