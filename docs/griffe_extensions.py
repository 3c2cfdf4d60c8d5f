"""Griffe extension: the docstrings read in the API reference as they read in ``help()`` and Sphinx.

- The readers' docstrings hold a ``{finish_parameters}`` line that
  :func:`imu_ground.datasets.skeleton.with_finish_parameters` replaces on import (the validation options
  every reader shares). Griffe reads the source, not the imported object, so this extension applies that
  same decorator to the docstring it read.
- Sphinx roles (``:func:`~imu_ground.pipeline.estimate_log```) become inline code (``estimate_log``, the
  name Sphinx shows), which Markdown would otherwise print with the role's colons.
"""
from __future__ import annotations

import re
from typing import Any

import griffe

#: ``:role:`target``` and ``:role:`~a.b.c```, ``:role:`text <target>```.
SPHINX_ROLE = re.compile(r":(?:py:)?(?:func|meth|class|mod|data|attr|obj|exc|const):`(~?)([^`<]*?)\s*(?:<[^>`]*>)?`")


def plain_roles(text: str) -> str:
    """``text`` with each Sphinx role written as the inline code Sphinx would show."""
    def shown(m: re.Match) -> str:
        name = m.group(2)
        return f"`{name.rsplit('.', 1)[-1] if m.group(1) else name}`"
    return SPHINX_ROLE.sub(shown, text)


class SphinxDocstrings(griffe.Extension):
    """Expand ``{finish_parameters}`` with the project's own decorator; Sphinx roles to inline code."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is None:
            return
        text = obj.docstring.value
        if "{finish_parameters}" in text:
            from imu_ground.datasets.skeleton import with_finish_parameters

            def holder() -> None: ...
            holder.__doc__ = text
            text = with_finish_parameters(holder).__doc__ or text
        obj.docstring.value = plain_roles(text)
