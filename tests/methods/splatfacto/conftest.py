"""Make the tiny analytic street importable by name (shared with the 2DGS, Scaffold-GS and export tests)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "splatfacto"))
