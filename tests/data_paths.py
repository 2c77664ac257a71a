"""Where the real data lives: ``$LIVEZMP_DATA`` if set, else ``../shared/data`` beside the
project (CI has it there). Without it the tests that read it are deselected (see
conftest.py), unless ``LIVEZMP_REQUIRE_DATA=1`` (CI), which makes its absence an error."""

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("LIVEZMP_DATA") or ROOT.parent / "shared" / "data")
HAVE_DATA = (DATA / "bvh" / "bandai").is_dir()
REQUIRE_DATA = os.environ.get("LIVEZMP_REQUIRE_DATA") == "1"
# The names a test reaches the data through (module-level helpers that use them are found too).
DATA_NAMES = ("DATA", "BANDAI", "OP3_URDF", "bandai_walk", "op3_body")
BANDAI = DATA / "bvh" / "bandai"
OP3_URDF = DATA / "robots" / "robotis_op3.urdf"
C3D = DATA / "c3d"
