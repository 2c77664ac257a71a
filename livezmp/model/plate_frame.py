"""A force plate's own axes, from its four corners in the lab (the C3D convention).

Corner 1 lies in the plate's +x +y quadrant, 2 in −x +y, 3 in −x −y, 4 in +x −y, so
x ∥ c1 − c2, y ∥ c1 − c4 and z = x × y, which points down into the plate as on most
plates; the origin is the centre of the corners (the surface centre). QTM's force
component, and plates in general, give force, moment and centre of pressure in these
axes; the capture sources turn them into the lab's.
"""

from __future__ import annotations

import numpy as np


def plate_axes(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``corners`` (4, 3) in the lab → (R (3, 3) whose columns are the plate's x, y, z in
    the lab, origin (3,)), so lab = R @ local + origin."""
    c = np.asarray(corners, float)
    x = c[0] - c[1]
    x /= np.linalg.norm(x)
    y = c[0] - c[3]
    y -= x * (x @ y)
    y /= np.linalg.norm(y)
    return np.column_stack([x, y, np.cross(x, y)]), c.mean(axis=0)
