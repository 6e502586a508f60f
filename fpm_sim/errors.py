"""The one error hierarchy of fpm-sim and its contract.

Every failure a user can cause (a bad description, an unreachable pose, an unwritable output, a
diverging simulation) raises a subclass of :class:`FpmSimError`; the command line maps exactly these to
exit code 2 with one ``error: ...`` line. Any other exception is a bug in fpm-sim and keeps its traceback.
Warnings that concern the user's input derive from :class:`FpmSimWarning`.

The contract: an error names what is wrong in the *library's* words. It carries

- ``parameter``: the library name of the offending value (``"section.thickness_m"``, ``"n_modes"``,
  ``"measured"``), never a command-line flag; the command line maps it to its option name
  (:data:`fpm_sim.cli.common.OPTION_NAMES`);
- ``value``: the offending value (SI units, as the parameter's name says), when there is one;
- ``hint``: how to fix it;
- ``file`` and ``row``: where the value was read, for values read from a file.

The message is built from these: ``"<file>: row <row>: <parameter>: <message>, got <value>; <hint>"``.
``FpmSimError("a plain message")`` keeps working.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["FpmSimError", "FpmSimWarning", "read_text_input"]

_UNSET: Any = type("_Unset", (), {"__repr__": lambda self: "<unset>"})()


def _show(value: Any) -> str:
    """``repr`` of a value, NumPy scalars as plain Python numbers (``0.5``, not ``np.float64(0.5)``)."""
    item = getattr(value, "item", None)
    if callable(item) and getattr(value, "shape", None) == ():
        value = item()
    return repr(value)


def _rebuild(cls: type[FpmSimError], message: str, fields: dict[str, Any]) -> FpmSimError:
    """Unpickling (errors cross process boundaries in the pose loops): the fields survive."""
    exc = cls.__new__(cls)
    FpmSimError.__init__(exc, message, **fields)
    return exc


class FpmSimError(ValueError):
    """A failure caused by the input; names the parameter or file, the value and how to fix it.

    Derives from :class:`ValueError` so that callers catching ``ValueError`` keep working.
    """

    def __init__(
        self,
        message: str = "",
        *,
        parameter: str | None = None,
        value: Any = _UNSET,
        hint: str | None = None,
        file: Any = None,
        row: int | None = None,
    ) -> None:
        self.message = message
        self.parameter = parameter
        self.value = value
        self.hint = hint
        self.file = None if file is None else str(file)
        self.row = row
        super().__init__(self.render())

    @property
    def has_value(self) -> bool:
        """Whether the error carries the offending value."""
        return self.value is not _UNSET

    def render(self, parameter: str | None = None, value: str | None = None) -> str:
        """Build the message, with ``parameter`` / ``value`` (already formatted) in place of the library's ones.

        The command line passes its option name and the value in the option's unit here.
        """
        name = parameter or self.parameter
        text = self.message or ("invalid value" if name else "invalid input")
        if name:
            text = f"{name}: {text}"
        if self.has_value:
            text += f", got {value if value is not None else _show(self.value)}"
        if self.hint:
            text += f"; {self.hint}"
        if self.row is not None:
            text = f"row {self.row}: {text}"
        if self.file:
            text = f"{self.file}: {text}"
        return text

    def __str__(self) -> str:
        """Build the message from the fields (they may be set after construction, e.g. ``file``)."""
        return self.render()

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickle with the fields (errors cross process boundaries in the pose loops)."""
        fields: dict[str, Any] = {"parameter": self.parameter, "hint": self.hint, "file": self.file, "row": self.row}
        if self.has_value:
            fields["value"] = self.value
        return (_rebuild, (type(self), self.message, fields))


class FpmSimWarning(UserWarning):
    """A result computed from questionable input (near a singularity, coarse resolution, ...).

    ``parameter`` optionally names the library parameter to change (the command line shows its option).
    """

    def __init__(self, message: str = "", *, parameter: str | None = None) -> None:
        self.parameter = parameter
        super().__init__(message)

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickle with ``parameter``."""
        return (_rebuild_warning, (type(self), str(self), self.parameter))


def _rebuild_warning(cls: type[FpmSimWarning], message: str, parameter: str | None) -> FpmSimWarning:
    w = cls.__new__(cls)
    FpmSimWarning.__init__(w, message, parameter=parameter)
    return w


def read_text_input(
    path: str | Path,
    *,
    error: type[FpmSimError] = FpmSimError,
    parameter: str | None = None,
    kind: str = "a text file",
    hint: str | None = None,
    newline: str | None = None,
) -> str:
    """Read an input file's text (UTF-8, a byte-order mark dropped): for every reader of a text format (TOML, CSV).

    A binary file (not UTF-8, or holding NUL bytes) is refused with ``error`` naming ``parameter`` (the option the
    file came from, on the command line) and saying what the file is not (``kind``: ``"a TOML file"``) and how to
    fix it (``hint``), instead of a ``UnicodeDecodeError`` from deep inside a parser. A missing file or a folder
    raises the ``OSError`` of :func:`open`: each reader words those its own way. ``newline`` as for :func:`open`
    (``""`` for the :mod:`csv` module).
    """
    p = Path(path)
    try:
        with open(p, encoding="utf-8-sig", newline=newline) as fh:
            text = fh.read()
    except UnicodeDecodeError as exc:
        raise error(
            f"{p} is not {kind}: binary, not UTF-8 text (byte {exc.start})", parameter=parameter, hint=hint
        ) from None
    nul = text.find("\x00")
    if nul >= 0:
        raise error(f"{p} is not {kind}: binary (a NUL byte at character {nul})", parameter=parameter, hint=hint)
    return text
