import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

# the tests import their naive oracles as sibling modules
sys.path.insert(0, str(Path(__file__).parent))

# derivations are cached on disk (symbolic.cache): the tests build their own, in a
# directory of this process that is removed at exit, never the user's ~/.cache
_CACHE = tempfile.mkdtemp(prefix="nasch-test-cache-")
os.environ["NASCH_CACHE_DIR"] = _CACHE
atexit.register(shutil.rmtree, _CACHE, ignore_errors=True)
