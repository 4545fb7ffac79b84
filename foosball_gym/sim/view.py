"""The whole table as it is drawn: a Bullet world with every rod in play, posed from the
simulator's state (never stepped), for pictures from the CPU renderer and the GUI window."""

from __future__ import annotations

import collections
import os
import sys
from collections.abc import Sequence

import numpy as np

from foosball_gym import table
from foosball_gym.camera import CameraModel, check_image_side
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
# Where :meth:`View.show_text` writes: beyond the side walls, a line apart (m).
_TEXT_MARGIN = 0.09
_TEXT_LINE = 0.04


def check_image_size(width: int, height: int) -> None:
    """Raise a ValueError unless both sides are whole numbers in [1, MAX_IMAGE_SIDE]."""
    check_image_side("image width", width)
    check_image_side("image height", height)


class View:
    """The table ``rods`` in a world of its own, in the GUI window with ``gui``."""

    def __init__(self, rods: Sequence[table.Rod], gui: bool) -> None:
        if gui and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
            raise RuntimeError(
                "the PyBullet GUI (render_mode='human') needs a display and "
                "DISPLAY is not set; on a headless machine use "
                "render_mode='rgb_array', or run under xvfb-run"
            )
        self.rods = tuple(rods)
        self.gui = gui
        self.world = World([rod.name for rod in rods], gui=gui)
        self._text_items: list[tuple[str, int]] = []
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

    def show_text(self, lines: Sequence[str]) -> None:
        """Write ``lines`` in the GUI window, the first above the table and the others below
        it, replacing what the last call wrote; without the GUI, nothing."""
        p = self.world.client
        lines = list(lines)
        for i, line in enumerate(lines):
            shown = self._text_items[i] if i < len(self._text_items) else None
            if shown is not None and shown[0] == line:
                continue
            beyond = table.FIELD_HALF_WIDTH + _TEXT_MARGIN
            y = beyond if i == 0 else -(beyond + (i - 1) * _TEXT_LINE)
            item = p.addUserDebugText(
                line,
                [-table.FIELD_HALF_LENGTH, y, 0.1],
                textColorRGB=[0, 0, 0],
                textSize=1.5,
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
