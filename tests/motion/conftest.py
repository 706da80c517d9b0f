import sys
from pathlib import Path

# motion_kin.py (test-only kinematics) lives next to the tests
sys.path.insert(0, str(Path(__file__).parent))
