"""Griffe extension for the documentation site (mkdocs.yml): the docstrings' Sphinx roles as cross-references.

The docstrings follow numpydoc and cross-reference with Sphinx roles (``:class:`fpm_sim.results.Result```,
``:func:`parse_description```), which mkdocstrings would print as they stand. Before any docstring is rendered this
rewrites every role in the package to an autorefs cross-reference:

- a target inside ``fpm_sim`` is resolved as Python resolves the name where the docstring stands (the module's
  members and imports, the class's members, then the parents'); a target that does not resolve is a WARNING, so
  ``mkdocs build --strict`` fails on a broken cross-reference anywhere in the package, rendered on a page or not;
- the resolved reference is "optional": a link where the target is rendered on a page of the site, plain code
  where it is not (the site documents the public surface, not every helper a docstring names);
- a target outside the package (``numpy.ndarray``, ``mujoco.MjModel``) stays plain code: nothing is fetched, so
  there is no other project's inventory to link to.

Also turns a reStructuredText literal-block marker (a line ending in ``::`` before an indented block) into a plain
colon: the indented block after it is already a Markdown code block.
"""

from __future__ import annotations

import builtins
import html
import importlib
import importlib.util
import logging
import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|attr|data|obj|exc|const):`(~?)([^`<>]+?)`")
LITERAL_MARK = re.compile(r"(?<=\S)::(?=\n\n[ \t])")
PACKAGE = "fpm_sim"

# mkdocs counts the WARNINGs of its own loggers in --strict mode
_log = logging.getLogger("mkdocs.plugins.fpm_sim_roles")


def _exists(pkg: griffe.Module, path: str) -> bool:
    if path == pkg.path:
        return True
    try:
        pkg[path.removeprefix(pkg.path + ".")]
    except (KeyError, griffe.AliasResolutionError, griffe.CyclicAliasError):
        return False
    return True


def _external(head: str) -> bool:
    """Whether a name that is not the package's is a builtin or an importable module (another project's object)."""
    if hasattr(builtins, head):
        return True
    try:
        return importlib.util.find_spec(head) is not None
    except (ImportError, ValueError):
        return False


def _runtime(path: str) -> str | None:
    """Where a name the static tree misses lives, by importing it: the lazily exported names (PEP 562 module
    ``__getattr__``: ``fpm_sim.Pose``, ``fpm_sim.study.identify.GROUPS``) and classes defined on first use."""
    parts = path.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        owner = None
        try:
            for name in parts[cut:]:
                owner, obj = obj, getattr(obj, name)
        except AttributeError:
            return None
        module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
        if isinstance(module, str) and isinstance(qualname, str) and "<locals>" not in qualname:
            return f"{module}.{qualname}"
        lazy = getattr(owner, "_NAMES", None) or getattr(owner, "_API", None)  # a module's lazy export table
        if isinstance(lazy, dict) and parts[-1] in lazy:
            return f"{lazy[parts[-1]]}.{parts[-1]}"
        return path
    return None


def _resolve(obj: griffe.Object, pkg: griffe.Module, target: str) -> str | None:
    """The full path of ``target`` as written in ``obj``'s docstring; None when it names nothing."""
    target = re.sub(r"\s+", "", target).lstrip(".")
    head, _, rest = target.partition(".")
    if head == pkg.name:
        return target if _exists(pkg, target) else _runtime(target)
    scope: griffe.Object | None = obj
    while scope is not None:
        try:
            base = scope.resolve(head)
        except griffe.NameResolutionError:
            scope = scope.parent
            continue
        full = f"{base}.{rest}" if rest else base
        if not full.startswith(pkg.name + ".") or _exists(pkg, full):
            return full
        return _runtime(full)
    if _external(head):
        return target
    return _runtime(f"{obj.module.path}.{target}")


def _rewrite(obj: griffe.Object, pkg: griffe.Module, text: str) -> str:
    def replace(match: re.Match[str]) -> str:
        short, target = match.group(1) == "~", match.group(2).strip()
        shown = target.rsplit(".", 1)[-1] if short else target
        full = _resolve(obj, pkg, target)
        if full is None:
            _log.warning("%s: cross-reference %r names nothing in %s", obj.path, match.group(0), pkg.name)
            return f"`{shown}`"
        if not full.startswith(pkg.name):
            return f"`{shown}`"  # another project's object: plain code, no inventory is fetched
        return f'<autoref identifier="{html.escape(full)}" optional><code>{html.escape(shown)}</code></autoref>'

    return LITERAL_MARK.sub(":", ROLE.sub(replace, text))


class SphinxRoles(griffe.Extension):
    """Rewrite the Sphinx roles of every docstring in the loaded package (see the module's docstring)."""

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs: Any) -> None:
        """Rewrite once the whole package is loaded, so that every name can be resolved."""
        if pkg.name != PACKAGE:
            return
        stack: list[griffe.Object] = [pkg]
        while stack:
            obj = stack.pop()
            if obj.docstring is not None:
                obj.docstring.value = _rewrite(obj, pkg, obj.docstring.value)
            stack.extend(m for m in obj.members.values() if not m.is_alias)
