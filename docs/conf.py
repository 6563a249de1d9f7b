"""Sphinx configuration for the skpcd documentation."""

import os
import re
import socket
import sys
from pathlib import Path

from docutils import nodes

# The documentation of this checkout: its skpcd, not an installed one (and
# the numba kernels the test run compiled and cached beside it, rather than
# a second compilation of every kernel for the gallery).
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
# docs/_performance.py, the extension that writes the Performance page's tables
sys.path.insert(0, str(ROOT / "docs"))

import skpcd
from skpcd.datasets import DALES_ENV

# Which data the gallery runs on. The examples read the DALES objects with
# skpcd.datasets.load_dales_objects, from the folder named by SKPCD_DALES_DIR, and
# fall back to the synthetic objects of make_urban_objects where that folder has no
# labels.csv. Unset, SKPCD_DALES_DIR takes the test suite's default location
# (tests/conftest.py), so that the docs and the tests see the same data. The pages
# learn the outcome from the tag ("dales" or "synthetic", for ``.. only::``) and the
# substitutions |gallery_data| and |gallery_data_short| defined below.
_DEFAULT_DALES = ROOT.parent / "shared" / "data" / "dales_objects"
if DALES_ENV not in os.environ and (_DEFAULT_DALES / "labels.csv").is_file():
    os.environ[DALES_ENV] = str(_DEFAULT_DALES)


def _count_dales_objects():
    """Objects in the DALES folder load_dales_objects would read, or 0."""
    folder = os.environ.get(DALES_ENV)
    labels = Path(folder) / "labels.csv" if folder else None
    if labels is None or not labels.is_file():
        return 0
    rows = [r for r in labels.read_text().splitlines() if r.strip()]
    if rows and rows[0].rsplit(",", 1)[-1].strip().lower() == "label":  # a header
        rows = rows[1:]
    return len(rows)


_N_DALES = _count_dales_objects()
if _N_DALES:
    tags.add("dales")  # noqa: F821 (Sphinx puts ``tags`` in this namespace)
    _GALLERY_DATA = f"the DALES objects ({_N_DALES} real aerial LiDAR objects)"
    _GALLERY_DATA_SHORT = "the DALES objects"
else:
    tags.add("synthetic")  # noqa: F821
    _GALLERY_DATA = (
        "synthetic objects of :func:`~skpcd.datasets.make_urban_objects` (the DALES "
        "objects were not available when this page was built)"
    )
    _GALLERY_DATA_SHORT = "synthetic objects (DALES unavailable)"

rst_prolog = f"""
.. |gallery_data| replace:: {_GALLERY_DATA}
.. |gallery_data_short| replace:: {_GALLERY_DATA_SHORT}
"""

project = "skpcd"
author = "skpcd developers"
copyright = "2026, skpcd developers"
version = release = skpcd.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.intersphinx",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "matplotlib.sphinxext.plot_directive",
    "_performance",
]

templates_path = ["_templates"]
exclude_patterns = [
    "_build",
    "auto_examples/*.ipynb",
    "auto_examples/*.py",
    "**.md5",
    "**sg_execution_times.rst",  # left by older builds (see write_computation_times)
]
html_theme = "pydata_sphinx_theme"
html_static_path = ["_static"]
html_theme_options = {"navigation_with_keys": False}
# Maths as MathML, written into the pages at build time (see _visit_math below):
# no script and nothing fetched from the network when a page is read.
html_math_renderer = "mathml"

autosummary_generate = True
autodoc_default_options = {"members": True}
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False

# Figures drawn from the committed benchmark results (``.. plot::`` in the user
# guide); the code runs from the repository root.
plot_working_directory = str(ROOT)
plot_include_source = False
plot_html_show_source_link = False
plot_html_show_formats = False
plot_formats = [("png", 110)]

intersphinx_mapping = {
    "python": ("https://docs.python.org/3", None),
    "numpy": ("https://numpy.org/doc/stable", None),
    "scipy": ("https://docs.scipy.org/doc/scipy", None),
    "sklearn": ("https://scikit-learn.org/stable", None),
    "joblib": ("https://joblib.readthedocs.io/en/stable", None),
}
intersphinx_timeout = 5


def _online(host="docs.python.org"):
    try:
        socket.create_connection((host, 443), timeout=3).close()
    except OSError:
        return False
    return True


# Without network (CI here), the inventories cannot be fetched and Sphinx would warn;
# the cross-references to numpy, scipy and scikit-learn then stay plain text.
if os.environ.get("SKPCD_DOCS_OFFLINE") or not _online():
    intersphinx_mapping = {}

sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "auto_examples",
    "doc_module": ("skpcd",),
    "backreferences_dir": "generated",
    "reference_url": {"skpcd": None},
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    # the timing pages load jQuery and DataTables from CDNs: not written
    "write_computation_times": False,
}


def _skip_sklearn_members(app, what, name, obj, skip, options):
    """Leave out members scikit-learn defines (``score``, ``set_fit_request``...).

    Their docstrings point at targets that live in scikit-learn's own docs;
    the API pages document what skpcd adds.
    """
    module = getattr(obj, "__module__", None) or ""
    if what == "class" and module.split(".")[0] == "sklearn":
        return True
    return skip


# ---------------------------------------------------------------------------
# Maths: LaTeX converted to MathML by latex2mathml when the page is written.


def _mathml(latex, display):
    from latex2mathml.converter import convert

    # latex2mathml spells \operatorname{atan2} as italic letters; \mathrm is upright
    latex = re.sub(r"\\operatorname\{([^}]*)\}", r"\\mathrm{\1}", latex)
    return convert(latex.strip(), display="block" if display else "inline")


def _visit_math(self, node):
    self.body.append(self.starttag(node, "span", "", CLASS="math notranslate"))
    self.body.append(_mathml(node.astext(), display=False))
    self.body.append("</span>")
    raise nodes.SkipNode


def _visit_displaymath(self, node):
    from sphinx.util.math import get_node_equation_number

    self.body.append(self.starttag(node, "div", CLASS="math notranslate"))
    if node["number"]:
        number = get_node_equation_number(self, node)
        self.body.append(f'<span class="eqno">({number})')
        self.add_permalink_ref(node, "Link to this equation")
        self.body.append("</span>")
    for part in node.astext().split("\n\n"):  # one equation per paragraph
        if part.strip():
            self.body.append(_mathml(part, display=True))
    self.body.append("</div>\n")
    raise nodes.SkipNode


def setup(app):
    app.connect("autodoc-skip-member", _skip_sklearn_members)
    app.add_html_math_renderer(
        "mathml", (_visit_math, None), (_visit_displaymath, None)
    )
