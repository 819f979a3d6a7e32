"""Every route takes a road or refuses it in one line with the reason (issue 25, item 1)."""
from __future__ import annotations

import pytest
from click.testing import CliRunner

from nasch.cli import main

RING_ONLY = [
    (["approx", "--method", "mf", "-c", "0.3"], "bulk of a ring"),
    (["derive", "--method", "mf"], "bulk of a ring"),
    (["goe"], "Garden-of-Eden"),
    (["study"], "sweeps rings"),
    (["plot", "fundamental", "-o", "{out}"], "phase-diagram"),
    (["plot", "models", "-o", "{out}"], "phase-diagram"),
    (["plot", "relaxation", "-o", "{out}"], "spectrum --road"),
    (["plot", "spacetime", "-o", "{out}"], "simulate --road"),
]


@pytest.mark.parametrize("args, words", RING_ONLY, ids=lambda a: " ".join(a) if
                         isinstance(a, list) else None)
def test_a_ring_only_route_refuses_a_road_with_its_reason(tmp_path, args, words):
    out = tmp_path / "fig.png"
    res = CliRunner().invoke(main, [a.format(out=out) for a in args] + ["--road"])
    assert res.exit_code == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --road: ") and words in lines[0]
    assert not out.exists()
