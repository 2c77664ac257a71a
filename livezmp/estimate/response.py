"""The estimator's frequency response, measured by running it over sinusoids: what a signal passed through it
keeps of each frequency, so that another measurement of the same motion (force plates) can be given the same band.
"""

from __future__ import annotations

import numpy as np

from livezmp.estimate.estimator import EstimatorConfig, estimate_offline

RESPONSE_PERIODS_S = 8.0  # s of sinusoid run through the estimator; the middle half is measured (clear of the ends)


def acceleration_response(config: EstimatorConfig, freq_hz: float) -> tuple[float, float]:
    """Gain and delay (s; + the estimate comes later) of the estimator's acceleration of a sinusoid of ``freq_hz``
    Hz sampled at ``config.rate_hz``, against the sinusoid's true acceleration."""
    rate = config.rate_hz
    t = np.arange(int(RESPONSE_PERIODS_S * rate)) / rate
    x = np.sin(2 * np.pi * freq_hz * t)[:, None]
    _, _, qdd = estimate_offline(t, x, None, config)
    true = -((2 * np.pi * freq_hz) ** 2) * x[:, 0]
    mid = (t > RESPONSE_PERIODS_S / 4) & (t < 3 * RESPONSE_PERIODS_S / 4)
    c = np.exp(-2j * np.pi * freq_hz * t[mid])
    ratio = (qdd[mid, 0] @ c) / (true[mid] @ c)
    return float(abs(ratio)), float(-np.angle(ratio) / (2 * np.pi * freq_hz))
