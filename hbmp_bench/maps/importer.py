"""Import a user map (OpenDRIVE ``.xodr`` or SUMO ``.net.xml``) under a new name.

What an import does:

1. ``.xodr``: netconvert with the benchmark's lane type map (:mod:`~hbmp_bench.maps.lanetypes`:
   only driving lanes carry cars, sidewalks carry pedestrians, parking, shoulder, bidirectional and
   other lanes stay closed) and the map's own traffic lights (no ``--tls.guess``). ``.net.xml``: read
   as it is.
2. Lanes typed as anything but a car lane that are open to cars (CARLA's own SUMO nets keep parking
   and bidirectional lanes for cars) are closed (:func:`~hbmp_bench.maps.lanetypes.lane_patches`).
3. A map without any walkable edge gets sidewalks and crossings guessed (``sidewalks=False`` keeps
   it as it is); traffic lights are guessed at junctions without a light only when asked
   (``guess_lights``); ``lights="lawful"`` rebuilds the programs with the benchmark's lawful timing
   (the built-in towns' all-red, greens and kinematic yellows, :mod:`~hbmp_bench.maps.signals`),
   ``"source"`` keeps the map's (re-phased by netconvert only where guessed crossings join a light).
   Crossings at nodes that only join two pieces of a road are discarded (:mod:`~hbmp_bench.maps.crossings`:
   netconvert widens such a node over the road for the crossing and cuts the piece between to a stub).
   Steps 2 and 3 are one netconvert run over the net (and one more to drop the crossings the sidewalk
   guess adds at such nodes); then each drivable lane's speed limit is lowered to what its bends allow
   (:mod:`~hbmp_bench.maps.curves`, 4 m/s²). A net that needs none of it is stored byte for byte.
4. Provenance beside the net (``<name>.map.json``, :func:`map_info`): the source file's name and
   SHA-256, the stored net's SHA-256 (records are keyed to it), the netconvert version and every
   option it ran with, the date, and the task parameters (``like``: a built-in town whose CoRL
   counts and route lengths the map borrows).

The map is converted and checked in a temporary directory and moved into
:func:`~hbmp_bench.maps.registry.user_maps_dir` only on success, so a failed import leaves nothing
behind; an existing map of the same name is replaced only with ``force``.
"""

from __future__ import annotations

import datetime
import json
import os
import re
import shutil
import tempfile
import xml.etree.ElementTree as ET
import xml.parsers.expat
from pathlib import Path

from ..errors import UnknownNameError, UserError
from .crossings import continuation_crossings, discard_xml
from .curves import limit_curve_speeds
from .lanetypes import allows, lane_patches, patch_xml, typemap_xml
from .netconvert import netconvert_version, run_netconvert
from .registry import INFO_SUFFIX, NET_SUFFIX, file_sha256, info_path, user_maps, user_maps_dir
from .signals import ALL_RED_TIME_S, CROSSING_CLEARANCE_S, retime_yellows
from .towns import TOWNS

XODR_OPTIONS: tuple[str, ...] = (
    "--opendrive.import-all-lanes", "true",
    "--crossings.guess", "true",
    "--tls.guess", "false",
    "--geometry.min-radius.fix", "true",
    "--geometry.remove", "true",
    "--opendrive.curve-resolution", "1",
    "--opendrive.internal-shapes", "true",
    "--junctions.join", "false",
    "--no-turnarounds", "true",
    "--output.street-names", "false",
    "--xml-validation", "never",
    "--no-warnings", "true",
)
"""netconvert options of an OpenDRIVE import (with ``--type-files``: the lane type map). Junction lanes take
the shapes of the file's connecting roads (``--opendrive.internal-shapes``): netconvert's own shapes join the
lane ends by a straight chord where a road piece before the junction is too short to give a direction (CARLA's
Town07 has 0.1 m pieces), and the ego turning on such a chord cut the corner 2.5 m onto the shoulder."""

NET_OPTIONS: tuple[str, ...] = (
    "--xml-validation", "never",
    "--no-warnings", "true",
    "--offset.disable-normalization", "true",
)
"""netconvert options of every run over a SUMO net (lane patches, guesses, lights)."""

SIDEWALK_OPTIONS: tuple[str, ...] = ("--sidewalks.guess", "true", "--crossings.guess", "true")
"""Sidewalks beside every road edge of 5.8 to 13.9 m/s (netconvert's range) and crossings at junctions."""

