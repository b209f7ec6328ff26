"""sphinx-gallery's image scraper for the animations physcore's examples write (issue 47, item 2).

After each code block of an example runs, :func:`scraper` moves every GIF, MP4 or WebM file the
block wrote into the example's folder (``examples/``; sphinx-gallery runs each example there) to
the gallery's ``images/`` folder, under sphinx-gallery's own name for the block's next image
(``sphx_glr_plot_NAME_001.gif``), and returns the reStructuredText that embeds it: an ``image``
directive, which Sphinx copies into the build's ``_images/`` and docutils writes as an ``<img>``,
or for a video as a ``<video controls>`` element (and a PNG of its frame a third of the way in
beside it, which sphinx-gallery requires of an image and makes the thumbnail). Moving the files also keeps ``examples/``
clean. A file there older than this build (a run by hand) is left alone. Named in
``sphinx_gallery_conf["image_scrapers"]`` in docs/conf.py, after matplotlib's, as PyVista's
gallery collects its GIFs.
"""
from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

ANIMATIONS = (".gif", ".mp4", ".webm")
_START = time.time()  # the build's start: older files were not written by this build's examples


def scraper(block, block_vars, gallery_conf) -> str:
    folder = Path(block_vars["src_file"]).parent
    found = sorted((p for p in folder.iterdir() if p.suffix.lower() in ANIMATIONS and p.stat().st_mtime >= _START),
                   key=lambda p: p.stat().st_mtime)
    rst = []
    for path in found:
        dest = Path(next(block_vars["image_path_iterator"])).with_suffix(path.suffix.lower())
        shutil.move(path, dest)
        uri = "/" + Path(os.path.relpath(dest, gallery_conf["src_dir"])).as_posix()
        video = dest.suffix != ".gif"
        if video:  # sphinx-gallery wants an image under that name: a frame, which is also the thumbnail
            _poster(dest, dest.with_suffix(".png"))
        rst += [f".. image:: {uri}", f"   :alt: {path.name}", f"   :class: {'controls' if video else 'sphx-glr-single-img'}", ""]
    return "\n" + "\n".join(rst) + "\n" if rst else ""


def _poster(video: Path, png: Path) -> None:
    import av  # PyAV: the video extra, which the docs and test extras bring

    with av.open(str(video)) as container:
        frames = [f.to_image() for f in container.decode(video=0)]
    frames[len(frames) // 3].save(png)


#: The examples' order on the gallery's page (a reader's path); any other example after them, by name.
ORDER = ["plot_own_scene", "plot_custom_force", "plot_video", "plot_sweep", "plot_batch"]


def example_order(filename: str) -> tuple[int, str]:
    """``sphinx_gallery_conf["within_subsection_order"]``: the key of an example's file."""
    stem = Path(filename).stem
    return (ORDER.index(stem) if stem in ORDER else len(ORDER), stem)
