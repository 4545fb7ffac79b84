"""The opponent's rods, seen by the camera: each rod's prismatic position from its figurines."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from foosball_gym import table as T
from foosball_gym.vision.projection import CameraCalibration

# The figurines' heads are what the camera above sees of them.
HEAD_HEIGHT = T.ROD_HEIGHT + T.FIGURINE_HEAD_ABOVE_AXIS
AWAY_HSV = ((0, 0, 0), (179, 80, 60))  # near-black and grey: not the shaded brown walls


class RodTracker:
    """Finds one team's figurines along each of its rods and fits the rods' slide values.

    The figurines are blobs of the team's colour in a band of the image along each rod; their
    centres, back-projected onto the plane of the heads, give world y values, and the slide
    value is the one that puts the rod's figurines closest to them. A rod is found as long as
    one of its figurines is seen.

    Args:
        calibration: the camera.
        rods: the rods to track (one team's).
        hsv_low, hsv_high: the figurines' colour.
        min_area_px: smaller blobs are noise.
    """

    def __init__(
        self,
        calibration: CameraCalibration,
        rods: Sequence[T.Rod],
        hsv_low: tuple[int, int, int] = AWAY_HSV[0],
        hsv_high: tuple[int, int, int] = AWAY_HSV[1],
        min_area_px: int = 6,
    ) -> None:
        self.calibration = calibration
        self.rods = list(rods)
        self.low = np.array(hsv_low, np.uint8)
        self.high = np.array(hsv_high, np.uint8)
        self.min_area = min_area_px
        # Each rod's band: its figurines' heads anywhere along the rod, inside the side walls
        # (beyond them the walls' tops and the goal pockets are dark too).
        self._bands = []
        for rod in self.rods:
            half = T.FIGURINE_SIZE[0]
            reach = max(abs(o) for o in rod.figurine_offsets) + rod.slide_limit + half
            corners = np.array(
                [[rod.x + dx, dy, HEAD_HEIGHT] for dx in (-half, half) for dy in (-reach, reach)]
            )
            uv = calibration.project(corners)
            self._bands.append(
                (
                    int(np.floor(uv[:, 0].min())),
                    int(np.ceil(uv[:, 0].max())) + 1,
                    int(np.floor(uv[:, 1].min())),
                    int(np.ceil(uv[:, 1].max())) + 1,
                )
            )
        # A head is about this many pixels; much bigger blobs are something else.
        head = np.array(
            [
                [0, -T.FIGURINE_SIZE[1] / 2, HEAD_HEIGHT],
                [T.FIGURINE_SIZE[0], T.FIGURINE_SIZE[1] / 2, HEAD_HEIGHT],
            ]
        )
        extent = np.abs(np.diff(calibration.project(head), axis=0)).ravel()
        self.max_area = 4 * float(extent[0] * extent[1])
        # The goal pockets are as dark as the away figurines, and the keeper's head is seen
        # right next to one: they are blanked out of the mask.
        self._pockets = [
            calibration.project(
                np.array(
                    [
                        [s * T.FIELD_HALF_LENGTH, -T.GOAL_HALF_WIDTH, 0.0],
                        [s * T.POCKET_BACK_X, -T.GOAL_HALF_WIDTH, 0.0],
                        [s * T.POCKET_BACK_X, T.GOAL_HALF_WIDTH, 0.0],
                        [s * T.FIELD_HALF_LENGTH, T.GOAL_HALF_WIDTH, 0.0],
                    ]
                )
            )
            .round()
            .astype(np.int32)
            for s in (-1.0, 1.0)
        ]

    def __call__(self, frame: np.ndarray) -> dict[str, float | None]:
        mask = cv2.inRange(cv2.cvtColor(frame, cv2.COLOR_BGR2HSV), self.low, self.high)
        cv2.fillPoly(mask, self._pockets, 0)
        out: dict[str, float | None] = {}
        for rod, (u0, u1, v0, v1) in zip(self.rods, self._bands):
            u0, v0 = max(u0, 0), max(v0, 0)
            band = mask[v0:v1, u0:u1]
            n, _, stats, centroids = cv2.connectedComponentsWithStats(band, connectivity=8)
            pixels = [
                (u0 + c[0], v0 + c[1])
                for i, c in enumerate(centroids)
                if i and self.min_area <= stats[i, cv2.CC_STAT_AREA] <= self.max_area
            ]
            if not pixels:
                out[rod.name] = None
                continue
            ys = self.calibration.pixel_to_table(np.array(pixels), z=HEAD_HEIGHT)[:, 1]
            out[rod.name] = fit_slide(rod, ys)
        return out


def fit_slide(rod: T.Rod, seen_y: Sequence[float]) -> float | None:
    """The slide value that best explains figurines seen at world ``seen_y``.

    Each seen figurine may be any of the rod's; for every candidate (a seen figurine taken as
    one of the rod's), the others are matched to their nearest figurine and the candidate with
    the smallest total miss wins.
    """
    d = rod.direction
    best, best_cost = None, np.inf
    for y in seen_y:
        for off in rod.figurine_offsets:
            slide = d * y - off
            if abs(slide) > rod.slide_limit + 0.01:
                continue
            fig = np.array(rod.figurine_y(slide))
            cost = sum(np.min(np.abs(fig - other)) for other in seen_y)
            if cost < best_cost:
                best, best_cost = float(np.clip(slide, -rod.slide_limit, rod.slide_limit)), cost
    if best is None:
        return None
    # Refine: the mean slide implied by each seen figurine's nearest match.
    fig = np.array(rod.figurine_y(best))
    implied = [d * y - rod.figurine_offsets[int(np.argmin(np.abs(fig - y)))] for y in seen_y]
    return float(np.clip(np.mean(implied), -rod.slide_limit, rod.slide_limit))
