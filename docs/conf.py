"""Sphinx configuration for the skpcd documentation."""

import os
import socket
from pathlib import Path

import skpcd

# The gallery reads the real DALES objects through skpcd.datasets.load_dales_objects,
# which looks at SKPCD_DALES_DIR; beside a checkout they sit in ../shared/data.
_DALES = Path(__file__).resolve().parents[2] / "shared" / "data" / "dales_objects"
if "SKPCD_DALES_DIR" not in os.environ and (_DALES / "labels.csv").is_file():
    os.environ["SKPCD_DALES_DIR"] = str(_DALES)

project = "skpcd"
author = "skpcd developers"
copyright = "2026, skpcd developers"
version = release = skpcd.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.intersphinx",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

templates_path = ["_templates"]
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "**.md5"]
html_theme = "pydata_sphinx_theme"
html_static_path = ["_static"]
html_theme_options = {"navigation_with_keys": False}

autosummary_generate = True
autodoc_default_options = {"members": True}
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False

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


def setup(app):
    app.connect("autodoc-skip-member", _skip_sklearn_members)
