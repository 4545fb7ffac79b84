"""The whole table as it is drawn: a Bullet world with every rod in play, posed from the
simulator's state (never stepped), for pictures from the CPU renderer and the GUI window."""

from __future__ import annotations

import collections
import math
import os
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.camera import CameraModel, check_image_side
from foosball_gym.sim.urdf import table_boxes, urdf_for_window
from foosball_gym.sim.worlds import UPRIGHT, World, pybullet

# The names :meth:`View.keyboard_events` gives PyBullet's codes of keys without a character.
_KEY_NAMES = {
    pybullet.B3G_LEFT_ARROW: "left",
    pybullet.B3G_RIGHT_ARROW: "right",
    pybullet.B3G_UP_ARROW: "up",
    pybullet.B3G_DOWN_ARROW: "down",
    pybullet.B3G_SPACE: "space",
    pybullet.B3G_RETURN: "return",
}
#: Where the GUI window looks from: ``"top"`` straight down with the home goal on the left (as
#: the rgb_array frames), ``"away"`` from behind the away goal, where a person playing the away
#: side stands (``foosball play --human --view away``), ``"home"`` from behind the home goal.
VIEWS = ("top", "away", "home")
#: The GUI window's size (pixels) and background (RGB): the table fills its width, and the
#: bands above and below it are left clear for the score and the key help.
WINDOW_SIZE = (960, 680)
WINDOW_BACKGROUND = (0.85, 0.85, 0.84)
# How much of the window's width the table takes; its text goes in the bands left above and
# below it, the first line in the middle of the band above, the others a line apart from the
# top of the band below (a line: this share of the window's height).
_TABLE_WIDTH_SHARE = 0.94
_TABLE_HEIGHT_SHARE = 0.78
_TEXT_LINE = 0.045
# The tilt of the views from behind a goal (degrees below the horizon).
_PLAYER_PITCH = -62.0
_YAW = {"top": 0.0, "away": 90.0, "home": -90.0}
# PyBullet's text size at a camera this far (m) from the text; farther, it grows in proportion,
# so that a line looks as large from every view.
_TEXT_SIZE, _TEXT_SIZE_AT = 2.0, 1.1
# The table's outer walls and goal pockets (m).
_OUTER_X = table.POCKET_BACK_X + table.WALL_THICKNESS
_OUTER_Y = table.FIELD_HALF_WIDTH + table.WALL_THICKNESS


class _Camera:
    """The GUI camera's matrices for a view's yaw and pitch, at any target and distance.

    Computed, not read back: the window takes a new placement only at its next frame, and
    each call to a GUI world waits for one. PyBullet gives the view matrix once; moving the
    target or the distance only moves the eye along the same line of sight.
    """

    def __init__(self, client: Any, yaw: float, pitch: float) -> None:
        width, height = client.getDebugVisualizerCamera()[:2]
        if not width or not height:
            # No window to ask: a second GUI in one process, which PyBullet does not open.
            width, height = WINDOW_SIZE
        # The window's camera: 90 degrees of vertical field of view. PyBullet's matrices
        # are column-major.
        projection = client.computeProjectionMatrixFOV(90.0, width / height, 0.01, 1000.0)
        self.projection = np.array(projection).reshape(4, 4).T
        view = (
            np.array(
                client.computeViewMatrixFromYawPitchRoll([0.0, 0.0, 0.0], 1.0, yaw, pitch, 0.0, 2)
            )
            .reshape(4, 4)
            .T
        )
        self.rotation = view[:3, :3]
        self.eye = -self.rotation.T @ view[:3, 3]  # the eye a metre from its target

    def matrix(self, target: Any, distance: float) -> np.ndarray:
        """Projection times view matrix with the camera ``distance`` from ``target``."""
        view = np.eye(4)
        view[:3, :3] = self.rotation
        view[:3, 3] = -self.rotation @ (np.asarray(target) + distance * self.eye)
        return self.projection @ view


