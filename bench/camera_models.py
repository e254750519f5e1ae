"""Camera-model benchmark: rays and projections per second on 10^6 points, both models.

Usage: python bench/camera_models.py [--points 1000000] [--repeats 5]
Prints the best of `repeats` runs for pixel_to_ray and project of the seed's GoPro (Scaramuzza,
Table 2, 3840x2160) and of a pinhole + Brown-Conrady camera, with OpenCV's own undistortPoints
and projectPoints on the same pinhole points as the reference rate, and the round-trip error.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
from sds_model.camera import PinholeCamera, load_camera

REPO = Path(__file__).resolve().parents[1]


def best_seconds(run: Callable[[], object], repeats: int) -> float:
    """Shortest wall time of `repeats` runs [s]."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    gopro = load_camera(REPO / "config" / "cameras" / "gopro_hero5_session.yaml")
    pinhole = PinholeCamera(3840, 2160, 2200.0, 2200.0, 1919.5, 1079.5, k1=-0.2, k2=0.05,
                            k3=-0.005, p1=1e-4, p2=-2e-4)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-12)
    print(f"{args.points:,} points, best of {args.repeats}")
    print(f"{'model':<28} {'operation':<14} {'M points/s':>10} {'round trip max px':>18}")
    models = (("scaramuzza (GoPro, Table 2)", gopro), ("pinhole + Brown-Conrady", pinhole))
    for name, camera in models:
        pixels = rng.uniform([0, 0], [camera.width_px - 1, camera.height_px - 1], (args.points, 2))
        rays = camera.pixel_to_ray(pixels)
        error = float(np.nanmax(np.abs(camera.project(rays) - pixels)))
        for operation, run in (("pixel_to_ray", lambda c=camera, p=pixels: c.pixel_to_ray(p)),
                               ("project", lambda c=camera, r=rays: c.project(r))):
            rate = args.points / best_seconds(run, args.repeats) / 1e6
            print(f"{name:<28} {operation:<14} {rate:>10.2f} {error:>18.2e}")
    pixels = rng.uniform([0, 0], [3839, 2159], (args.points, 1, 2))
    k, dist = pinhole.camera_matrix(), pinhole.distortion_coefficients()
    rate = args.points / best_seconds(
        lambda: cv2.undistortPoints(pixels, k, dist, criteria=criteria), args.repeats) / 1e6
    print(f"{'OpenCV (same pinhole)':<28} {'undistortPts':<14} {rate:>10.2f}")
    points = pinhole.pixel_to_ray(pixels.reshape(-1, 2))
    rate = args.points / best_seconds(
        lambda: cv2.projectPoints(points, np.zeros(3), np.zeros(3), k, dist), args.repeats) / 1e6
    print(f"{'OpenCV (same pinhole)':<28} {'projectPoints':<14} {rate:>10.2f}")


if __name__ == "__main__":
    main()
