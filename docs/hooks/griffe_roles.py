"""Griffe extension: the Sphinx roles in the docstrings (``:class:`~a.b.C```) as inline code (`` `C` ``).

The docstrings are Google style, read by ``help()`` and by mkdocstrings, and name other objects with Sphinx
roles (``:class:``, ``:func:``, ``:meth:``, ``:mod:``, ``:data:``, ``:attr:``, ...) that Markdown would show as
written. They become inline code with the text Sphinx shows: the last component after a leading ``~``, the
whole target otherwise (a leading ``.`` of a relative target dropped).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|data|attr|exc|obj|const|type):`(?P<target>[^`]+)`")


def plain(target: str) -> str:
    """The text Sphinx shows for a role's target."""
    if target.startswith("~"):
        return target[1:].rsplit(".", 1)[-1]
    return target.lstrip(".")


def strip_roles(text: str) -> str:
    """``text`` with each Sphinx role replaced by inline code."""
    return _ROLE.sub(lambda match: f"`{plain(match['target'])}`", text)


class SphinxRoles(griffe.Extension):
    """Rewrites the roles of every docstring as it is read.

    Listed after ``griffe_sphinx`` in ``mkdocs.yml``, so that it also sees the attributes' ``#:`` comments, which
    that extension makes their docstrings.
    """

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        """Griffe event: an object was created with its docstring."""
        _rewrite(obj)

    def on_attribute_instance(self, *, attr: griffe.Attribute, **kwargs: Any) -> None:
        """Griffe event: an attribute was created (after ``griffe_sphinx`` gave it its ``#:`` comment)."""
        _rewrite(attr)


def _rewrite(obj: griffe.Object) -> None:
    if obj.docstring is not None and ":`" in obj.docstring.value:
        obj.docstring.value = strip_roles(obj.docstring.value)
