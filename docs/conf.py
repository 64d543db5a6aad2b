"""Sphinx configuration of the vesicle_opt site: MyST Markdown pages, an executed sphinx-gallery of
examples/ (the quick ones), the API reference by autodoc/autosummary, the furo theme.

Pages with tables the code holds (scene keys, npz keys, CSV columns, output files, studies) include
``_generated/*.md``, written at build time by ``_ext/vo_generate.py`` from the package itself.
Build: ``pip install '.[docs]'`` then ``sphinx-build -W -b html docs docs/_build/html``.
"""

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
sys.path.insert(0, str(HERE.parent))  # the package of this checkout, installed or not
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import vesicle_opt  # noqa: E402

project = "vesicle_opt"
author = "the vesicle_opt authors"
copyright = "the vesicle_opt authors (MIT licence)"
release = version = vesicle_opt.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx_gallery.gen_gallery",
    "vo_generate",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "_generated", "results", "Thumbs.db", ".DS_Store",
                    "auto_examples/*.ipynb", "auto_examples/*.py", "auto_examples/*.zip",
                    "auto_examples/*.md5", "auto_examples/*.codeobj.json"]
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 4
html_theme = "furo"
html_title = f"vesicle_opt {release}"
html_static_path = []

autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_default_options = {"members": True, "undoc-members": False}
autosummary_generate = False  # the API page lists and documents the names itself (api.md)

sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "auto_examples",
    # executed at build time: the quick examples only (the 3D torus takes tens of seconds)
    "filename_pattern": r"/(solve_and_read|own_constraint|flow_with_tracker|branch_2d|penalty_vs_exact)\.py$",
    "ignore_pattern": r"__init__\.py",
    "within_subsection_order": "vo_generate.TourOrder",  # the tour's order, simplest first
    "abort_on_example_error": True,
    "download_all_examples": False,
    "remove_config_comments": True,
    "min_reported_time": 1,
    "image_scrapers": ("matplotlib",),
    "matplotlib_animations": False,
    "show_memory": False,
    "plot_gallery": "True",
}
