"""The table's URDF with just the rods in play, assembled from the shipped one (no pybullet)."""

from __future__ import annotations

import contextlib
import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from functools import cache
from importlib import resources
from pathlib import Path

from foosball_gym import table


def urdf_path(name: str = "foosball_table.urdf") -> Path:
    """Path of a URDF shipped with the package (``urdf/`` of the source tree)."""
    try:
        return Path(str(resources.files("foosball_gym.urdf") / name))
    except ModuleNotFoundError:
        # A source checkout imported straight from its directory has no mapped subpackage.
        return Path(__file__).resolve().parents[2] / "urdf" / name


@cache
def urdf_with_rods(rod_names: tuple[str, ...]) -> str:
    """The table URDF's text with only the given rods, built once per process and rod set."""
    tree = ET.parse(urdf_path())
    robot = tree.getroot()
    keep = set(rod_names)

    def rod_of(name: str) -> str | None:
        for rod in table.RODS:
            if name.startswith(rod.name + "_"):
                return rod.name
        return None

    for el in list(robot):
        if el.tag in ("link", "joint"):
            owner = rod_of(el.get("name", ""))
            if owner is not None and owner not in keep:
                robot.remove(el)
    _merge_fixed_links(robot)
    # The copy lives elsewhere, so the meshes it names are given by their full path.
    for mesh in robot.iter("mesh"):
        mesh.set("filename", str(urdf_path(mesh.get("filename", ""))))
    return ET.tostring(robot, encoding="unicode")


@contextlib.contextmanager
def urdf_file(text: str) -> Iterator[str]:
    """The path of a file holding ``text`` while the context lasts, for Bullet, which loads a
    URDF only from a file.

    The file is written into a folder made for it that only this user can open (mode 0700)
    and removed with it afterwards, so what Bullet reads is what was written here: no one
    else can put a table of their own in its place between the writing and the loading (in
    a shared temp folder, a file another user made first, or rewrote later, was loaded as
    it was).
    """
    with tempfile.TemporaryDirectory(prefix="foosball_gym_") as folder:
        path = os.path.join(folder, "table.urdf")
        # O_EXCL: a fresh file of this user's, never one that was there.
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(text)
        yield path


@cache
def urdf_for_window(rod_names: tuple[str, ...]) -> str:
    """The table's URDF text with the rods ``rod_names`` as the GUI window draws them: the
    rods' figurines only, without the table's parts and the rods' bars. For the window only:
    nothing in it collides with the table.

    PyBullet's GUI draws all the shapes of one link in one colour, the last one's: the table
    link (field, walls, goal pockets) came out in the pockets' near-black and a rod's bar in
    its team's colour. The window draws those parts as bodies of their own
    (:func:`table_boxes`), each in its colour.
    """
    robot = ET.fromstring(urdf_with_rods(rod_names))
    for link in robot.findall("link"):
        for visual in link.findall("visual"):
            if visual.get("name", "").endswith("_bar"):
                link.remove(visual)
        if link.get("name") == "table":
            # The collision shapes too: the GUI draws those of a link without visual shapes.
            for part in link.findall("visual") + link.findall("collision"):
                link.remove(part)
    return ET.tostring(robot, encoding="unicode")


def table_boxes() -> list[tuple[tuple[float, float, float], tuple[float, float, float], str]]:
    """The table link's visual boxes: (centre, size, material name) of each, from the URDF."""
    boxes = []
    link = next(
        link for link in ET.parse(urdf_path()).getroot().iter("link") if link.get("name") == "table"
    )
    for visual in link.findall("visual"):
        centre = tuple(float(v) for v in _attr(_find(visual, "origin"), "xyz").split())
        box = _find(_find(visual, "geometry"), "box")
        size = tuple(float(v) for v in _attr(box, "size").split())
        material = _attr(_find(visual, "material"), "name")
        boxes.append((centre, size, material))
    return boxes  # type: ignore[return-value]


def _find(element: ET.Element, tag: str) -> ET.Element:
    """``element``'s first ``tag`` child, which the URDF must have."""
    found = element.find(tag)
    if found is None:
        raise ValueError(f"<{element.tag} name={element.get('name')!r}> has no <{tag}>")
    return found


def _attr(element: ET.Element, name: str) -> str:
    """``element``'s attribute ``name``, which the URDF must have."""
    value = element.get(name)
    if value is None:
        raise ValueError(f"<{element.tag} name={element.get('name')!r}> has no {name}=")
    return value


def _merge_fixed_links(robot: ET.Element) -> None:
    """Fold every link on a fixed joint (the figurines) into its parent (the rod).

    This is what Bullet's ``URDF_MERGE_FIXED_LINKS`` does, done before loading because that
    flag leaks about 100 kB of Bullet's memory per load. The order Bullet merges in (a
    parent's first child, then the others last to first) and the way it sums the centre of
    mass are kept, so the table is the same to the last bit.
    """
    links = {link.get("name"): link for link in robot.findall("link")}
    children: dict[str, list[ET.Element]] = {}
    for joint in robot.findall("joint"):
        if joint.get("type") == "fixed":
            children.setdefault(_attr(_find(joint, "parent"), "link"), []).append(joint)
    for parent_name, joints in children.items():
        parent = links[parent_name]
        inertial = _find(parent, "inertial")
        mass = float(_attr(_find(inertial, "mass"), "value"))
        com = [float(v) for v in _attr(_find(inertial, "origin"), "xyz").split()]
        for joint in joints[:1] + joints[:0:-1]:
            child = links[_attr(_find(joint, "child"), "link")]
            offset = [float(v) for v in _attr(_find(joint, "origin"), "xyz").split()]
            if any(float(v) for v in _find(joint, "origin").get("rpy", "0 0 0").split()):
                raise ValueError(f"fixed joint {joint.get('name')} is turned; not merged")
            child_inertial = _find(child, "inertial")
            child_mass = float(_attr(_find(child_inertial, "mass"), "value"))
            child_com = [
                float(v) + o
                for v, o in zip(_attr(_find(child_inertial, "origin"), "xyz").split(), offset)
            ]
            total = mass + child_mass
            com = [(mass * a + child_mass * b) * (1 / total) for a, b in zip(com, child_com)]
            mass = total
            for element in child:
                if element.tag in ("visual", "collision"):
                    origin = _find(element, "origin")
                    xyz = [float(v) for v in _attr(origin, "xyz").split()]
                    origin.set("xyz", " ".join(repr(v + o) for v, o in zip(xyz, offset)))
                    parent.append(element)
            robot.remove(child)
            robot.remove(joint)
        _find(inertial, "mass").set("value", repr(mass))
        _find(inertial, "origin").set("xyz", " ".join(repr(v) for v in com))
