"""Where a URDF's mesh files may be read from: its own folder and the given ``package_dirs``.

A URDF is data, possibly untrusted, and its ``<mesh filename>`` is a path: ``../``, an absolute
path, a ``file://`` URI, ``package://pkg/../elsewhere`` or a symbolic link inside a package would
make the loader (Pinocchio) and the viewer read, and ``save_html`` publish, any file the process
can read. Here every mesh reference is resolved as Pinocchio resolves it, then with ``..`` and
symbolic links resolved (``os.path.realpath``); the file must lie inside

- the folder of the package it names (``package://pkg/...`` found as ``<dir>/pkg/...`` in the
  first of ``package_dirs`` that has it), or
- for any other reference (relative, absolute or ``file://``), the URDF file's own folder or one
  of ``package_dirs``.

Anything else raises :class:`URDFError` naming the path, unless the caller opts in
(``allow_outside_meshes=True``). A missing package names the folder to pass.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from lxml import etree

from .exceptions import URDFError

PACKAGE = "package://"
FILE = "file://"


def mesh_references(data: bytes) -> list[tuple[str, str]]:
    """``(link name, filename)`` of every ``<mesh>`` in the URDF document ``data``."""
    parser = etree.XMLParser(resolve_entities=False, no_network=True)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError:
        return []  # the URDF check reports it
    found = []
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename")
        if filename is None:
            continue
        link = next((a.get("name") for a in mesh.iterancestors("link")), None)
        found.append((link or "?", filename))
    return found


def package_of(filename: str) -> str | None:
    """The package a ``package://pkg/...`` reference names (None for other references)."""
    if not filename.startswith(PACKAGE):
        return None
    return filename[len(PACKAGE):].lstrip("/").split("/", 1)[0]


def guess_package_dirs(urdf: Path, references: Iterable[tuple[str, str]],
                       dirs: Sequence[str]) -> list[str]:
    """Folders to add to ``dirs`` so that ``package://pkg/...`` references resolve: for a
    package not found in ``dirs``, the parent of the nearest folder named ``pkg`` that holds
    the URDF (example-robot-data's files name ``package://example-robot-data/robots/...``, so
    this is the folder containing ``example-robot-data``; a ROS package's files name their own
    package)."""
    added: list[str] = []
    for package in sorted({p for _, f in references if (p := package_of(f))}):
        if any(os.path.isdir(os.path.join(d, package)) for d in [*dirs, *added]):
            continue
        for folder in urdf.resolve().parents:
            if folder.name == package:
                added.append(str(folder.parent))
                break
    return added


def resolve(filename: str, dirs: Sequence[str]) -> tuple[str | None, Path | None]:
    """``(the file Pinocchio would read, the folder it must lie inside)`` for one reference, as
    Pinocchio resolves it: ``package://pkg/rest`` and a relative path as ``<dir>/...`` in the
    first of ``dirs`` that has it (``from_urdf`` puts the URDF's folder last), ``file://`` and
    absolute paths as they are. The file is None when no folder has it; the folder is None when
    any allowed root will do."""
    if filename.startswith(FILE):
        return filename[len(FILE):], None
    if os.path.isabs(filename):
        return filename, None
    package = package_of(filename)
    rest = filename[len(PACKAGE):] if package is not None else filename
    for folder in dirs:
        candidate = folder.rstrip("/") + "/" + rest  # as Pinocchio joins them
        if os.path.exists(candidate):
            within = None if package is None else Path(os.path.realpath(os.path.join(folder,
                                                                                      package)))
            return candidate, within
    return None, None


def not_found(filename: str, dirs: Sequence[str]) -> str:
    """Why ``filename`` was not found, and which folder to pass."""
    package = package_of(filename)
    if package is None:
        return f"mesh {filename!r} is in none of package_dirs={list(dirs)}"
    return (f"mesh {filename!r}: no folder {package!r} in package_dirs={list(dirs)}; pass "
            f"package_dirs=[the folder that contains {package!r}]{_package_hint(package)}")


