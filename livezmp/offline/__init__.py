"""Whole-take analysis: the vectorised batch path (equal to stepping the pipeline), reports and plots."""
