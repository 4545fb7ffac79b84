"""Writes the table and ball URDFs from the numbers in ``foosball_gym.table``.

Run ``python -m foosball_gym.urdf.generate`` after changing ``table.py``; a test checks that the
committed files are what this script writes.

Each rod is a prismatic joint (``<rod>_slide``) carrying a carriage, then a revolute joint
(``<rod>_spin``) carrying the rod, with the figurines fixed to it. The away rods are the home
rods turned by 180 degrees about z, so their joint values mean the same from their own side.
Positive spin swings a figurine's foot towards the goal its team attacks.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

from foosball_gym import table

HERE = Path(__file__).resolve().parent
TABLE_FILE = "foosball_table.urdf"
BALL_FILE = "ball.urdf"
LEG_FILE = "figurine_leg.obj"
# Points on each rounded end of a leg cross-section between its two corners: enough that the
# facets of the hull turn a kick by little (3 per end made the angle jump 6-10 degrees), and
# odd, so one is the tip.
_END_POINTS = 13

COLOURS = table.COLOURS


def _fmt(*values: float) -> str:
    return " ".join(f"{v:.6g}" for v in values)


def _box(
    parent: ET.Element,
    lo: tuple[float, float, float],
    hi: tuple[float, float, float],
    material: str,
    name: str,
) -> None:
    """A visual and a collision box spanning the corners ``lo`` and ``hi``."""
    centre = tuple((a + b) / 2 for a, b in zip(lo, hi))
    size = tuple(b - a for a, b in zip(lo, hi))
    for tag in ("visual", "collision"):
        el = ET.SubElement(parent, tag, name=name)
        ET.SubElement(el, "origin", xyz=_fmt(*centre), rpy="0 0 0")
        geom = ET.SubElement(el, "geometry")
        ET.SubElement(geom, "box", size=_fmt(*size))
        if tag == "visual":
            ET.SubElement(el, "material", name=material)


def _inertial(
    parent: ET.Element,
    mass: float,
    ixx: float,
    iyy: float,
    izz: float,
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> None:
    el = ET.SubElement(parent, "inertial")
    ET.SubElement(el, "origin", xyz=_fmt(*xyz), rpy="0 0 0")
    ET.SubElement(el, "mass", value=_fmt(mass))
    ET.SubElement(
        el, "inertia", ixx=_fmt(ixx), ixy="0", ixz="0", iyy=_fmt(iyy), iyz="0", izz=_fmt(izz)
    )


def _materials(robot: ET.Element) -> None:
    for name, rgba in COLOURS.items():
        mat = ET.SubElement(robot, "material", name=name)
        ET.SubElement(mat, "color", rgba=_fmt(*rgba))


def _table_link(robot: ET.Element) -> None:
    """Surface, side walls, end walls with the goal openings, and a goal pocket behind each."""
    link = ET.SubElement(robot, "link", name="table")
    _inertial(link, 0.0, 0.0, 0.0, 0.0)
    lx, ly, h = table.FIELD_HALF_LENGTH, table.FIELD_HALF_WIDTH, table.WALL_HEIGHT
    w, s = table.WALL_THICKNESS, table.SURFACE_THICKNESS
    gw, gh = table.GOAL_HALF_WIDTH, table.GOAL_HEIGHT
    end_out = lx + table.END_WALL_THICKNESS
    back = table.POCKET_BACK_X
    outer_x = back + w
    _box(link, (-lx, -ly, -s), (lx, ly, 0.0), "field", "surface")
    for side, sign in (("left", 1.0), ("right", -1.0)):
        y0, y1 = sorted((sign * ly, sign * (ly + w)))
        _box(link, (-outer_x, y0, -s), (outer_x, y1, h), "wall", f"{side}_side_wall")
    for team, sign in ((table.HOME, -1.0), (table.AWAY, 1.0)):
        x0, x1 = sorted((sign * lx, sign * end_out))
        for side, ysign in (("left", 1.0), ("right", -1.0)):
            y0, y1 = sorted((ysign * gw, ysign * ly))
            _box(link, (x0, y0, -s), (x1, y1, h), "wall", f"{team}_end_wall_{side}")
        _box(link, (x0, -gw, gh), (x1, gw, h), "wall", f"{team}_goal_crossbar")
        # The pocket: floor, back wall, side walls and a roof, so a goal stays a goal.
        px0, px1 = sorted((sign * end_out, sign * back))
        fx0, fx1 = sorted((sign * lx, sign * back))  # the floor runs on under the goal mouth
        _box(link, (fx0, -gw, -s), (fx1, gw, 0.0), "pocket", f"{team}_pocket_floor")
        _box(link, (px0, -gw - w, gh), (px1, gw + w, gh + w), "pocket", f"{team}_pocket_roof")
        for side, ysign in (("left", 1.0), ("right", -1.0)):
            y0, y1 = sorted((ysign * gw, ysign * (gw + w)))
            _box(link, (px0, y0, -s), (px1, y1, gh), "pocket", f"{team}_pocket_{side}")
        bx0, bx1 = sorted((sign * back, sign * outer_x))
        _box(link, (bx0, -gw - w, -s), (bx1, gw + w, gh + w), "pocket", f"{team}_pocket_back")


def _rod(robot: ET.Element, rod: table.Rod) -> None:
    yaw = 0.0 if rod.team == table.HOME else math.pi
    carriage = f"{rod.name}_carriage"
    body = f"{rod.name}_rod"

    link = ET.SubElement(robot, "link", name=carriage)
    _inertial(link, table.CARRIAGE_MASS, 1e-4, 1e-4, 1e-4)

    joint = ET.SubElement(robot, "joint", name=rod.slide_joint, type="prismatic")
    ET.SubElement(joint, "parent", link="table")
    ET.SubElement(joint, "child", link=carriage)
    ET.SubElement(joint, "origin", xyz=_fmt(rod.x, 0.0, table.ROD_HEIGHT), rpy=_fmt(0.0, 0.0, yaw))
    ET.SubElement(joint, "axis", xyz="0 1 0")
    ET.SubElement(
        joint,
        "limit",
        lower=_fmt(-rod.slide_limit),
        upper=_fmt(rod.slide_limit),
        effort=_fmt(table.SLIDE_MAX_FORCE),
        velocity=_fmt(table.SLIDE_MAX_SPEED),
    )

    link = ET.SubElement(robot, "link", name=body)
    m, r, length = table.ROD_MASS, table.ROD_RADIUS, table.ROD_LENGTH
    across = m * (3 * r * r + length * length) / 12
    _inertial(link, m, across, m * r * r / 2, across)
    visual = ET.SubElement(link, "visual", name=f"{rod.name}_bar")
    # A cylinder's axis is z; turn it onto y.
    ET.SubElement(visual, "origin", xyz="0 0 0", rpy=_fmt(math.pi / 2, 0.0, 0.0))
    ET.SubElement(
        ET.SubElement(visual, "geometry"), "cylinder", radius=_fmt(r), length=_fmt(length)
    )
    ET.SubElement(visual, "material", name="rod")

    joint = ET.SubElement(robot, "joint", name=rod.spin_joint, type="revolute")
    ET.SubElement(joint, "parent", link=carriage)
    ET.SubElement(joint, "child", link=body)
    ET.SubElement(joint, "origin", xyz="0 0 0", rpy="0 0 0")
    # About -y, so positive spin moves the foot (below the axis) towards +x of the rod frame.
    ET.SubElement(joint, "axis", xyz="0 -1 0")
    ET.SubElement(
        joint,
        "limit",
        lower=_fmt(-table.SPIN_LIMIT),
        upper=_fmt(table.SPIN_LIMIT),
        effort=_fmt(table.SPIN_MAX_TORQUE),
        velocity=_fmt(table.SPIN_MAX_SPEED),
    )

    fx, fy, fz = table.FIGURINE_SIZE
    fm = table.FIGURINE_MASS
    # Heights above the surface -> the figurine link's frame (its origin is the box centre).
    centre = table.ROD_HEIGHT - table.FIGURINE_CENTRE_BELOW_AXIS
    body_lo = (-fx / 2, -fy / 2, table.FIGURINE_LEG_TOP - centre)
    for i, offset in enumerate(rod.figurine_offsets):
        name = f"{rod.name}_figurine_{i}"
        link = ET.SubElement(robot, "link", name=name)
        _inertial(
            link,
            fm,
            fm * (fy * fy + fz * fz) / 12,
            fm * (fx * fx + fz * fz) / 12,
            fm * (fx * fx + fy * fy) / 12,
        )
        _box(link, body_lo, (fx / 2, fy / 2, fz / 2), rod.team, f"{name}_body")
        _mesh(link, LEG_FILE, (0.0, 0.0, -centre), rod.team, f"{name}_leg")
        joint = ET.SubElement(robot, "joint", name=f"{name}_mount", type="fixed")
        ET.SubElement(joint, "parent", link=body)
        ET.SubElement(joint, "child", link=name)
        ET.SubElement(
            joint, "origin", xyz=_fmt(0.0, offset, -table.FIGURINE_CENTRE_BELOW_AXIS), rpy="0 0 0"
        )


def _mesh(
    parent: ET.Element, filename: str, xyz: tuple[float, float, float], material: str, name: str
) -> None:
    """A visual and a collision mesh (Bullet collides with its convex hull)."""
    for tag in ("visual", "collision"):
        el = ET.SubElement(parent, tag, name=name)
        ET.SubElement(el, "origin", xyz=_fmt(*xyz), rpy="0 0 0")
        ET.SubElement(ET.SubElement(el, "geometry"), "mesh", filename=filename)
        if tag == "visual":
            ET.SubElement(el, "material", name=material)


def leg_section(x0: float, x1: float) -> list[tuple[float, float]]:
    """A leg cross-section at one height: full thickness ``x0..x1`` out to the flat half
    width, then rounded ends narrowing to a point at the full half width (counter-clockwise)."""
    flat, half = table.FIGURINE_LEG_FLAT_HALF_WIDTH, table.FIGURINE_LEG_HALF_WIDTH
    mid, hx = (x0 + x1) / 2, (x1 - x0) / 2
    points = []
    for sign in (1.0, -1.0):
        # One end: from the corner (x1, sign*flat) over the tip to (x0, sign*flat).
        points.append((mid + sign * hx, sign * flat))
        for k in range(1, _END_POINTS + 1):
            t = math.pi * k / (_END_POINTS + 1)
            points.append(
                (mid + sign * hx * math.cos(t), sign * (flat + (half - flat) * math.sin(t)))
            )
        points.append((mid - sign * hx, sign * flat))
    return points


def leg_obj() -> str:
    """The leg as a closed mesh: its cross-sections at the heights of ``table.py``, joined."""
    rings = [[(x, y, h) for x, y in leg_section(x0, x1)] for h, x0, x1 in table.FIGURINE_LEG_HULL]
    n = len(rings[0])
    lines = ["# Generated by urdf/generate.py from foosball_gym/table.py; do not edit."]
    lines += [f"v {_fmt(*v)}" for ring in rings for v in ring]
    faces = []
    for r in range(len(rings) - 1):
        for k in range(n):
            a, b = r * n + k + 1, r * n + (k + 1) % n + 1
            faces += [(a, b, b + n), (a, b + n, a + n)]
    top = (len(rings) - 1) * n
    for k in range(1, n - 1):
        faces.append((1, k + 2, k + 1))  # the sole, facing down
        faces.append((top + 1, top + k + 1, top + k + 2))
    lines += [f"f {a} {b} {c}" for a, b, c in faces]
    return "\n".join(lines) + "\n"


def table_urdf() -> str:
    robot = ET.Element("robot", name="foosball_table")
    _materials(robot)
    _table_link(robot)
    for rod in table.RODS:
        _rod(robot, rod)
    return _serialise(robot)


def ball_urdf() -> str:
    robot = ET.Element("robot", name="ball")
    mat = ET.SubElement(robot, "material", name="ball")
    ET.SubElement(mat, "color", rgba=_fmt(*COLOURS["ball"]))
    link = ET.SubElement(robot, "link", name="ball")
    m, r = table.BALL_MASS, table.BALL_RADIUS
    i = 2 * m * r * r / 5
    _inertial(link, m, i, i, i)
    for tag in ("visual", "collision"):
        el = ET.SubElement(link, tag, name="ball")
        ET.SubElement(el, "origin", xyz="0 0 0", rpy="0 0 0")
        ET.SubElement(ET.SubElement(el, "geometry"), "sphere", radius=_fmt(r))
        if tag == "visual":
            ET.SubElement(el, "material", name="ball")
    return _serialise(robot)


def _serialise(robot: ET.Element) -> str:
    ET.indent(robot)
    header = (
        '<?xml version="1.0"?>\n'
        "<!-- Generated by urdf/generate.py from foosball_gym/table.py; do not edit. -->\n"
    )
    return header + ET.tostring(robot, encoding="unicode") + "\n"


def main() -> None:
    for name, text in ((TABLE_FILE, table_urdf()), (BALL_FILE, ball_urdf()), (LEG_FILE, leg_obj())):
        (HERE / name).write_text(text)
        print(f"wrote {HERE / name}")


if __name__ == "__main__":
    main()
