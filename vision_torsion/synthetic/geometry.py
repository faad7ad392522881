"""Where things are: the disk's rotation and the camera's view of the disk plane.

Disk-plane coordinates are the pixel coordinates an ideal camera square to the disk
would see (so with no tilt and no distortion they equal image coordinates). The
camera model is a pinhole at distance f (``focal_length_px``) from the principal
point (the image centre), the disk plane tilted by ``tilt_deg`` about an in-plane
axis at ``tilt_axis_deg`` through the principal point (a homography), followed by
radial distortion ``x_d = c + (x - c)(1 + k1·ρ²)`` with ρ = |x - c| / f.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CameraMapping", "marker_centres_disk", "marker_centres_image", "rotate_about"]


def rotate_about(points, centre, angle_deg):
    """Rotate points (x, y) in image axes by `angle_deg` counter-clockwise as displayed."""
    a = np.deg2rad(angle_deg)
    c, s = np.cos(a), np.sin(a)
    pts = np.asarray(points, dtype=np.float64)
    dx = pts[..., 0] - centre[0]
    dy = pts[..., 1] - centre[1]
    # y points down, so a counter-clockwise turn as displayed is clockwise in (x, y).
    return np.stack([centre[0] + c * dx + s * dy, centre[1] - s * dx + c * dy], axis=-1)


def marker_centres_disk(scene, angle_deg):
    """Marker centres on the disk plane (px) at disk rotation `angle_deg`; shape (n, 2)."""
    mk, disk = scene.markers, scene.disk
    phi = np.deg2rad(np.asarray(mk.positions_deg, dtype=np.float64) + angle_deg)
    dist = np.asarray(mk.distances(), dtype=np.float64)
    return np.stack(
        [disk.center_x + dist * np.cos(phi), disk.center_y - dist * np.sin(phi)],
        axis=-1,
    )


def marker_centres_image(scene, angle_deg):
    """True marker centres in the image (px): the projected disk-plane centres; shape (n, 2)."""
    c = marker_centres_disk(scene, angle_deg)
    x, y = CameraMapping(scene).to_image(c[:, 0], c[:, 1])
    return np.stack([x, y], axis=-1)


class CameraMapping:
    """Mapping between disk-plane and image coordinates for a scene's camera.

    Parameters
    ----------
    scene : Scene
        Uses ``scene.optics`` (tilt, axis, focal length, k1) and the image size.
    """

    def __init__(self, scene):
        op = scene.optics
        self.f = float(op.focal_length_px)
        self.k1 = float(op.radial_k1)
        self.c = np.array([(scene.image.width - 1) / 2.0, (scene.image.height - 1) / 2.0])
        beta = np.deg2rad(op.tilt_deg)
        psi = np.deg2rad(op.tilt_axis_deg)
        axis = np.array([np.cos(psi), -np.sin(psi), 0.0])
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        self.R = np.eye(3) + np.sin(beta) * k + (1 - np.cos(beta)) * (k @ k)
        self.tilted = abs(op.tilt_deg) > 0
        self.is_identity = not self.tilted and self.k1 == 0.0

    # -- tilt (homography) ---------------------------------------------------------
    def _plane_to_undistorted(self, X, Y):
        qx, qy = X - self.c[0], Y - self.c[1]
        R = self.R
        px = R[0, 0] * qx + R[0, 1] * qy
        py = R[1, 0] * qx + R[1, 1] * qy
        pz = R[2, 0] * qx + R[2, 1] * qy
        w = self.f / (self.f + pz)
        return self.c[0] + px * w, self.c[1] + py * w

    def _undistorted_to_plane(self, x, y):
        ux, uy = x - self.c[0], y - self.c[1]
        n = self.R[:, 2]
        # ray from the camera centre (0, 0, -f) through (ux, uy, 0) meets the plane n·P = 0
        t = self.f * n[2] / (n[0] * ux + n[1] * uy + n[2] * self.f)
        P = np.stack([t * ux, t * uy, t * self.f - self.f])
        Q = np.tensordot(self.R.T, P, axes=1)
        return self.c[0] + Q[0], self.c[1] + Q[1]

    # -- radial distortion ----------------------------------------------------------
    def _distort(self, x, y):
        dx, dy = x - self.c[0], y - self.c[1]
        g = 1 + self.k1 * (dx * dx + dy * dy) / self.f**2
        return self.c[0] + dx * g, self.c[1] + dy * g

    def _undistort(self, x, y):
        dx, dy = x - self.c[0], y - self.c[1]
        ux, uy = dx, dy
        for _ in range(20):
            g = 1 + self.k1 * (ux * ux + uy * uy) / self.f**2
            ux, uy = dx / g, dy / g
        return self.c[0] + ux, self.c[1] + uy

    # -- public ----------------------------------------------------------------------
    def to_image(self, X, Y):
        """Disk-plane (px) to image coordinates (px)."""
        X = np.asarray(X, dtype=np.float64)
        Y = np.asarray(Y, dtype=np.float64)
        if self.is_identity:
            return X, Y
        x, y = self._plane_to_undistorted(X, Y) if self.tilted else (X, Y)
        return self._distort(x, y) if self.k1 else (x, y)

    def to_disk(self, x, y):
        """Image (px) to disk-plane coordinates (px)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if self.is_identity:
            return x, y
        if self.k1:
            x, y = self._undistort(x, y)
        return self._undistorted_to_plane(x, y) if self.tilted else (x, y)
