"""Where the real data lives: ``../shared/data`` beside the project (CI has it there)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
BANDAI = DATA / "bvh" / "bandai"
OP3_URDF = DATA / "robots" / "robotis_op3.urdf"
C3D = DATA / "c3d"
