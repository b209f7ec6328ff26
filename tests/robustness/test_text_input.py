"""Text that cannot be written as UTF-8 (a lone surrogate: what Python makes of undecodable
bytes in argv) is refused naming the argument, before anything changes or is simulated; it
raised UnicodeEncodeError from the core, or from the page's write after the simulation."""
from __future__ import annotations

import subprocess
import sys

import pytest

import physcore as pc

BAD = "a\udcff"


@pytest.mark.parametrize("make", [
    lambda s: s.add(pc.Gravity([0.0, -1.0], name=BAD)),
    lambda s: s.add(pc.Drag(0.1, name=BAD)),
    lambda s: s.add(pc.XpbdConstraints(distance=[[0, 1]], name=BAD)),
    lambda s: s.set_attribute(BAD, [1.0, 2.0]),
    lambda s: pc.Bodies("ball", size=[0.1], name=BAD),
    lambda s: pc.Wave((8, 8), name=BAD),
], ids=["term", "drag", "xpbd", "attribute", "bodies", "grid"])
def test_a_name_that_is_not_text_is_refused_by_name(make):
    s = pc.Scene(dim=2, dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]])
    with pytest.raises(pc.InvalidInputError, match=r"^name: not valid text"):
        make(s)
    assert len(s.terms) == 0 and s.time == 0.0


@pytest.mark.parametrize("fn, out", [(pc.render.html, "t.html"), (pc.render.gif, "t.gif")])
def test_a_title_that_is_not_text_is_refused_before_simulating(tmp_path, fn, out):
    s = pc.scenes.projectile()
    with pytest.raises(pc.InvalidInputError, match=r"^title: not valid text"):
        fn(s, tmp_path / out, frames=3, title=BAD)
    assert s.time == 0.0 and not (tmp_path / out).exists()


def test_the_cli_refuses_a_title_of_undecodable_bytes_as_a_usage_error(tmp_path):
    out = tmp_path / "c.html"
    r = subprocess.run([sys.executable, "-m", "physcore", "render", "projectile", "-o", str(out), "--frames", "3",
                        "--title", b"\xff".decode("utf-8", "surrogateescape")], capture_output=True, text=True,
                       errors="replace", timeout=120)
    assert r.returncode == 2 and "--title: not valid text" in r.stderr and "simulating" not in r.stderr, r.stderr
    assert not out.exists()
