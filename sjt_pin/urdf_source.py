"""A URDF document as ``Robot.from_urdf`` is given it: :func:`read_urdf` turns a file path, or
URDF XML text (``str`` or UTF-8 ``bytes``), into a :class:`URDFSource`, whose label starts
every :class:`~sjt_pin.exceptions.URDFError` about it. Nothing is parsed here
(:mod:`sjt_pin.urdf_check` checks the document)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from .exceptions import URDFError

STRING_LABEL = "<URDF string>"


@dataclass(frozen=True)
class URDFSource:
    """A URDF document to parse: XML text given in the call, or a file."""

    label: str  #: the file path, or ``<URDF string>``: every error message starts with it
    data: bytes  #: the document's bytes
    path: Path | None = None  #: the file; None for XML text

    @property
    def text(self) -> str:
        """The document as text (XML text sources are UTF-8 encoded in ``data``)."""
        return self.data.decode("utf-8", errors="replace")

    def error(self, problem: str) -> URDFError:
        """A :class:`URDFError` naming this source."""
        return URDFError(f"invalid URDF {self.label}: {problem}")


# -- the argument ------------------------------------------------------------------------------
def read_urdf(path_or_xml: str | bytes | os.PathLike) -> URDFSource:
    """``path_or_xml`` as a :class:`URDFSource`: a file path (``str`` or ``os.PathLike``), or
    URDF XML text (a ``str``, or UTF-8 ``bytes``, starting with ``<``).

    Raises ``TypeError`` for other types and for bytes that are not XML text, and
    :class:`URDFError` for an empty string, text that is neither XML nor a file name, a missing
    file, a directory, or an unreadable or empty file.
    """
    if isinstance(path_or_xml, (bytes, bytearray)):
        return _xml_text(_decoded(bytes(path_or_xml)))
    if isinstance(path_or_xml, str):
        if not path_or_xml.strip():
            raise URDFError(f"empty URDF: path_or_xml is {path_or_xml!r}; pass a URDF file path "
                            "or URDF XML text")
        if path_or_xml.lstrip().startswith("<"):
            return _xml_text(path_or_xml)
        if not path_or_xml.isprintable():
            raise URDFError("path_or_xml is neither a URDF file path nor URDF XML text (XML "
                            f"starts with '<'): got {preview(path_or_xml)}")
    elif not isinstance(path_or_xml, os.PathLike):
        raise TypeError("path_or_xml must be a URDF file path (str or os.PathLike) or URDF XML "
                        f"text (str or bytes starting with '<'), got {type(path_or_xml).__name__}")
    return _file(Path(path_or_xml))


def _decoded(data: bytes) -> str:
    """UTF-8 ``bytes`` of XML text as ``str``; ``TypeError`` if they do not start with ``<``."""
    if not starts_xml(data):
        raise TypeError("path_or_xml as bytes must be URDF XML text starting with '<', got "
                        f"{preview(data)}; pass a file path as str or pathlib.Path")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise URDFError(f"path_or_xml: the URDF bytes are not UTF-8 text: {exc}") from exc


def starts_xml(data: bytes) -> bool:
    """Whether ``data`` starts with ``<`` after white space and a UTF-8 byte order mark."""
    return data.lstrip().removeprefix(b"\xef\xbb\xbf").lstrip().startswith(b"<")


def _xml_text(text: str) -> URDFSource:
    return URDFSource(STRING_LABEL, text.encode("utf-8"))


def _file(path: Path) -> URDFSource:
    """The URDF file at ``path``, read; :class:`URDFError` if it is missing, a directory,
    unreadable or empty."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise URDFError(f"URDF file not found: {path}") from None
    except IsADirectoryError:
        urdfs = sorted(p.name for p in path.glob("*.urdf"))
        hint = f" (URDF files in it: {urdfs})" if urdfs else ""
        raise URDFError(f"URDF path {path} is a directory, not a file{hint}") from None
    except OSError as exc:
        raise URDFError(f"cannot read URDF file {preview(str(path))}: {exc.strerror}; "
                        "path_or_xml must be a URDF file path or URDF XML text") from exc
    if not data.strip():
        raise URDFError(f"empty URDF: the file {path} is empty")
    return URDFSource(str(path), data, path)


def preview(value: str | bytes, size: int = 60) -> str:
    """``repr`` of the start of ``value``, for messages."""
    return repr(value[:size]) + ("..." if len(value) > size else "")
