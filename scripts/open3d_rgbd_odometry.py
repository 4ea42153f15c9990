"""Open3D's frame-to-frame RGB-D odometry on a TUM folder: the reference for `gcs slam run`.

    target/pyenv/bin/python scripts/open3d_rgbd_odometry.py ../shared/data/rgbd/tum_fr1_rpy_first150 out.txt

Chains Open3D's hybrid (photometric + geometric) RGB-D odometry between consecutive frames of
`associations.txt`, with the Freiburg 1 intrinsics, writes the camera trajectory in TUM format
(`gcs slam eval` scores it) and prints the time per frame pair.
"""

import sys
import time

import numpy as np
import open3d as o3d


def quaternion(r: np.ndarray) -> tuple:
    """x, y, z, w of a rotation matrix (Shepperd's method)."""
    t = np.trace(r)
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        return ((r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s)
    i = int(np.argmax(np.diag(r)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
    q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
    q[i] = 0.25 * s
    q[j] = (r[j, i] + r[i, j]) / s
    q[k] = (r[k, i] + r[i, k]) / s
    return tuple(q)


def main(folder: str, out: str) -> None:
    pairs = []
    with open(f"{folder}/associations.txt") as f:
        for line in f:
            if line.strip() and not line.startswith("#"):
                t_rgb, rgb, _, depth = line.split()[:4]
                pairs.append((float(t_rgb), f"{folder}/{rgb}", f"{folder}/{depth}"))
    # Freiburg 1 (TUM's calibration), depth in 1/5000 m.
    camera = o3d.camera.PinholeCameraIntrinsic(640, 480, 517.3, 516.5, 318.6, 255.3)
    option = o3d.pipelines.odometry.OdometryOption()
    jacobian = o3d.pipelines.odometry.RGBDOdometryJacobianFromHybridTerm()

    def load(rgb: str, depth: str):
        return o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.io.read_image(rgb),
            o3d.io.read_image(depth),
            depth_scale=5000.0,
            depth_trunc=4.0,
            convert_rgb_to_intensity=True,
        )

    pose = np.eye(4)
    poses = [(pairs[0][0], pose.copy())]
    previous = load(*pairs[0][1:])
    spent = 0.0
    for stamp, rgb, depth in pairs[1:]:
        current = load(rgb, depth)
        started = time.perf_counter()
        ok, previous_from_current, _ = o3d.pipelines.odometry.compute_rgbd_odometry(
            current, previous, camera, np.eye(4), jacobian, option
        )
        spent += time.perf_counter() - started
        if ok:
            pose = pose @ previous_from_current
        poses.append((stamp, pose.copy()))
        previous = current
    with open(out, "w") as f:
        for stamp, p in poses:
            q = quaternion(p[:3, :3])
            t = p[:3, 3]
            f.write(f"{stamp:.6f} {t[0]:.6f} {t[1]:.6f} {t[2]:.6f} {q[0]:.6f} {q[1]:.6f} {q[2]:.6f} {q[3]:.6f}\n")
    print(f"open3d {o3d.__version__}: {len(poses)} poses, {spent / max(len(pairs) - 1, 1) * 1e3:.1f} ms per frame pair")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