LAWFUL_LIGHT_OPTIONS: tuple[str, ...] = (
    "--tls.rebuild", "true",
    "--tls.green.time", "20",
    "--tls.allred.time", str(ALL_RED_TIME_S),
    "--tls.left-green.time", "0",
    "--tls.crossing-clearance.time", str(CROSSING_CLEARANCE_S),
)
"""The built-in towns' light programs (20 s greens, all-red after each yellow, no protected lefts);
the yellows are then re-timed (:func:`~hbmp_bench.maps.signals.retime_yellows`)."""

LIGHTS = ("source", "lawful")
"""Light programs of an import: the map's own, or the benchmark's lawful ones."""

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


def _check_name(name: str) -> None:
    if not isinstance(name, str) or not _NAME.fullmatch(name) or name.endswith(NET_SUFFIX):
        raise UserError(f"invalid map name {name!r}: use letters, digits, '_', '-', '.'")
    if name in TOWNS or name.lower() in {t.lower() for t in TOWNS}:
        raise UserError(f"map name {name!r} would shadow a built-in town")


def validate_net(path: Path, source: str | None = None) -> None:
    """Raise UserError unless ``path`` is a SUMO net with a road a car may drive; the message names
    ``source`` (the user's file) rather than the staged copy."""
    label = source or path.name
    try:
        import sumolib

        net = sumolib.net.readNet(str(path), withInternal=True, withPedestrianConnections=True)
    except Exception as exc:  # sumolib raises a mix of SAX, KeyError, ValueError
        raise UserError(f"{label} is not a readable SUMO net: {str(exc).replace(str(path), label)}") from exc
    edges = net.getEdges(withInternal=False)
    if not edges:
        raise UserError(f"{label} has no edges")
    if not any(ln.allows("passenger") for e in edges for ln in e.getLanes()):
        raise UserError(f"{label} has no lane a car may drive (no driving lane)")


class _RootFound(Exception):
    """Raised by the prolog check's handler at the first element (its name)."""


def _quick_xml_check(path: Path, root_tag: str, label: str) -> None:
    """Before netconvert or sumolib read the file: it holds an XML element, the right root element,
    and no document type declaration (entity expansion) anywhere before it. Reads up to the root
    element's start."""
    parser = xml.parsers.expat.ParserCreate()

    def doctype(*_args) -> None:
        raise UserError(f"{label}: document type declarations are not accepted in a map file")

    def start(name: str, _attrs) -> None:
        raise _RootFound(name)

    parser.StartDoctypeDeclHandler = doctype
    parser.StartElementHandler = start
    try:
        with open(path, "rb") as f:
            while chunk := f.read(1 << 16):
                parser.Parse(chunk, False)
            parser.Parse(b"", True)
    except _RootFound as found:
        tag = found.args[0].rsplit(":", 1)[-1]
        if tag != root_tag:
            raise UserError(f"{label}: root element is <{tag}>, not <{root_tag}>") from None
        return
    except xml.parsers.expat.ExpatError as exc:
        if exc.code == xml.parsers.expat.errors.codes[xml.parsers.expat.errors.XML_ERROR_NO_ELEMENTS]:
            raise UserError(f"{label} is empty (no XML element)") from None
        raise UserError(f"{label} is not well-formed XML: {exc}") from None
    raise UserError(f"{label} is empty (no XML element)")  # pragma: no cover - expat raises first


def _netconvert(args: list[str], cwd: Path, label: str, what: str) -> None:
    try:
        run_netconvert(args, cwd=cwd)
    except RuntimeError as exc:
        msg = str(exc).replace("input.xodr", label).replace("input.net.xml", label)
        raise UserError(f"{label}: {what} failed: {msg}") from exc


def _has_walkable_edge(root: ET.Element) -> bool:
    return any(allows(lane, "pedestrian") for edge in root.iter("edge") if edge.get("function", "normal") == "normal"
               for lane in edge.findall("lane"))


def _tls_count(root: ET.Element) -> int:
    return len(root.findall("tlLogic"))


