"""Calibrating the camera: intrinsics from a chessboard, pose from the field's corners."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from foosball_gym import table
from foosball_gym.vision.projection import CameraCalibration

#: The playing field's corners (x, y, z): the markers the camera's pose is solved from, in the
#: order :func:`find_field_corners` returns them (home goal on the image's left).
FIELD_MARKERS = np.array(
    [
        [-table.FIELD_HALF_LENGTH, table.FIELD_HALF_WIDTH, 0.0],
        [table.FIELD_HALF_LENGTH, table.FIELD_HALF_WIDTH, 0.0],
        [table.FIELD_HALF_LENGTH, -table.FIELD_HALF_WIDTH, 0.0],
        [-table.FIELD_HALF_LENGTH, -table.FIELD_HALF_WIDTH, 0.0],
    ]
)
FIELD_HSV = ((40, 80, 40), (85, 255, 255))  # the green playing surface


def calibrate_intrinsics(
    images: Sequence[np.ndarray], pattern: tuple[int, int] = (9, 6), square: float = 0.025
) -> tuple[np.ndarray, np.ndarray, float]:
    """Camera matrix and distortion from views of a chessboard.

    Args:
        images: BGR or grey views of the board (at least three, from different angles).
        pattern: inner corners per row and column.
        square: the squares' side (m).

    Returns:
        (K, dist, rms reprojection error in pixels).
    """
    board = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    board[:, :2] = np.mgrid[: pattern[0], : pattern[1]].T.reshape(-1, 2) * square
    object_points, image_points, size = [], [], None
    for image in images:
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        size = grey.shape[::-1]
        found, corners = cv2.findChessboardCorners(grey, pattern)
        if not found:
            continue
        corners = cv2.cornerSubPix(
            grey,
            corners,
            (5, 5),
            (-1, -1),
            (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3),
        )
        object_points.append(board)
        image_points.append(corners)
    if len(object_points) < 3:
        raise ValueError(
            f"the chessboard ({pattern[0]}x{pattern[1]} inner corners) was found "
            f"in {len(object_points)} of {len(images)} images; at least 3 needed"
        )
    assert size is not None  # every image sets it, and three or more were read
    rms, K, dist, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None)
    return K, dist.reshape(-1), float(rms)


def find_field_corners(frame: np.ndarray, home_side: str = "left") -> np.ndarray:
    """The four corners of the green playing field in a BGR frame, in FIELD_MARKERS order.

    Args:
        frame: a view of the whole field.
        home_side: where the home goal is in the image, ``"left"`` or ``"right"``.

    Returns:
        (4, 2) pixel coordinates.
    """
    if home_side not in ("left", "right"):
        raise ValueError(f"home_side must be 'left' or 'right', got {home_side!r}")
    mask = cv2.inRange(cv2.cvtColor(frame, cv2.COLOR_BGR2HSV), *FIELD_HSV)
    # Close the gaps the rods and figurines cut into the green before taking its outline.
    size = max(5, frame.shape[1] // 40) | 1
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((size, size), np.uint8))
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise ValueError("no green playing field in the frame")
    hull = cv2.convexHull(max(contours, key=cv2.contourArea))
    if cv2.contourArea(hull) < 0.05 * mask.size:
        raise ValueError("the green area is too small to be the playing field")
    quad = None
    for eps in np.linspace(0.005, 0.05, 20):
        approx = cv2.approxPolyDP(hull, eps * cv2.arcLength(hull, True), True)
        if len(approx) == 4:
            quad = approx.reshape(4, 2).astype(float)
            break
    if quad is None:
        raise ValueError("the playing field's outline is not a quadrilateral")
    quad = _refine_corners(mask, quad)
    # Left two, right two; within each, top first. Home on the left: that is FIELD_MARKERS.
    left, right = sorted(quad, key=lambda p: p[0])[:2], sorted(quad, key=lambda p: p[0])[2:]
    top_left, bottom_left = sorted(left, key=lambda p: p[1])
    top_right, bottom_right = sorted(right, key=lambda p: p[1])
    corners = np.array([top_left, top_right, bottom_right, bottom_left])
    return corners if home_side == "left" else corners[[2, 3, 0, 1]]


def _refine_corners(mask: np.ndarray, quad: np.ndarray) -> np.ndarray:
    """Corners as the intersections of lines fitted to the outline's four sides."""
    contour = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0]
    points = max(contour, key=cv2.contourArea).reshape(-1, 2).astype(float)
    lines = []
    for i in range(4):
        a, b = quad[i], quad[(i + 1) % 4]
        direction = (b - a) / np.linalg.norm(b - a)
        normal = np.array([-direction[1], direction[0]])
        along = (points - a) @ direction
        length = np.linalg.norm(b - a)
        near = (np.abs((points - a) @ normal) < 3) & (along > 0.1 * length) & (along < 0.9 * length)
        if near.sum() < 10:
            return quad
        vx, vy, x0, y0 = cv2.fitLine(
            points[near].astype(np.float32), cv2.DIST_L2, 0, 0.01, 0.01
        ).ravel()
        lines.append((np.array([x0, y0]), np.array([vx, vy])))
    refined = []
    for i in range(4):
        (p1, d1), (p2, d2) = lines[i - 1], lines[i]
        t = np.linalg.solve(np.column_stack([d1, -d2]), p2 - p1)
        refined.append(p1 + t[0] * d1)
    return np.array(refined)


def calibrate_extrinsics(
    image_points: np.ndarray,
    K: np.ndarray,
    dist: np.ndarray,
    world_points: np.ndarray = FIELD_MARKERS,
) -> CameraCalibration:
    """The camera's pose from known field points seen in the image (solvePnP).

    SQPnP, not IPPE: for a camera looking almost straight down on the four corners, IPPE's
    pose tilts by a few hundredths of a radian for a tenth of a pixel of noise.
    """
    image_points = np.asarray(image_points, dtype=float).reshape(-1, 2)
    world_points = np.asarray(world_points, dtype=float).reshape(-1, 3)
    if len(image_points) != len(world_points) or len(image_points) < 4:
        raise ValueError("need the same number (at least 4) of image and world points")
    ok, rvec, tvec = cv2.solvePnP(
        world_points,
        image_points,
        np.asarray(K, float),
        np.asarray(dist, float),
        flags=cv2.SOLVEPNP_SQPNP,
    )
    if not ok:
        raise ValueError("solvePnP found no camera pose for these points")
    return CameraCalibration(K, dist, rvec, tvec)


def calibrate_from_frame(
    frame: np.ndarray, K: np.ndarray, dist: np.ndarray, home_side: str = "left"
) -> CameraCalibration:
    """The camera's pose from one frame of the field, with known intrinsics."""
    return calibrate_extrinsics(find_field_corners(frame, home_side), K, dist)
