"""Import a user map (OpenDRIVE ``.xodr`` or SUMO ``.net.xml``) under a new name.

The map is converted / validated in a temporary directory and moved into
:func:`~hbmp_bench.maps.registry.user_maps_dir` only on success, so a failed import
leaves nothing behind.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

from .netconvert import run_netconvert
from .registry import NET_SUFFIX, user_maps_dir
from .towns import TOWNS

#: netconvert options for OpenDRIVE imports.
XODR_OPTIONS: tuple[str, ...] = (
    "--sidewalks.guess", "true",
    "--crossings.guess", "true",
    "--tls.guess", "true",
    "--geometry.min-radius.fix", "true",
    "--geometry.remove", "true",
    "--opendrive.curve-resolution", "1",
    "--opendrive.import-all-lanes", "true",
    "--junctions.join", "false",
    "--no-turnarounds", "true",
    "--output.street-names", "false",
    "--xml-validation", "never",
    "--no-warnings", "true",
)

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


def _check_name(name: str) -> None:
    if not isinstance(name, str) or not _NAME.fullmatch(name) or name.endswith(NET_SUFFIX):
        raise ValueError(f"invalid map name {name!r}: use letters, digits, '_', '-', '.'")
    if name in TOWNS or name.lower() in {t.lower() for t in TOWNS}:
        raise ValueError(f"map name {name!r} would shadow a built-in town")


def validate_net(path: Path) -> None:
    """Raise ValueError unless ``path`` is a SUMO net with at least one normal edge."""
    try:
        import sumolib

        net = sumolib.net.readNet(str(path), withInternal=True,
                                  withPedestrianConnections=True)
    except Exception as exc:  # sumolib raises a mix of SAX, KeyError, ValueError
        raise ValueError(f"{path.name} is not a readable SUMO net: {exc}") from exc
    if not net.getEdges(withInternal=False):
        raise ValueError(f"{path.name} has no edges")


def _quick_xml_check(path: Path, root_tag: str) -> None:
    try:
        for _event, elem in ET.iterparse(path, events=("start",)):
            tag = elem.tag.rsplit("}", 1)[-1]
            if tag != root_tag:
                raise ValueError(f"{path.name}: root element is <{tag}>, not <{root_tag}>")
            return
    except ET.ParseError as exc:
        raise ValueError(f"{path.name} is not well-formed XML: {exc}") from exc
    raise ValueError(f"{path.name} is empty")


def import_map(path: str | Path, name: str) -> Path:
    """Import the map at ``path`` as ``name``; returns the stored ``.net.xml``.

    ``.xodr`` files are converted with netconvert (:data:`XODR_OPTIONS`); ``.net.xml``
    files are validated by reading them with sumolib. An existing import of the same
    name is replaced.

    Raises FileNotFoundError for a missing file and ValueError for a bad name, a wrong
    extension or a malformed file; nothing is written then.
    """
    _check_name(name)
    src = Path(path).expanduser()
    if not src.is_file():
        raise FileNotFoundError(f"map file not found: {src}")
    lower = src.name.lower()
    if not (lower.endswith(".xodr") or lower.endswith(NET_SUFFIX)):
        raise ValueError(f"{src.name}: expected an OpenDRIVE .xodr or a SUMO .net.xml file")

    with tempfile.TemporaryDirectory(prefix="hbmp_import_") as tmp:
        tmp_dir = Path(tmp)
        staged = tmp_dir / f"{name}{NET_SUFFIX}"
        if lower.endswith(".xodr"):
            _quick_xml_check(src, "OpenDRIVE")
            shutil.copyfile(src, tmp_dir / "input.xodr")
            try:
                run_netconvert(["--opendrive-files", "input.xodr", *XODR_OPTIONS,
                                "--output-file", staged.name], cwd=tmp_dir)
            except RuntimeError as exc:
                raise ValueError(f"{src.name}: OpenDRIVE conversion failed: {exc}") from exc
        else:
            _quick_xml_check(src, "net")
            shutil.copyfile(src, staged)
        validate_net(staged)
        dest_dir = user_maps_dir()
        dest_dir.mkdir(parents=True, exist_ok=True)
        target = dest_dir / staged.name
        partial = dest_dir / f".{staged.name}.partial"
        try:
            shutil.copyfile(staged, partial)
            os.replace(partial, target)  # atomic within dest_dir
        finally:
            partial.unlink(missing_ok=True)
    return target
