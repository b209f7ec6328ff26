"""The floating box of test_floating.py under WCSPH: a slow case (about 75 s on the 2-core
machine), in a file of its own so that the suite's workers (pytest-xdist, one file each) run it
beside test_floating_fine.py's rather than after it.
"""
from __future__ import annotations

import pytest
from test_floating import HY, _draft


@pytest.mark.slow
def test_a_wcsph_fluid_floats_a_box_too():
    """WCSPH (Tait equation of state) through the same boundary particles, its pressure force
    −m_i Ψ_b (p_i/ρ_i²) ∇W_ib (Akinci 2012, eq. 10) and the reaction on the body (no
    hydrostatic part: a WCSPH sample takes its particle's pressure once, not mirrored): at 80
    across, draft 7.41 cm against 7.50 (−1.2 %); at 40, 7.04 (−6.2 %). (The old surface
    estimator read 7.49 and 7.14 cm, −0.2 and −4.8 %; over t = 2.5 .. 4 s, as this test once
    measured it at 40 across, 7.33.) Averaged over t = 4 .. 6 s (a seventh of the time): 7.41 cm
    at 80 across, as over 4 .. 7 s to 0.01 %."""
    assert _draft(80, 500.0, "wcsph", until=6.0) == pytest.approx(2 * HY * 0.5, rel=0.03)
