"""Euler angles' two branches. A rotation R_a(x) R_b(y) R_c(z) about three distinct axes is also
R_a(x + h) R_b(h − y) R_c(z + h), h a half turn (a half turn about a flips b, and two about perpendicular axes make one
about the third): a decomposition that folds its middle angle into ±90° jumps from one branch to the other as the
middle angle passes 90°. Angles in radians (``half_turn`` = pi) or degrees (180)."""

from __future__ import annotations

import numpy as np


def other_branch(angles: np.ndarray, half_turn: float = np.pi) -> np.ndarray:
    """(F, 3) the same rotations as the Euler ``angles`` (F, 3) on the other branch (middle angle mirrored
    about a quarter turn), in the unit of ``half_turn`` (rad by default; 180 for degrees)."""
    return np.column_stack([angles[:, 0] + half_turn, half_turn - angles[:, 1], angles[:, 2] + half_turn])


def wrapped(d: np.ndarray, half_turn: float = np.pi) -> np.ndarray:
    """Angle differences ``d`` into [-half_turn, half_turn)."""
    return np.mod(d + half_turn, 2 * half_turn) - half_turn
