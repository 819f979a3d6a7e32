"""What both stationary-state formats share: the sums, the canonical metadata, the
probability checks, and the fault a reader turns into one CorruptFileError line
(:mod:`markov.solvers.storage` for rings, :mod:`markov.solvers.road_storage` for roads)."""
from __future__ import annotations

import hashlib
import json

import numpy as np

#: ``|sum(probabilities) - 1|`` allowed on loading (the solvers normalise to ~1e-15).
SUM_TOLERANCE = 1e-9


def _package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("nasch-exact")
    except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "unknown"


def _digest(data) -> str:
    """SHA-256 of a buffer (an array's bytes as stored), in hex."""
    return hashlib.sha256(data).hexdigest()


def _canonical_json(meta: dict) -> str:
    """The metadata as hashed: sorted keys, no spaces, ASCII (parsing and dumping again
    gives the same text, so the hash does not depend on how the JSON was laid out)."""
    return json.dumps(meta, sort_keys=True, separators=(",", ":"), ensure_ascii=True)


class _Bad(Exception):
    """What is wrong with the file being read (becomes one CorruptFileError line)."""


def _check_probabilities(pi: np.ndarray) -> None:
    finite = np.isfinite(pi)
    if not finite.all():
        i = int(np.argmin(finite))
        raise _Bad(f"probability {i} is {pi[i]}, not a finite number")
    if pi.min() < 0:
        i = int(np.argmin(pi))
        raise _Bad(f"probability {i} is {pi[i]!r}, negative")
    total = float(pi.sum())
    if abs(total - 1.0) > SUM_TOLERANCE:
        raise _Bad(f"the probabilities sum to {total!r}, not 1 (tolerance {SUM_TOLERANCE:g})")
