"""The floating box of test_floating.py at finer pools and under WCSPH: the slow cases, in a file
of their own so that the suite's workers (pytest-xdist, one file each) run them beside the rest
of test_floating.py rather than after it.
"""
from __future__ import annotations

import pytest
from test_floating import HY, _draft


@pytest.mark.slow
def test_the_draft_converges_with_the_resolution_at_a_tight_density_tolerance():
    """At density_error 0.01 % and α = 0.5 the draft converges with the resolution: 6.97, 7.51
    and 7.65 cm at 40, 80 and 120 across (−7.1, +0.1, +2.0 %; spacing 2.5, 1.25 and 0.83 cm),
    the steps between them shrinking 3.7× for a spacing 1.5× finer, towards about 7.7 cm: the
    limit is some 2.5 % deeper than Archimedes (cause not found; the guide's Limits say so).
    (Measured over t = 2.5 .. 4 s, before the box had settled, these read 7.28, 7.54, 7.62 and
    the test asserted 2 % at 120 across.)"""
    d40, d80, d120 = (_draft(n, 500.0, density_error=1e-4, alpha=0.5) for n in (40, 80, 120))
    archimedes = 2 * HY * 0.5
    print(f"drafts {d40 * 100:.3f}, {d80 * 100:.3f}, {d120 * 100:.3f} cm (Archimedes {archimedes * 100:.2f})")
    assert abs(d120 - d80) < 0.5 * abs(d80 - d40)  # converging
    assert d80 == pytest.approx(archimedes, rel=0.03) and d120 == pytest.approx(archimedes, rel=0.03)


@pytest.mark.slow
def test_a_wcsph_fluid_floats_a_box_too():
    """WCSPH (Tait equation of state) through the same boundary particles, its pressure force
    −m_i Ψ_b (p_i/ρ_i²) ∇W_ib (Akinci 2012, eq. 10) and the reaction on the body (no
    hydrostatic part: a WCSPH sample takes its particle's pressure once, not mirrored): at 80
    across, draft 7.49 cm against 7.50 (−0.2 %); at 40, 7.14 (−4.8 %; over t = 2.5 .. 4 s, as
    this test once measured it at 40 across, 7.33)."""
    assert _draft(80, 500.0, "wcsph") == pytest.approx(2 * HY * 0.5, rel=0.03)
