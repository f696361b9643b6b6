"""Make the helpers shared by this folder's tests (projection_cases.py) importable by name."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
