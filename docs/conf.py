"""Sphinx configuration of the sjt-pin documentation (``python -m sphinx -W -n docs OUT``).

Everything the pages need is installed with the ``docs`` extra: the theme (furo) and MathJax
(sphinx-mathjax-offline) are served from the built site, so it works without a network.
"""

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))

import sjt_pin  # noqa: E402

project = "sjt-pin"
author = "the sjt-pin developers"
copyright = "the sjt-pin developers, BSD-3-Clause"
release = version = sjt_pin.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",  # MathJax 3 copied into _static: math renders offline
    "sphinx_copybutton",
    "bench_tables",  # the benchmark tables, from the JSON files of docs/bench/
    "api_pages",  # one page per public name of sjt_pin.__all__
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build"]
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

html_theme = "furo"
html_title = f"sjt-pin {release}"
html_static_path = ["_static"]
html_extra_path = []
html_show_sourcelink = False
html_copy_source = False

# the docstrings speak of Pinocchio's, NumPy's and coal's types, whose own documentation is
# not reachable offline (no intersphinx): those references stay plain text
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(pin|pinocchio|np|numpy|coal|hppfcl|npt|numpy\.typing)(\..*)?"),
    (r"py:.*", r"(ndarray|NDArray|ArrayLike|SE3|Motion|Model|Data|GeometryModel|FrameType)"),
    (r"py:.*", r"(concurrent\.futures\..*|collections\.abc\..*|typing\..*|pathlib\..*)"),
    (r"py:.*", r"(Executor|Future|Path|Callable|Iterable|Iterator|Sequence|Mapping|Any)"),
    # an instance attribute (set in __init__, so no import finds it) that has no page
    (r"py:attr", r"pairs"),
]

autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_description_target = "documented_params"
autodoc_preserve_defaults = True
autosummary_generate = False
napoleon_google_docstring = True
napoleon_numpy_docstring = False

copybutton_exclude = ".linenos, .gp, .go"

def _attribute_docstrings_have_no_inline_type():
    """napoleon reads ``name: text`` at the start of an attribute's docstring as its type
    (``#: the joint of each velocity (tangent) index: columns of J`` became a type "the joint
    ..."); the attributes here carry their types as annotations, so the whole text is the
    description."""
    from sphinx.ext.napoleon.docstring import GoogleDocstring

    def consume(self):
        lines = self._consume_to_next_section()
        return "", lines

    GoogleDocstring._consume_inline_attribute = consume


_attribute_docstrings_have_no_inline_type()


def _docstring_text(app, what, name, obj, options, lines):
    """Before napoleon reads a docstring: ``|e|`` outside ``code`` is a norm, not a
    reStructuredText substitution; the solvers' argument headings ("SJT's own arguments:",
    "Common arguments (keyword-only):"), which napoleon's section pattern cannot match, become
    its own "Parameters:" and "Keyword Arguments:"."""
    import re

    bars = re.compile(r"(?<![\\|])\|([^|\s][^|]*?)\|(?![_|])")
    for i, line in enumerate(lines):
        stripped = line.strip()
        if re.fullmatch(r"\w+'s own arguments:", stripped):
            lines[i] = line.replace(stripped, "Parameters:")
            continue
        if stripped == "Common arguments (keyword-only):":
            lines[i] = line.replace(stripped, "Keyword Arguments:")
            continue
        parts = line.split("``")
        for k in range(0, len(parts), 2):  # the even parts lie outside ``literals``
            parts[k] = bars.sub(r"\\|\1\\|", parts[k])
        lines[i] = "``".join(parts)


def _resolve_to_what_exists(app, env, node, contnode):
    """A reference to a helper of the package that has no page of its own (a module constant,
    an internal module or base class) is shown as code without a link, but only where the
    name exists: a reference to nothing still fails the build."""
    import importlib

    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~.")
    if not target or not (target.startswith("sjt_pin") or node.get("py:module", "").startswith(
            "sjt_pin")):
        return None
    candidates = [target]
    module = node.get("py:module")
    if module:
        candidates.append(f"{module}.{target}")
        if node.get("py:class"):
            candidates.append(f"{module}.{node['py:class']}.{target}")
    source = str(node.source or "")
    if "docstring of " in source:  # the object whose docstring makes the reference
        owner = source.rsplit("docstring of ", 1)[1].split(":")[0].split(".")
        candidates += [".".join([*owner[:cut], target]) for cut in range(len(owner), 0, -1)]
    for full in candidates:
        parts = full.split(".")
        for cut in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:cut]))
            except ImportError:
                continue
            try:
                for attr in parts[cut:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                break
            return contnode
    return None


def setup(app):
    app.connect("autodoc-process-docstring", _docstring_text, priority=400)
    # after api_pages' resolution of short names (priority 500)
    app.connect("missing-reference", _resolve_to_what_exists, priority=900)