def import_map(path: str | Path, name: str, *, like: str | None = None, sidewalks: bool = True,
               guess_lights: bool = False, lights: str = "source", force: bool = False) -> Path:
    """Import the map at ``path`` as ``name``; returns the stored ``.net.xml`` (see the module docstring).

    Args:
        like: a built-in town whose task parameters the map takes (CoRL2017 traffic counts and route
            lengths); None: from the map's own size.
        sidewalks: guess sidewalks and crossings when the map has no walkable edge.
        guess_lights: add traffic lights at junctions without one (netconvert's ``--tls.guess``).
        lights: ``"source"`` or ``"lawful"`` (:data:`LIGHTS`).
        force: replace an imported map of the same name.

    Raises FileNotFoundError for a missing file, UnknownNameError for a bad ``like`` or ``lights``,
    and UserError (a ValueError) for a bad name, an existing map without ``force``, a wrong
    extension or a file that does not convert; nothing is written then.
    """
    src, lower = _check_import(path, name, like, lights, force)
    label = src.name
    runs: list[list[str]] = []
    with tempfile.TemporaryDirectory(prefix="hbmp_import_") as tmp:
        tmp_dir = Path(tmp)
        staged = _stage(src, tmp_dir, label, runs)
        validate_net(staged, label)
        root = ET.parse(staged).getroot()
        source_tls = _tls_count(root)
        patches = lane_patches(root)
        discarded = continuation_crossings(root)
        guess_sidewalks = sidewalks and not _has_walkable_edge(root)
        final = staged
        if patches or discarded or guess_sidewalks or guess_lights or lights == "lawful":
            final, discarded = _rebuild(staged, tmp_dir, label, runs, patches, discarded, guess_sidewalks,
                                        guess_lights, lights)
        curves_lowered = limit_curve_speeds(final)
        if lights == "lawful":
            retime_yellows(final)  # after the curve speeds: yellows follow the approach speeds
        if runs:
            _strip_header(final)
        if final is not staged or curves_lowered:
            validate_net(final, label)
        info = {
            "name": name,
            "source": label,
            "source_sha256": file_sha256(src),
            "format": "xodr" if lower.endswith(".xodr") else "net.xml",
            "net_sha256": file_sha256(final),
            "netconvert": netconvert_version() if runs else None,
            "netconvert_runs": runs,
            "imported_at": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "like": like,
            "lights": lights,
            "source_tls": source_tls,
            "tls_guessed": guess_lights,
            "lanes_closed": {kind: sum(p[2] == kind for p in patches) for kind in sorted({p[2] for p in patches})},
            "sidewalks_guessed": guess_sidewalks,
            "crossings_discarded": len(discarded),
            "curve_speed_lanes": curves_lowered,
        }
        _install(final, info, name)
    return user_maps_dir() / f"{name}{NET_SUFFIX}"


def _check_import(path: str | Path, name: str, like: str | None, lights: str, force: bool) -> tuple[Path, str]:
    """Refuse an import before anything is written (see :func:`import_map`); (the source file, its lower-case
    name)."""
    _check_name(name)
    if like is not None and like not in TOWNS:
        raise UnknownNameError("town", like, TOWNS)
    if lights not in LIGHTS:
        raise UnknownNameError("lights", lights, LIGHTS)
    src = Path(path).expanduser()
    if not src.is_file():
        raise FileNotFoundError(f"map file not found: {src}")
    lower = src.name.lower()
    if not (lower.endswith(".xodr") or lower.endswith(NET_SUFFIX)):
        raise UserError(f"{src.name}: expected an OpenDRIVE .xodr or a SUMO .net.xml file")
    if name in user_maps() and not force:
        previous = map_info(name)
        raise UserError(f"map {name!r} exists (imported from {previous.get('source', '?')} on "
                        f"{previous.get('imported_at', '?')}); use --force (force=True) to replace it")
    return src, lower


def _stage(src: Path, tmp_dir: Path, label: str, runs: list[list[str]]) -> Path:
    """``input.net.xml`` in ``tmp_dir``: the SUMO net as it is, or netconvert's conversion of the OpenDRIVE file
    (its options appended to ``runs``)."""
    staged = tmp_dir / "input.net.xml"
    if src.name.lower().endswith(".xodr"):
        _quick_xml_check(src, "OpenDRIVE", label)
        shutil.copyfile(src, tmp_dir / "input.xodr")
        (tmp_dir / "lanetypes.typ.xml").write_text(typemap_xml(), encoding="utf-8")
        args = ["--opendrive-files", "input.xodr", "--type-files", "lanetypes.typ.xml", *XODR_OPTIONS,
                "--output-file", staged.name]
        _netconvert(args, tmp_dir, label, "OpenDRIVE conversion")
        runs.append(args)
    else:
        _quick_xml_check(src, "net", label)
        shutil.copyfile(src, staged)
    return staged


