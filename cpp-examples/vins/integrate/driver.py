#!/usr/bin/python3
"""Plays topoloc-sim sequences to VINS-Fusion's loop_fusion_node as its VIO estimator would.

    driver.py SEQ_DIR [SEQ_DIR ...] [--image-topic /cam0/image_raw] [--rate-hz 5] [--pause-s 8]
              [--features 150] [--out DIR]

Run with /usr/bin/python3 (Debian's ROS: rospy, cv2, numpy) and ROS_MASTER_URI set. Per frame,
all with the same header stamp: /vins_estimator/extrinsic (camera in body: tic = 0, qic =
R_body_camera), the image (mono8), /vins_estimator/keyframe_point (up to --features corners with
a depth, as points of the VIO world, channels[i].values = [x_norm, y_norm, u, v, id]) and
/vins_estimator/keyframe_pose (the body in the VIO world).

Every sequence gets its own VIO frame, as VINS would start it: the odometry with frame 0 moved to
the origin and its yaw removed (roll and pitch kept). Stamps are the sequence's own plus an offset
that puts each sequence at least --gap-s after the previous one: loop_fusion's image_callback
starts a new sequence when a stamp jumps forward by more than 1 s (or back), and then clears its
queues, so the first frame of every later sequence is lost. Frames go out at --rate-hz wall clock
(loop_fusion's process() keeps one pose of those queued and drops the rest when it falls behind),
with --pause-s between sequences. --out gets truth-K.txt and odometry-K.txt per sequence (TUM,
published stamps; the odometry in its VIO frame, as published) for judge.py.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import rosgraph
import rospy
from geometry_msgs.msg import Point32
from nav_msgs.msg import Odometry
from sensor_msgs.msg import ChannelFloat32, Image, PointCloud

R_BODY_CAMERA = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
POSE_TOPIC = "/vins_estimator/keyframe_pose"
POINT_TOPIC = "/vins_estimator/keyframe_point"
EXTRINSIC_TOPIC = "/vins_estimator/extrinsic"

Pose = tuple[np.ndarray, np.ndarray]  # (R 3x3, t 3)


def quat_to_rot(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    x, y, z, w = qx / n, qy / n, qz / n, qw / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rot_to_quat(r: np.ndarray) -> tuple[float, float, float, float]:
    """(qx, qy, qz, qw) of a rotation matrix, qw >= 0."""
    trace = float(r[0, 0] + r[1, 1] + r[2, 2])
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = (
            (r[2, 1] - r[1, 2]) / s,
            (r[0, 2] - r[2, 0]) / s,
            (r[1, 0] - r[0, 1]) / s,
            0.25 * s,
        )
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = (
            0.25 * s,
            (r[0, 1] + r[1, 0]) / s,
            (r[0, 2] + r[2, 0]) / s,
            (r[2, 1] - r[1, 2]) / s,
        )
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = (
            (r[0, 1] + r[1, 0]) / s,
            0.25 * s,
            (r[1, 2] + r[2, 1]) / s,
            (r[0, 2] - r[2, 0]) / s,
        )
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = (
            (r[0, 2] + r[2, 0]) / s,
            (r[1, 2] + r[2, 1]) / s,
            0.25 * s,
            (r[1, 0] - r[0, 1]) / s,
        )
    sign = -1.0 if q[3] < 0 else 1.0
    return (
        sign * float(q[0]),
        sign * float(q[1]),
        sign * float(q[2]),
        sign * float(q[3]),
    )


def rot_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def read_tum(path: Path) -> tuple[list[float], list[Pose]]:
    stamps: list[float] = []
    poses: list[Pose] = []
    for line in path.read_text().splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        v = [float(x) for x in line.split()]
        stamps.append(v[0])
        poses.append((quat_to_rot(v[4], v[5], v[6], v[7]), np.array(v[1:4])))
    return stamps, poses


def to_vio_frame(odometry: list[Pose]) -> list[Pose]:
    """The odometry in a VIO frame: frame 0 at the origin with yaw 0, roll and pitch kept."""
    r0, t0 = odometry[0]
    undo_yaw = rot_z(-math.atan2(r0[1, 0], r0[0, 0]))
    return [(undo_yaw @ r, undo_yaw @ (t - t0)) for r, t in odometry]


def tum_line(stamp: float, pose: Pose) -> str:
    qx, qy, qz, qw = rot_to_quat(pose[0])
    x, y, z = (float(c) for c in pose[1])
    return f"{stamp:.6f} {x:.9f} {y:.9f} {z:.9f} {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}\n"


def odometry_msg(stamp: rospy.Time, pose: Pose) -> Odometry:
    msg = Odometry()
    msg.header.stamp = stamp
    msg.header.frame_id = "world"
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    p.x, p.y, p.z = (float(c) for c in pose[1])
    o.x, o.y, o.z, o.w = rot_to_quat(pose[0])
    return msg


class Sequence:
    def __init__(self, folder: Path) -> None:
        self.dir = folder
        self.stamps, self.odometry = read_tum(folder / "odometry.txt")
        truth_stamps, self.truth = read_tum(folder / "groundtruth.txt")
        if truth_stamps != self.stamps or not self.stamps:
            raise ValueError(f"{folder}: odometry and ground truth differ in stamps (or are empty)")
        k = json.loads((folder / "intrinsics.json").read_text())
        self.fx, self.fy, self.cx, self.cy = (float(k[n]) for n in ("fx", "fy", "cx", "cy"))
        manifest = folder / "manifest.json"
        scale = json.loads(manifest.read_text()).get("depth_scale") if manifest.exists() else None
        self.depth_scale = float(scale) if scale else 1000.0
        self.vio = to_vio_frame(self.odometry)

    def image(self, i: int) -> np.ndarray:
        image = cv2.imread(str(self.dir / "images" / f"{i:06d}.png"), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise ValueError(f"cannot read {self.dir}/images/{i:06d}.png")
        return np.ascontiguousarray(image)

    def depth_m(self, i: int) -> np.ndarray:
        depth = cv2.imread(str(self.dir / "depth" / f"{i:06d}.png"), cv2.IMREAD_UNCHANGED)
        if depth is None or depth.dtype != np.uint16:
            raise ValueError(f"{self.dir}/depth/{i:06d}.png is not a 16-bit depth image")
        return depth.astype(np.float64) / self.depth_scale


class Driver:
    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.next_id = 0
        self.image_pub = rospy.Publisher(args.image_topic, Image, queue_size=100)
        self.point_pub = rospy.Publisher(POINT_TOPIC, PointCloud, queue_size=100)
        self.pose_pub = rospy.Publisher(POSE_TOPIC, Odometry, queue_size=100)
        self.extrinsic_pub = rospy.Publisher(EXTRINSIC_TOPIC, Odometry, queue_size=100)
        self.extrinsic: Pose = (R_BODY_CAMERA, np.zeros(3))

    def wait_for_subscribers(self, timeout_s: float) -> bool:
        publishers = [self.image_pub, self.point_pub, self.pose_pub, self.extrinsic_pub]
        deadline = time.monotonic() + timeout_s
        while not rospy.is_shutdown():
            missing = [p.name for p in publishers if p.get_num_connections() == 0]
            if not missing:
                time.sleep(0.5)  # let the last connection's handshake settle
                return True
            if time.monotonic() > deadline:
                print(
                    f"driver.py: no subscriber after {timeout_s:.0f} s on {', '.join(missing)}"
                    " (is loop_fusion_node running, with image0_topic = "
                    f"{self.args.image_topic}?)",
                    file=sys.stderr,
                )
                return False
            time.sleep(0.1)
        return False

    def points(self, seq: Sequence, i: int, grey: np.ndarray, stamp: rospy.Time) -> PointCloud:
        cloud = PointCloud()
        cloud.header.stamp = stamp
        cloud.header.frame_id = "world"
        depth = seq.depth_m(i)
        corners = cv2.goodFeaturesToTrack(
            grey,
            maxCorners=3 * self.args.features,
            qualityLevel=0.01,
            minDistance=self.args.min_distance,
        )
        if corners is None:
            return cloud
        r_vio, t_vio = seq.vio[i]
        r_vio_camera = r_vio @ R_BODY_CAMERA
        for u, v in corners.reshape(-1, 2):
            if len(cloud.points) >= self.args.features:
                break
            col, row = round(float(u)), round(float(v))
            if not (0 <= row < depth.shape[0] and 0 <= col < depth.shape[1]):
                continue
            z = float(depth[row, col])
            if z <= 0:
                continue
            x_norm, y_norm = (float(u) - seq.cx) / seq.fx, (float(v) - seq.cy) / seq.fy
            world = r_vio_camera @ np.array([x_norm * z, y_norm * z, z]) + t_vio
            cloud.points.append(Point32(*(float(c) for c in world)))
            cloud.channels.append(
                ChannelFloat32(values=[x_norm, y_norm, float(u), float(v), float(self.next_id)])
            )
            self.next_id += 1
        return cloud

    def publish_frame(self, seq: Sequence, i: int, stamp_s: float) -> None:
        stamp = rospy.Time.from_sec(stamp_s)
        grey = seq.image(i)
        image = Image()
        image.header.stamp = stamp
        image.header.frame_id = "cam0"
        image.height, image.width = grey.shape
        image.encoding = "mono8"
        image.is_bigendian = 0
        image.step = grey.shape[1]
        image.data = grey.tobytes()
        cloud = self.points(seq, i, grey, stamp)
        self.extrinsic_pub.publish(odometry_msg(stamp, self.extrinsic))
        self.image_pub.publish(image)
        self.point_pub.publish(cloud)
        self.pose_pub.publish(odometry_msg(stamp, seq.vio[i]))

    def play(self, k: int, seq: Sequence, offset: float) -> None:
        out: Path = self.args.out
        header = "# timestamp tx ty tz qx qy qz qw\n"
        for name, poses in (("truth", seq.truth), ("odometry", seq.vio)):
            lines = (tum_line(t + offset, pose) for t, pose in zip(seq.stamps, poses))
            (out / f"{name}-{k}.txt").write_text(header + "".join(lines))
        period = 1.0 / self.args.rate_hz
        start = time.monotonic()
        for i, t in enumerate(seq.stamps):
            if rospy.is_shutdown():
                raise KeyboardInterrupt
            self.publish_frame(seq, i, t + offset)
            delay = start + (i + 1) * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        print(
            f"sequence {k}: {seq.dir}: {len(seq.stamps)} frames, "
            f"{seq.stamps[-1] - seq.stamps[0]:.1f} s of data, stamps "
            f"{seq.stamps[0] + offset:.3f}..{seq.stamps[-1] + offset:.3f}, "
            f"published in {time.monotonic() - start:.1f} s",
            flush=True,
        )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sequences", nargs="+", type=Path, metavar="SEQ_DIR")
    parser.add_argument("--image-topic", default="/cam0/image_raw")
    parser.add_argument("--rate-hz", type=float, default=5.0, help="frames per wall-clock second")
    parser.add_argument("--pause-s", type=float, default=8.0, help="wall-clock pause between")
    parser.add_argument("--features", type=int, default=150, help="most points per frame")
    parser.add_argument("--min-distance", type=float, default=15.0, help="between corners, px")
    parser.add_argument("--first-stamp", type=float, default=1000.0, help="stamp offset, seq 0")
    parser.add_argument("--gap-s", type=float, default=1000.0, help="stamp gap between sequences")
    parser.add_argument("--wait-s", type=float, default=60.0, help="subscriber wait timeout")
    parser.add_argument("--linger-s", type=float, default=2.0, help="wait before exit (flush)")
    parser.add_argument("--out", type=Path, default=Path("."))
    args = parser.parse_args(rospy.myargv()[1:])
    if args.rate_hz <= 0 or args.features <= 0:
        parser.error("--rate-hz and --features must be positive")
    if len(args.sequences) > 5:
        parser.error("loop_fusion_node supports 5 sequences (ROS_BREAK in new_sequence)")
    try:
        sequences = [Sequence(d) for d in args.sequences]
    except (OSError, ValueError, KeyError) as e:
        print(f"driver.py: {e}", file=sys.stderr)
        return 2
    if not rosgraph.is_master_online():
        print(f"driver.py: no ROS master at {rosgraph.get_master_uri()}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    rospy.init_node("topoloc_vins_driver", disable_signals=False)
    driver = Driver(args)
    if not driver.wait_for_subscribers(args.wait_s):
        return 3
    offsets: list[float] = []
    for k, seq in enumerate(sequences):
        offset = args.first_stamp - seq.stamps[0]
        if offsets:
            last = sequences[k - 1].stamps[-1] + offsets[-1]
            offset = math.ceil(last + args.gap_s) - seq.stamps[0]
        offsets.append(offset)
    try:
        for k, (seq, offset) in enumerate(zip(sequences, offsets)):
            if k > 0:
                time.sleep(args.pause_s)
            driver.play(k, seq, offset)
        time.sleep(args.linger_s)
    except KeyboardInterrupt:
        print("driver.py: interrupted", file=sys.stderr)
        return 130
    except (OSError, ValueError) as e:
        print(f"driver.py: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