def _package_hint(package: str) -> str:
    """For example-robot-data's package, the exact folder to pass."""
    if package != "example-robot-data":
        return ""
    try:
        import example_robot_data as erd
        robots = Path(erd.getModelPath("ur_description/urdf/ur5_robot.urdf")).resolve()
    except (ImportError, OSError):
        return ""
    return f" (here: package_dirs=[{str(robots.parent.parent)!r}])"


def roots(urdf_dir: Path | None, dirs: Sequence[str]) -> tuple[Path, ...]:
    """The folders (resolved) mesh files may lie in: the URDF's own and ``dirs``."""
    folders = [*dirs] + ([str(urdf_dir)] if urdf_dir is not None else [])
    return tuple(dict.fromkeys(Path(os.path.realpath(f)) for f in folders))


def inside(path: str | os.PathLike, folders: Iterable[Path]) -> bool:
    """Whether ``path``, with ``..`` and symbolic links resolved, lies in one of ``folders``."""
    real = Path(os.path.realpath(path))
    return any(real == folder or folder in real.parents for folder in folders)


def check_file(path: str | os.PathLike, folders: Sequence[Path] | None, what: str = "mesh") -> str:
    """``path`` resolved, if it lies inside ``folders`` (None: anywhere) and is a regular
    file; otherwise :class:`URDFError` naming it."""
    real = os.path.realpath(path)
    if folders is not None and not inside(real, folders):
        raise URDFError(f"{what} file {str(path)!r} (resolved: {real}) lies outside the URDF's "
                        f"folder and package_dirs {[str(f) for f in folders]}; it is not read "
                        "(pass allow_outside_meshes=True to read it anyway)")
    if not os.path.isfile(real):
        raise URDFError(f"{what} file {str(path)!r} (resolved: {real}) is not a file")
    return real


def check_references(label: str, data: bytes, urdf_dir: Path | None, dirs: Sequence[str],
                     allow_outside: bool = False, must_exist: bool = True) -> None:
    """Raise :class:`URDFError` (starting with ``label``) for a mesh reference of the URDF
    ``data`` that resolves outside its allowed folder or (``must_exist``) to no file."""
    allowed = roots(urdf_dir, dirs)
    for link, filename in mesh_references(data):
        path, package = resolve(filename, dirs)
        try:
            if path is None:
                if must_exist:
                    raise URDFError(not_found(filename, dirs))
                continue
            if allow_outside or not (must_exist or os.path.exists(path)):
                continue
            check_file(path, allowed if package is None else (package,))
        except URDFError as exc:
            raise URDFError(f"invalid URDF {label}: link {link!r}: {exc}") from None


def check_geometry(geometry_model, folders: Sequence[Path] | None, label: str) -> None:
    """Raise :class:`URDFError` if a mesh of ``geometry_model`` (a ``pin.GeometryModel``) lies
    outside ``folders`` (None: no check)."""
    if folders is None or geometry_model is None:
        return
    for geometry in geometry_model.geometryObjects:
        if geometry.meshPath and os.path.exists(geometry.meshPath):
            try:
                check_file(geometry.meshPath, folders)
            except URDFError as exc:
                raise URDFError(f"{label}: geometry {geometry.name!r}: {exc}") from None


def geometry_roots(urdf: str | None, package_dirs: Sequence[str], geometries: Iterable,
                   label: str) -> tuple[Path, ...] | None:
    """The folders a robot's meshes may be read from (the ``package_dirs`` and the folder of
    its ``urdf`` file), each of its ``geometries`` checked against them; ``None`` when there
    are none (geometry the caller built, naming no URDF file or folder, is the caller's)."""
    urdf_dir = (Path(urdf).resolve().parent if urdf is not None and
                not urdf.lstrip().startswith("<") else None)
    # geometry the caller built, naming no URDF file or folder, is theirs: None
    mesh_roots = roots(urdf_dir, package_dirs) or None
    if mesh_roots is not None:
        for geometry in geometries:
            check_geometry(geometry, mesh_roots, label)
    return mesh_roots