def _rebuild(staged: Path, tmp_dir: Path, label: str, runs: list[list[str]], patches, discarded: list,
             guess_sidewalks: bool, guess_lights: bool, lights: str) -> tuple[Path, list]:
    """(``output.net.xml``, the crossings discarded): the staged net rebuilt by netconvert with the lane patches,
    the ``discarded`` crossings (and those the sidewalk guess put at continuation nodes, dropped by one more pass),
    guessed sidewalks and lights and the lawful light timing asked for; each pass's options appended to ``runs``."""
    args = ["--sumo-net-file", staged.name, *NET_OPTIONS]
    if patches:
        (tmp_dir / "lanetypes.edg.xml").write_text(patch_xml(patches), encoding="utf-8")
        args += ["--edge-files", "lanetypes.edg.xml"]
    if discarded:
        (tmp_dir / "crossings.con.xml").write_text(discard_xml(discarded), encoding="utf-8")
        args += ["--connection-files", "crossings.con.xml"]
    if guess_sidewalks:
        args += list(SIDEWALK_OPTIONS)
    if guess_lights:
        args += ["--tls.guess", "true"]
    if lights == "lawful":
        args += list(LAWFUL_LIGHT_OPTIONS)
    final = tmp_dir / "output.net.xml"
    args += ["--output-file", final.name]
    _netconvert(args, tmp_dir, label, "net rebuild")
    runs.append(args)
    guessed = continuation_crossings(ET.parse(final).getroot()) if guess_sidewalks else []
    if guessed:  # crossings the sidewalk guess put at continuation nodes: one more pass drops them
        (tmp_dir / "guessed.con.xml").write_text(discard_xml(guessed), encoding="utf-8")
        staged_again = tmp_dir / "guessed.net.xml"
        final.replace(staged_again)
        args = ["--sumo-net-file", staged_again.name, *NET_OPTIONS, "--connection-files", "guessed.con.xml",
                *(LAWFUL_LIGHT_OPTIONS if lights == "lawful" else ()), "--output-file", final.name]
        _netconvert(args, tmp_dir, label, "crossing removal")
        runs.append(args)
        discarded = discarded + guessed
    return final, discarded


_HEADER = re.compile(rb"<!-- generated on .*?-->\n", re.S)


def _strip_header(path: Path) -> None:
    """Drop the comment netconvert writes at the top of a net it made: its date and the temporary paths it read
    (its options are in the provenance), so that one source file always imports to the same bytes (the net's
    SHA-256, which records and boards are keyed to, is reproducible)."""
    data = path.read_bytes()
    path.write_bytes(_HEADER.sub(b"", data, count=1))


def _install(net: Path, info: dict, name: str) -> None:
    """Move the net and its provenance into the user maps folder: the provenance first, then the net
    (an atomic rename; the net's presence is what lists the map)."""
    dest_dir = user_maps_dir()
    dest_dir.mkdir(parents=True, exist_ok=True)
    targets = [(info_path(name), json.dumps(info, indent=2).encode()), (dest_dir / f"{name}{NET_SUFFIX}", None)]
    for target, blob in targets:
        partial = target.with_name(f".{target.name}.partial")
        try:
            if blob is None:
                shutil.copyfile(net, partial)
            else:
                partial.write_bytes(blob)
            os.replace(partial, target)
        finally:
            partial.unlink(missing_ok=True)


def map_info(name: str) -> dict:
    """Provenance of imported map ``name`` (see the module docstring; ``{}`` for an import that kept
    none). UnknownNameError unless ``name`` is an imported map."""
    if name not in user_maps():
        raise UnknownNameError("imported map", name, user_maps())
    path = info_path(name)
    if not path.is_file():
        return {}
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def remove_map(name: str) -> None:
    """Delete imported map ``name`` (its net and provenance). UnknownNameError for a built-in town or
    an unknown name."""
    if name in TOWNS:
        raise UserError(f"{name!r} is a built-in town; only imported maps can be removed")
    if name not in user_maps():
        raise UnknownNameError("imported map", name, user_maps())
    (user_maps_dir() / f"{name}{NET_SUFFIX}").unlink(missing_ok=True)
    info_path(name).unlink(missing_ok=True)


__all__ = ["INFO_SUFFIX", "LIGHTS", "import_map", "map_info", "remove_map", "validate_net"]