def _project(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Where world ``points`` (N, 3) fall in the window: x, y from -1 to 1, y up."""
    clip = np.c_[points, np.ones(len(points))] @ matrix.T
    # A point behind the camera is nowhere on the screen.
    w = np.where(clip[:, 3:4] > 1e-9, clip[:, 3:4], np.nan)
    return np.nan_to_num(clip[:, :2] / w, nan=np.inf)


def _unproject(matrix: np.ndarray, target: Any, u: float, v: float) -> np.ndarray:
    """The world point the window shows at (u, v) (from -1 to 1, y up), on the plane through
    the camera's ``target`` that faces the camera: as far away as the table's middle."""
    inverse = np.linalg.inv(matrix)

    def point(u: float, v: float, depth: float) -> np.ndarray:
        world = inverse @ np.array([u, v, depth, 1.0])
        return world[:3] / world[3]

    near, far = point(u, v, -1.0), point(u, v, 1.0)
    forward = point(0.0, 0.0, 1.0) - point(0.0, 0.0, -1.0)
    ray = far - near
    along = np.dot(np.asarray(target) - near, forward) / np.dot(ray, forward)
    return near + along * ray


def check_image_size(width: int, height: int) -> None:
    """Raise a ValueError unless both sides are whole numbers in [1, MAX_IMAGE_SIDE]."""
    check_image_side("image width", width)
    check_image_side("image height", height)


class View:
    """The table ``rods`` in a world of its own, in the GUI window with ``gui``, seen from
    ``view`` (one of :data:`VIEWS`)."""

    def __init__(self, rods: Sequence[table.Rod], gui: bool, view: str = "top") -> None:
        if gui and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
            raise RuntimeError(
                "the PyBullet GUI (render_mode='human') needs a display and "
                "DISPLAY is not set; on a headless machine use "
                "render_mode='rgb_array', or run under xvfb-run"
            )
        if view not in VIEWS:
            raise ValueError(f"no view {view!r}; allowed: {', '.join(VIEWS)}")
        self.rods = tuple(rods)
        self.gui = gui
        names = [rod.name for rod in rods]
        if gui:
            width, height = WINDOW_SIZE
            red, green, blue = WINDOW_BACKGROUND
            options = (
                f"--width={width} --height={height} --background_color_red={red} "
                f"--background_color_green={green} --background_color_blue={blue}"
            )
            self.world = World(
                names, gui=True, urdf=urdf_for_window(tuple(names)), window_options=options
            )
            self._add_table_parts()
        else:
            self.world = World(names)
        self.view = view
        self._text_items: list[tuple[str, int]] = []
        self._camera_placement: tuple[np.ndarray, np.ndarray, float] = (
            np.eye(4),
            np.zeros(3),
            _TEXT_SIZE_AT,
        )
        self._table_rows = (0.15, 0.85)
        if gui:
            self.set_view(view)
        self._keyboard_taken = False
        self._camera: CameraModel | None = None
        self._view_matrix = self._proj = None
        self._shapes: list[tuple[int, int, int, list[float]]] | None = None
        self._fixed_shown = True
        self._fixed_layers: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def pose(self, pos: Sequence[float], vel: Sequence[float], ball: Sequence[float]) -> None:
        """Pose the rods (joint values and speeds, all slides then all spins) and the ball
        (x, y, z)."""
        n = len(self.rods)
        order = [j for i in range(n) for j in (i, n + i)]
        world = self.world
        world.place(
            [rod.name for rod in self.rods], [pos[j] for j in order], [vel[j] for j in order]
        )
        world.reset_pose(world.ball, tuple(ball), UPRIGHT)

    def _add_table_parts(self) -> None:
        """The table's parts and the rods' bars as bodies of their own, each in its colour
        (see :func:`~foosball_gym.sim.urdf.urdf_for_window`); the window only shows them."""
        p = self.world.client
        for centre, size, material in table_boxes():
            shape = p.createVisualShape(
                pybullet.GEOM_BOX,
                halfExtents=[v / 2 for v in size],
                rgbaColor=list(table.COLOURS[material]),
            )
            p.createMultiBody(baseMass=0.0, baseVisualShapeIndex=shape, basePosition=centre)
        # A bar looks the same wherever it slides and turns: one standing from wall to wall,
        # so that nothing sticks out of the table.
        bar = p.createVisualShape(
            pybullet.GEOM_CYLINDER,
            radius=table.ROD_RADIUS,
            length=2 * (table.FIELD_HALF_WIDTH + table.WALL_THICKNESS),
            rgbaColor=list(table.COLOURS["rod"]),
            visualFrameOrientation=p.getQuaternionFromEuler([math.pi / 2, 0.0, 0.0]),
        )
        for rod in self.rods:
            p.createMultiBody(
                baseMass=0.0, baseVisualShapeIndex=bar, basePosition=[rod.x, 0.0, table.ROD_HEIGHT]
            )

    def set_view(self, view: str) -> None:
        """Look at the table from ``view`` (one of :data:`VIEWS`), framing the whole table
        and nothing else across the window's width; without the GUI, nothing."""
        if view not in VIEWS:
            raise ValueError(f"no view {view!r}; allowed: {', '.join(VIEWS)}")
        self.view = view
        if not self.gui:
            return
        p = self.world.client
        yaw = _YAW[view]
        pitch = -89.9 if view == "top" else _PLAYER_PITCH
        corners = np.array(
            [
                (sx * _OUTER_X, sy * _OUTER_Y, z)
                for sx in (-1, 1)
                for sy in (-1, 1)
                for z in (-table.SURFACE_THICKNESS, table.WALL_HEIGHT)
            ]
        )

        camera = _Camera(p, yaw, pitch)

        def framed(distance: float, target: Any) -> np.ndarray:
            return _project(camera.matrix(target, distance), corners)

        def centred(distance: float) -> np.ndarray:
            """The target that puts the table in the middle of the window's height."""
            target = np.zeros(3)
            for _ in range(4):
                ndc = framed(distance, target)
                middle = (ndc[:, 1].max() + ndc[:, 1].min()) / 2
                target = _unproject(camera.matrix(target, distance), target, 0.0, middle)
            return target

        def fits(distance: float) -> bool:
            ndc = framed(distance, centred(distance))
            tall = ndc[:, 1].max() - ndc[:, 1].min()
            return bool(
                np.abs(ndc[:, 0]).max() <= _TABLE_WIDTH_SHARE and tall <= 2 * _TABLE_HEIGHT_SHARE
            )

        # As near as the whole table fits: its widest part takes its share of the window's
        # width (or, from behind a goal, its length its share of the height).
        low, high = 0.2, 10.0
        for _ in range(30):
            distance = (low + high) / 2
            low, high = (low, distance) if fits(distance) else (distance, high)
        distance = high
        target = centred(distance)
        p.resetDebugVisualizerCamera(distance, yaw, pitch, list(target))
        self._camera_placement = (camera.matrix(target, distance), target, distance)
        ndc = framed(distance, target)
        # The table's top and bottom edges, as fractions of the window's height from its top.
        self._table_rows = ((1 - ndc[:, 1].max()) / 2, (1 - ndc[:, 1].min()) / 2)
        lines = [line for line, _ in self._text_items]
        self.show_text([])
        self.show_text(lines)

    def _text_place(self, height: float) -> tuple[list[float], float]:
        """Where a line of text starts that the window shows at ``height`` (a fraction of its
        height from the top) and the table's left edge, and the size that keeps it as large
        whatever the view."""
        matrix, target, distance = self._camera_placement
        start = _unproject(matrix, target, -_TABLE_WIDTH_SHARE, 1.0 - 2.0 * height)
        return [float(v) for v in start], _TEXT_SIZE * distance / _TEXT_SIZE_AT

    def show_text(self, lines: Sequence[str]) -> None:
        """Write ``lines`` in the GUI window, the first above the table and the others below
        it, replacing what the last call wrote; without the GUI, nothing."""
        if not self.gui:
            return
        p = self.world.client
        lines = list(lines)
        for i, line in enumerate(lines):
            shown = self._text_items[i] if i < len(self._text_items) else None
            if shown is not None and shown[0] == line:
                continue
            top, bottom = self._table_rows
            height = top / 2 if i == 0 else bottom + (i + 0.4) * _TEXT_LINE
            position, size = self._text_place(height)
            item = p.addUserDebugText(
                line,
                position,
                textColorRGB=[0.05, 0.05, 0.05],
                textSize=size,
                replaceItemUniqueId=shown[1] if shown is not None else -1,
            )
            if shown is None:
                self._text_items.append((line, item))
            else:
                self._text_items[i] = (line, item)
        for _, item in self._text_items[len(lines) :]:
            p.removeUserDebugItem(item)
        del self._text_items[len(lines) :]

    def keyboard_events(self) -> tuple[frozenset[str], frozenset[str]]:
        """The keys held down in the GUI window now, and those pressed since the last call.

        Keys are named ``"left"``, ``"right"``, ``"up"``, ``"down"``, ``"space"``,
        ``"return"`` or by their lower-case character. The first call turns off the GUI's
        own single-key shortcuts (wireframe, ...), which would fight a player's keys.
        """
        p = self.world.client
        if not self._keyboard_taken:
            p.configureDebugVisualizer(pybullet.COV_ENABLE_KEYBOARD_SHORTCUTS, 0)
            self._keyboard_taken = True
        held, pressed = set(), set()
        for code, state in p.getKeyboardEvents().items():
            name = _KEY_NAMES.get(code) or (chr(code).lower() if 32 < code < 127 else None)
            if name is None:
                continue
            if state & pybullet.KEY_IS_DOWN:
                held.add(name)
            if state & pybullet.KEY_WAS_TRIGGERED:
                pressed.add(name)
        return frozenset(held), frozenset(pressed)

    def camera(self, width: int, height: int) -> CameraModel:
        if self._camera is None or (self._camera.width, self._camera.height) != (width, height):
            p = self.world.client
            cam = CameraModel(width, height)
            self._camera = cam
            self._view_matrix = p.computeViewMatrix(
                [0, 0, cam.height_above_table], [0, 0, 0], [0, 1, 0]
            )
            self._proj = p.computeProjectionMatrixFOV(
                cam.vertical_fov_deg, width / height, 0.1, cam.height_above_table + 0.5
            )
        return self._camera

    def render(self, width: int = 320, height: int = 180, layered: bool = True) -> np.ndarray:
        """An (height, width, 3) uint8 top view from the CPU renderer.

        ``layered`` draws the table's fixed parts once per size and then only the rods and
        the ball, laid over them by depth: the same picture (a test compares them pixel for
        pixel) in a quarter of the time for one rod, since the field and walls fill most of
        the frame. Without a GUI only: there the fixed parts must stay on the screen.
        """
        check_image_size(width, height)
        self.camera(width, height)
        if not layered or self.gui:
            self._show_fixed_parts(True)
            return self._draw(width, height)[0]
        fixed_rgb, fixed_depth = self._fixed_layer(width, height)
        self._show_fixed_parts(False)
        rgb, depth = self._draw(width, height)
        return np.where((depth < fixed_depth)[:, :, None], rgb, fixed_rgb)

    def _draw(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        _, _, rgba, depth, _ = self.world.client.getCameraImage(
            width,
            height,
            self._view_matrix,
            self._proj,
            renderer=pybullet.ER_TINY_RENDERER,
            shadow=0,
            flags=pybullet.ER_NO_SEGMENTATION_MASK,
        )
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()
        return rgb, np.asarray(depth, dtype=np.float32).reshape(height, width)

    def _visual_shapes(self) -> list[tuple[int, int, int, list[float]]]:
        """(body, link, shape index, colour) of every visual shape, fixed parts first."""
        view = self.world
        if self._shapes is None:
            shapes = []
            seen: collections.Counter[tuple[int, int]] = collections.Counter()
            for body in (view.body, view.ball):
                for shape in view.client.getVisualShapeData(body):
                    link = shape[1]
                    shapes.append((body, link, seen[body, link], list(shape[7])))
                    seen[body, link] += 1
            self._shapes = shapes
        return self._shapes

    def _set_visible(self, fixed: bool, visible: bool) -> None:
        view = self.world
        for body, link, index, colour in self._visual_shapes():
            if (body == view.body and link == -1) == fixed:
                alpha = colour[3] if visible else 0.0
                view.client.changeVisualShape(
                    body, link, shapeIndex=index, rgbaColor=[*colour[:3], alpha]
                )

    def _show_fixed_parts(self, visible: bool) -> None:
        if self._fixed_shown != visible:
            self._set_visible(fixed=True, visible=visible)
            self._fixed_shown = visible

    def _fixed_layer(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """The field and walls alone, with their depth, drawn once per size."""
        layer = self._fixed_layers.get((width, height))
        if layer is None:
            self._show_fixed_parts(True)
            self._set_visible(fixed=False, visible=False)
            try:
                layer = self._draw(width, height)
            finally:
                self._set_visible(fixed=False, visible=True)
            self._fixed_layers[width, height] = layer
        return layer

    def close(self) -> None:
        self.world.close()
