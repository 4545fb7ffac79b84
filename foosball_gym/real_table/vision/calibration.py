"""Calibrating the camera: intrinsics from a chessboard, pose from the field's corners."""

from __future__ import annotations

import struct
from collections.abc import Sequence
from pathlib import Path
from typing import BinaryIO

import cv2
import numpy as np

from foosball_gym import table
from foosball_gym.real_table.vision.projection import CameraCalibration

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
#: The most pixels a picture to calibrate from may have: beyond any table camera's (a
#: 50-megapixel still), and checked in the file's header before decoding, since a file of a
#: megabyte can decode to gigabytes.
MAX_IMAGE_PIXELS = 50_000_000
#: How a calibration must fit the field to be taken for one (:func:`check_field`): the field's
#: corners this far (pixels, and share of the picture's larger side) inside the picture's
#: edge; the field's sides, back on the table's plane, within this share of their true length;
#: the corners reprojected within this share of the field's diagonal in the picture (and at
#: least :data:`MIN_REPROJECTION_PX`).
EDGE_MARGIN_PX = 2.0
EDGE_MARGIN_SHARE = 0.005
MAX_SIDE_ERROR = 0.05
MAX_REPROJECTION_SHARE = 0.01
MIN_REPROJECTION_PX = 2.0


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


def image_size(path: str | Path) -> tuple[int, int]:
    """A PNG, JPEG or BMP file's (width, height), from its header alone.

    Raises:
        ValueError: another format, or a header that does not say.
    """
    with open(path, "rb") as f:
        head = f.read(32)
        if head.startswith(b"\x89PNG\r\n\x1a\n") and head[12:16] == b"IHDR":
            width, height = struct.unpack(">II", head[16:24])
            return width, height
        if head.startswith(b"BM") and len(head) >= 26:
            width, height = struct.unpack("<ii", head[18:26])
            return abs(width), abs(height)
        if head.startswith(b"\xff\xd8"):
            return _jpeg_size(f)
    raise ValueError(f"{path}: not a PNG, JPEG or BMP picture")


def _jpeg_size(f: BinaryIO) -> tuple[int, int]:
    """The frame size in a JPEG's start-of-frame segment, walking the segments before it."""
    f.seek(2)
    while True:
        marker = f.read(2)
        while marker[:1] == b"\xff" and marker[1:2] == b"\xff":  # fill bytes
            marker = marker[1:] + f.read(1)
        if len(marker) < 2 or marker[0] != 0xFF:
            break
        kind = marker[1]
        if kind in (0xD8, 0x01) or 0xD0 <= kind <= 0xD7:
            continue  # markers without a length
        raw = f.read(2)
        if len(raw) < 2:
            break
        (length,) = struct.unpack(">H", raw)
        if 0xC0 <= kind <= 0xCF and kind not in (0xC4, 0xC8, 0xCC):
            frame = f.read(5)
            if len(frame) < 5:
                break
            height, width = struct.unpack(">HH", frame[1:5])
            return width, height
        f.seek(length - 2, 1)
    raise ValueError(f"{getattr(f, 'name', 'the file')}: a JPEG whose header gives no size")


def read_image(path: str | Path, max_pixels: int = MAX_IMAGE_PIXELS) -> np.ndarray:
    """A picture to calibrate from, BGR, its size checked in its header before it is decoded.

    Raises:
        ValueError: not a PNG, JPEG or BMP, more than ``max_pixels`` pixels, or not decodable.
    """
    width, height = image_size(path)
    if width * height > max_pixels:
        raise ValueError(
            f"{path} is {width} x {height} pixels ({width * height / 1e6:.0f} megapixels); a "
            f"picture to calibrate from may have at most {max_pixels / 1e6:.0f} megapixels"
        )
    image = cv2.imread(str(path))
    if image is None:
        raise ValueError(f"cannot read an image from {path}")
    return image


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


def check_field(
    corners: np.ndarray, calibration: CameraCalibration, shape: tuple[int, ...]
) -> None:
    """Refuse a calibration that does not look like one of the table (see the constants above
    :func:`calibrate_intrinsics`): the field must lie whole inside the picture, the camera
    above it, its sides on the table's plane as long as the field's, and the pose must
    reproject the corners where they were found.

    Raises:
        ValueError: saying which of these failed, and by how much.
    """
    height, width = shape[:2]
    corners = np.asarray(corners, dtype=float).reshape(4, 2)
    margin = max(EDGE_MARGIN_PX, EDGE_MARGIN_SHARE * max(width, height))
    inside = (corners >= margin).all() and (corners[:, 0] <= width - 1 - margin).all()
    if not inside or not (corners[:, 1] <= height - 1 - margin).all():
        raise ValueError(
            "the green area reaches the picture's edge: the whole field, with a margin "
            "around it, must be in view (is this a picture of the table?)"
        )
    if not calibration.centre[2] > 0:
        raise ValueError("the camera comes out below the table: that is not the field")
    on_table = calibration.pixel_to_table(corners, z=0.0)
    sides = np.linalg.norm(on_table - np.roll(on_table, -1, axis=0), axis=1)
    true = 2 * np.array([table.FIELD_HALF_LENGTH, table.FIELD_HALF_WIDTH] * 2)
    errors = np.abs(sides / true - 1)
    if not errors.max() <= MAX_SIDE_ERROR:
        raise ValueError(
            f"the green quadrilateral is no field of {true[0]:g} x {true[1]:g} m seen by this "
            f"camera: its sides come out {', '.join(f'{v:.3f}' for v in sides)} m (off by up "
            f"to {100 * errors.max():.0f} %, at most {100 * MAX_SIDE_ERROR:g} %)"
        )
    reprojected = calibration.project(FIELD_MARKERS)
    rms = float(np.sqrt(((reprojected - corners) ** 2).sum(axis=1).mean()))
    diagonal = float(np.linalg.norm(corners[2] - corners[0]))
    bound = max(MIN_REPROJECTION_PX, MAX_REPROJECTION_SHARE * diagonal)
    if not rms <= bound:
        raise ValueError(
            f"the field's corners reproject {rms:.1f} px from where they were found (at most "
            f"{bound:.1f} px): the green area is not the field's shape, or camera.K is wrong"
        )


def calibrate_from_frame(
    frame: np.ndarray, K: np.ndarray, dist: np.ndarray, home_side: str = "left"
) -> CameraCalibration:
    """The camera's pose from one frame of the field, with known intrinsics.

    Raises:
        ValueError: no field found, or a calibration that does not look like the table's
            (:func:`check_field`).
    """
    corners = find_field_corners(frame, home_side)
    calibration = calibrate_extrinsics(corners, K, dist)
    check_field(corners, calibration, frame.shape)
    return calibration
