"""Gait analysis and walking-speed control (source paper 003).

A walk's joint-angle waveforms are described by posture (DC), size (amplitude) and
speed (the stride frequency common to all joints). Across people, the changes that
are common to everyone (small coefficient of variation) are the "feature parts";
a base walk is turned into a slower or faster one by changing only those.

Modules: :mod:`.take` (a walk in SI), :mod:`.channels` (which channel is which),
:mod:`.cycles` and :mod:`.harmonics` (gait cycles, frequency, Fourier fit),
:mod:`.features` (one walk's features), :mod:`.takeset` (labelled take sets),
:mod:`.population` (K, μ, σ, CV, feature parts), :mod:`.tables` (outputs),
:mod:`.synth` (speed control), :mod:`.compare` (evaluation), :mod:`.live`
(streaming estimator), :mod:`.sinewalk` (walks made of known sinusoids),
:mod:`.cli` (``livezmp gait``).
"""
