"""``python -m nasch``: the ``nasch`` command line."""
from .cli import run

run()
