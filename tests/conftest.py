import sys
from pathlib import Path

# the tests import their naive oracle as a sibling module
sys.path.insert(0, str(Path(__file__).parent))
