"""Share the tiny analytic street of the splatfacto tests."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "splatfacto"))
