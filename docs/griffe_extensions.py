"""Griffe extension: the docstrings read in the API reference as they read in ``help()`` and Sphinx.

- The readers' docstrings hold a ``{finish_parameters}`` line that
  :func:`imu_ground.datasets.skeleton.with_finish_parameters` replaces on import (the validation options
  every reader shares). Griffe reads the source, not the imported object, so this extension applies that
  same decorator to the docstring it read.
- Sphinx roles (``:func:`~imu_ground.pipeline.estimate_log```) become inline code (``estimate_log``, the
  name Sphinx shows), which Markdown would otherwise print with the role's colons.
- A parameter typed by its choices (``time_unit : {"s", "ms"}, optional``) shows the signature's default:
  griffe takes the first choice for the default (numpydoc's convention), and the project's docstrings list
  the choices in their own order, with ``None`` (told from the data) as the default.
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
        if isinstance(obj, griffe.Function) and "{" in text:
            signature_defaults(obj)


#: A parameter line typed by its choices: ``name : {"a", "b"}`` (griffe's default is then the first, ``"a"``).
CHOICES_LINE = re.compile(r"^\s*(\**\w+)\s*:\s*\{([^}]*)\}", flags=re.M)


def signature_defaults(func: griffe.Function) -> None:
    """Parse ``func``'s docstring now and give each parameter typed by choices the signature's default."""
    first = {name.lstrip("*"): choices.split(",", 1)[0].strip()
             for name, choices in CHOICES_LINE.findall(func.docstring.value)}
    for section in func.docstring.parsed:
        if section.kind not in (griffe.DocstringSectionKind.parameters, griffe.DocstringSectionKind.other_parameters):
            continue
        for param in section.value:
            name = param.name.lstrip("*")
            if name in first and param.value == first[name]:        # the default griffe took from the choices
                param.value = func.parameters[name].default if name in func.parameters else None
