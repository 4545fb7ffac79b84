"""The opponent's rods, seen by the camera: each rod's prismatic position from its figurines.

A figurine is a box that spins about the rod's axis, which runs along y, so its extent along
the rod, ``[y - w/2, y + w/2]``, is the same at every spin angle: only its heights change.
Seen from above, a hanging figurine shows the top of its head and, by perspective, the side
that faces the point below the camera (the nadir). So the edge of its blob away from the nadir
is the head's top edge (z = ``ROD_HEIGHT + FIGURINE_HEAD_ABOVE_AXIS``) and the edge towards the
nadir is the foot's (z = ``FIGURINE_FOOT_HEIGHT``); an edge on the far side of the nadir is the
head's. Each edge is back-projected onto the plane of its own height and the figurine's centre
is the midpoint of the two. That is exact for a figurine hanging straight down; a spun
figurine's highest and lowest points are at other heights, which moves its centre outwards or
inwards by a few per cent of its distance from the nadir. Measured on the simulated table at
640x360: 0.3 mm on average and under 1 mm for hanging figurines; about 1 mm on average and up
to 6 mm for rods at any spin angle.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

from foosball_gym import table
from foosball_gym.real_table.vision.projection import CameraCalibration

HEAD_TOP_HEIGHT = table.ROD_HEIGHT + table.FIGURINE_HEAD_ABOVE_AXIS
AWAY_HSV = ((0, 0, 0), (179, 80, 60))  # near-black and grey: not the shaded brown walls
# The farthest a figurine's corner gets from its rod's axis as it spins.
_SWING = math.hypot(
    table.FIGURINE_SIZE[0] / 2, table.FIGURINE_SIZE[2] - table.FIGURINE_HEAD_ABOVE_AXIS
)
# A pixel's corners, to take a blob's extent to the pixels' edges rather than their centres.
_PIXEL_CORNERS = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
# Pieces of one blob (a figurine cut in two by its rod) lie this close along the rod.
_MERGE_GAP = 0.005


class RodTracker:
    """Finds one team's figurines and fits each of its rods' slide value.

    Figurines are blobs of the team's colour; each blob goes to the rod nearest to it along x,
    its extent along the rod gives the figurine's world y (see the module's docstring), and
    the slide value is the one that puts the rod's figurines closest to those seen. A rod is
    found as long as one of its figurines is seen; where one figurine alone fits two positions
    of the rod, the one nearer the rod's last position wins.

    Args:
        calibration: the camera.
        rods: the rods to track (one team's).
        hsv_low: the low end of the figurines' colour range in OpenCV's HSV (H in 0-179); the
            default is the simulator's near-black away team.
        hsv_high: the high end of that range.
        min_area_px: smaller blobs are noise.
    """

    def __init__(
        self,
        calibration: CameraCalibration,
        rods: Sequence[table.Rod],
        hsv_low: tuple[int, int, int] = AWAY_HSV[0],
        hsv_high: tuple[int, int, int] = AWAY_HSV[1],
        min_area_px: int = 6,
    ) -> None:
        self.calibration = calibration
        self.rods = list(rods)
        self.low = np.array(hsv_low, np.uint8)
        self.high = np.array(hsv_high, np.uint8)
        self.min_area = min_area_px
        self._rod_x = np.array([rod.x for rod in self.rods])
        self._last: dict[str, float] = {}
        # A figurine's largest side, seen at the height of its head: much bigger blobs are
        # something else (a sleeve, a shadow).
        _, fy, fz = table.FIGURINE_SIZE
        side = calibration.project(
            np.array(
                [
                    [0.0, 0.0, HEAD_TOP_HEIGHT],
                    [fz, 0.0, HEAD_TOP_HEIGHT],
                    [0.0, fy, HEAD_TOP_HEIGHT],
                ]
            )
        )
        length, width = np.linalg.norm(side[1] - side[0]), abs(side[2, 1] - side[0, 1])
        self.max_area = 2.0 * float(length * width)
        # The goal pockets are as dark as the away figurines and a keeper's head is seen right
        # next to one: the image of each pocket, walls and roof included, is blanked out.
        self._pockets = []
        for sign in (-1.0, 1.0):
            xs = (
                sign * table.FIELD_HALF_LENGTH,
                sign * (table.POCKET_BACK_X + table.WALL_THICKNESS),
            )
            ys = (
                -table.GOAL_HALF_WIDTH - table.WALL_THICKNESS,
                table.GOAL_HALF_WIDTH + table.WALL_THICKNESS,
            )
            zs = (0.0, table.GOAL_HEIGHT + table.WALL_THICKNESS)
            box = np.array([[x, y, z] for x in xs for y in ys for z in zs])
            hull = cv2.convexHull(calibration.project(box).astype(np.float32))
            self._pockets.append(hull.round().astype(np.int32))

    def __call__(self, frame: np.ndarray) -> dict[str, float | None]:
        """Each rod's slide value (m, in the rod's own frame), or None for a rod not seen."""
        mask = cv2.inRange(cv2.cvtColor(frame, cv2.COLOR_BGR2HSV), self.low, self.high)
        cv2.fillPoly(mask, self._pockets, 0)
        # Rounding the hull's corners can leave a rim of pocket pixels touching a keeper.
        cv2.polylines(mask, self._pockets, True, 0, thickness=3)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        blobs, centres = [], []
        for contour in contours:
            moments = cv2.moments(contour)
            if self.min_area <= moments["m00"] <= self.max_area:
                # Back-projection onto a plane maps lines to lines, so a blob's extreme
                # points on the table are corners of its convex hull.
                blobs.append(cv2.convexHull(contour).reshape(-1, 2))
                centres.append((moments["m10"] / moments["m00"], moments["m01"] / moments["m00"]))
        extents: dict[str, list[tuple[float, float]]] = {rod.name: [] for rod in self.rods}
        if blobs:
            x = self.calibration.pixel_to_table(np.array(centres), z=table.ROD_HEIGHT)[:, 0]
            nearest = np.argmin(np.abs(x[:, None] - self._rod_x), axis=1)
            # A blob's centre lies within the figurine's swing of its rod, give or take what
            # perspective adds for the parts above and below the axis.
            ours = np.abs(x - self._rod_x[nearest]) < _SWING + 0.02
            kept = [blob for blob, keep in zip(blobs, ours) if keep]
            for k, extent in zip(nearest[ours], self._extents(kept)):
                extents[self.rods[k].name].append(extent)
        out: dict[str, float | None] = {}
        for rod in self.rods:
            slide = fit_slide(rod, _merged_centres(extents[rod.name]), self._last.get(rod.name))
            if slide is not None:
                self._last[rod.name] = slide
            out[rod.name] = slide
        return out

    def _extents(self, outlines: list[np.ndarray]) -> list[tuple[float, float]]:
        """World y of each figurine's two edges along the rod, from its blob's outline (or
        the outline's convex hull)."""
        if not outlines:
            return []
        # Every outline's pixel corners, back-projected at once (one call per height).
        corners = [(o[:, None, :] + _PIXEL_CORNERS).reshape(-1, 2) for o in outlines]
        starts = np.cumsum([0] + [len(c) for c in corners[:-1]])
        points = np.vstack(corners)
        nadir = self.calibration.centre[1]
        out = []
        for height in (HEAD_TOP_HEIGHT, table.FIGURINE_FOOT_HEIGHT):
            y = self.calibration.pixel_to_table(points, z=height)[:, 1]
            out.append((np.minimum.reduceat(y, starts), np.maximum.reduceat(y, starts)))
        (head_low, head_high), (foot_low, foot_high) = out
        # An edge on the nadir's side of the figurine is its foot; beyond the nadir, its head.
        low = np.where(foot_low > nadir, foot_low, head_low)
        high = np.where(foot_high < nadir, foot_high, head_high)
        return list(zip(low.tolist(), high.tolist()))


def _merged_centres(extents: list[tuple[float, float]]) -> list[float]:
    """Figurine centres from blob extents, joining the pieces of one figurine."""
    merged: list[list[float]] = []
    for low, high in sorted(extents):
        if merged and low <= merged[-1][1] + _MERGE_GAP:
            merged[-1][1] = max(merged[-1][1], high)
        else:
            merged.append([low, high])
    return [(low + high) / 2 for low, high in merged]


def fit_slide(rod: table.Rod, seen_y: Sequence[float], prior: float | None = None) -> float | None:
    """The slide value that best explains figurines seen at world ``seen_y``.

    Each seen figurine may be any of the rod's; for every candidate (a seen figurine taken as
    one of the rod's), the others are matched to their nearest figurine and the candidate with
    the smallest total miss wins. Candidates that explain the figurines equally well (one
    figurine seen, which two positions of the rod can put there) are told apart by ``prior``,
    the rod's last known slide value.

    Returns:
        The slide value in the rod's own frame, within its range; None if nothing is seen.
    """
    offsets = np.array(rod.figurine_offsets)
    seen = rod.direction * np.asarray(seen_y, dtype=float)  # in the rod's frame
    slides = (seen[:, None] - offsets).ravel()
    slides = slides[np.abs(slides) <= rod.slide_limit + 0.01]
    if not len(slides):
        return None
    # (candidate, seen figurine): how far that figurine is from the nearest of the rod's.
    miss = np.abs(seen[None, :, None] - (slides[:, None, None] + offsets)).min(axis=2)
    cost = miss.sum(axis=1)
    best = int(np.argmin(cost))
    if prior is not None:
        tied = np.flatnonzero(cost <= cost[best] + _MERGE_GAP * len(seen))
        best = int(tied[np.argmin(np.abs(slides[tied] - prior))])
    # Refine: the mean slide implied by each seen figurine's nearest match.
    nearest = np.argmin(np.abs(seen[:, None] - (slides[best] + offsets)), axis=1)
    implied = seen - offsets[nearest]
    return float(np.clip(implied.mean(), -rod.slide_limit, rod.slide_limit))
