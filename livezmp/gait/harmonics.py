"""Least-squares Fourier fit of waveforms at a known fundamental frequency.

Over whole gait cycles the fit's constant term is the waveform's mean (the paper's
DC) and the harmonics describe its shape; unlike an FFT it needs no integer number
of samples per cycle and it is exact for a sampled sum of those harmonics.
"""

from __future__ import annotations

import numpy as np


def design_matrix(t: np.ndarray, frequency: float, harmonics: int) -> np.ndarray:
    """Columns 1, cos(2πkft), sin(2πkft) for k = 1..harmonics; ``t`` in s, ``frequency`` in Hz."""
    w = 2 * np.pi * frequency * t[:, None] * np.arange(1, harmonics + 1)
    return np.hstack([np.ones((len(t), 1)), np.cos(w), np.sin(w)])


def fit(t: np.ndarray, x: np.ndarray, frequency: float, harmonics: int) -> tuple[np.ndarray, np.ndarray]:
    """Fit ``x`` (N,) or (N, C) sampled at ``t`` (N,) s.

    Returns ``(coef, residual)``: coef (2H+1, C) ordered as :func:`design_matrix`
    (same units as ``x``) and the residual sum of squares per column (C,).
    """
    x2 = x.reshape(len(t), -1)
    m = design_matrix(t, frequency, harmonics)
    coef, *_ = np.linalg.lstsq(m, x2, rcond=None)
    res = np.sum((m @ coef - x2) ** 2, axis=0)
    return coef, res


def mean_and_amplitude(coef: np.ndarray, harmonics: int) -> tuple[np.ndarray, np.ndarray]:
    """DC and amplitude per column from :func:`fit`'s coefficients.

    The amplitude is sqrt(Σ_k a_k² + b_k²), i.e. √2 × the RMS of the periodic part
    about its mean: a sinusoid's own amplitude, and it scales exactly with the
    waveform when the waveform is scaled about its mean.
    """
    a = coef[1 : 1 + harmonics]
    b = coef[1 + harmonics : 1 + 2 * harmonics]
    return coef[0], np.sqrt(np.sum(a * a + b * b, axis=0))
