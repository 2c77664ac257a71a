"""Figures livezmp's analysis was validated to against force plates (docs/validation.md); no imports,
so the command-line grammar can show them as defaults."""

# ZMP error against the plates (p95, mm): the median over the shared gait trials of `livezmp analyze`'s
# p95 (python benchmarks/bench_forceplates.py); the default tolerance of the "inside" test.
VALIDATED_P95_MM = 85.0
