"""A graph process's cost of taking messages: rclpy's SingleThreadedExecutor (what
`sds_ros.node_host` spins) against its EventsExecutor, on the recorder's mix of messages.

Usage: python bench/executor.py [--seconds 14] [--pairs 2]

A publisher process sends what a recorder takes per frame of a 30 fps drop: one frame's
packet (foxglove_msgs/CompressedVideo, 260 kB, about a 4K H.264 frame at 62 Mbit/s), 20 IMU
samples (sensor_msgs/Imu: the camera's 200 Hz accelerometer and 400 Hz gyroscope) and three
small point clouds, all reliable. A subscriber process takes them serialized (as the
recorder does) with one executor or the other and prints its CPU time per frame. The two
executors alternate, `--pairs` times, in one run (the machine's speed varies from day to day:
compare within a run). Then each once more with callbacks that also take the message's info
(`rclpy.subscription.MessageInfo`: its publisher's sequence number and source time, which
the recorder, tracker, reconstruction and viewer read), wrapped as the graph's nodes wrap
them (`sds_ros.executor.WithMessageInfo`; the graph spins the EventsExecutor).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

from sds_bringup.ros_env import graph_environment, pick_domain_id

FPS = 30
IMU_PER_FRAME = 20
CLOUDS_PER_FRAME = 3
PACKET_BYTES = 260_000
SETTLE_S = 3.0
"""Time the publisher waits for discovery before its first frame [s]."""


def publish(seconds: float) -> None:
    """The publisher process: the recorder's messages at 30 frames a second."""
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu, PointCloud2

    from foxglove_msgs.msg import CompressedVideo

    rclpy.init()
    node = Node("bench_publisher")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                     history=HistoryPolicy.KEEP_LAST)
    video = node.create_publisher(CompressedVideo, "video", qos)
    imu = node.create_publisher(Imu, "imu", qos)
    clouds = node.create_publisher(PointCloud2, "points", qos)
    packet = CompressedVideo(format="h264", data=bytes(PACKET_BYTES))
    cloud = PointCloud2(width=100, data=bytes(1600))
    sample = Imu()
    time.sleep(SETTLE_S)
    start, frames = time.monotonic(), 0
    while time.monotonic() - start < seconds:
        video.publish(packet)
        for _ in range(IMU_PER_FRAME):
            imu.publish(sample)
        for _ in range(CLOUDS_PER_FRAME):
            clouds.publish(cloud)
        frames += 1
        time.sleep(max(0.0, start + frames / FPS - time.monotonic()))
    time.sleep(1.0)
    node.destroy_node()
    rclpy.try_shutdown()


def subscribe(kind: str, seconds: float, with_info: bool) -> None:
    """The subscriber process: every message taken serialized (with its info if
    `with_info`); prints frames and CPU ms per frame from the first packet on."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sds_ros.executor import WithMessageInfo
    from sensor_msgs.msg import Imu, PointCloud2

    from foxglove_msgs.msg import CompressedVideo

    rclpy.init()
    node = Node("bench_subscriber")
    qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE,
                     history=HistoryPolicy.KEEP_LAST)
    counts = {"video": 0, "imu": 0, "points": 0}

    def counter(topic: str):
        """A callback that counts `topic`'s messages, with their info if `with_info`."""
        def count(_message: bytes) -> None:
            counts[topic] += 1

        def count_with_info(_message: bytes, _info: object) -> None:
            counts[topic] += 1
        return WithMessageInfo(count_with_info) if with_info else count

    for topic, message_type in (("video", CompressedVideo), ("imu", Imu),
                                ("points", PointCloud2)):
        node.create_subscription(message_type, topic, counter(topic), qos, raw=True)
    executor = EventsExecutor() if kind == "events" else SingleThreadedExecutor()
    executor.add_node(node)
    end = time.monotonic() + seconds
    while counts["video"] == 0 and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    cpu_start, first = time.process_time(), counts["video"]
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    frames = counts["video"] - first
    print(f"{frames} {1e3 * (time.process_time() - cpu_start) / max(frames, 1):.2f}",
          flush=True)
    executor.shutdown(timeout_sec=1.0)
    node.destroy_node()
    rclpy.try_shutdown()


def run_pair(kind: str, seconds: float, with_info: bool, env: dict[str, str]) -> str:
    """One subscriber with `kind` beside one publisher: frames taken and CPU ms per frame,
    or the subscriber's last line of error."""
    listening_s = seconds + SETTLE_S + 3.0
    subscriber = subprocess.Popen([sys.executable, __file__, "--role", "subscribe", "--kind",
                                   kind, "--seconds", str(listening_s),
                                   *(["--with-info"] if with_info else [])], env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    subprocess.run([sys.executable, __file__, "--role", "publish", "--seconds", str(seconds)],
                   env=env, check=True)
    output, errors = subscriber.communicate(timeout=listening_s + 30)
    if subscriber.returncode != 0:
        return f"failed: {errors.strip().splitlines()[-1]}"
    frames, cpu_ms = output.split()
    return f"{int(frames):7d} {float(cpu_ms):13.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=14.0)
    parser.add_argument("--pairs", type=int, default=2)
    parser.add_argument("--role", choices=("bench", "publish", "subscribe"), default="bench")
    parser.add_argument("--kind", choices=("single", "events"), default="single")
    parser.add_argument("--with-info", action="store_true")
    args = parser.parse_args()
    if args.role == "publish":
        publish(args.seconds)
        return
    if args.role == "subscribe":
        subscribe(args.kind, args.seconds, args.with_info)
        return
    # The graph's own environment (transport, QoS profile), on a domain of its own.
    env = graph_environment(pick_domain_id())
    print(f"{'executor':24s} {'frames':>7s} {'CPU ms/frame':>13s}")
    runs = [("single", False), ("events", False)] * args.pairs + [("single", True),
                                                                   ("events", True)]
    for kind, with_info in runs:
        name = f"{kind}{' with info' if with_info else ''}"
        print(f"{name:24s} {run_pair(kind, args.seconds, with_info, env)}", flush=True)


if __name__ == "__main__":
    main()
