"""ROS 2 node: tracked spots and line profiles in, surface points (PointCloud2) and fits out.

The live spots (`spots_live`, as measured before the Hampel filter) become `points_live` at
once, for a live view; `points` and `surface_fit` come from the filtered spots. Under a rolling
shutter (the camera file's readout_s) each cloud point carries its row's time and the fits are
the surface at the frame's time (`sds_recon.instant`): a frame's cloud and fit then come when
the next frame's spots do, the last one after IDLE_FLUSH_S without spots."""

from __future__ import annotations

import numpy as np
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import MessageInfo
from sds_model.rig import Rig, RigError, load_rig, rig_document
from sds_recon.instant import InstantFits, InstantFrame, sample_offsets_s
from sds_recon.reconstruction import (
    SurfaceFits,
    SurfacePoints,
    fit_surface,
    frame_points,
    reconstruct_line,
)
from sds_ros.hosted_node import HostedNode
from sds_ros.point_cloud import points_to_cloud, stamp_s
from sds_ros.qos import live_qos, start_when_consumed, stream_qos
from sds_ros.shedding import LiveShedding, report_on_console, waited_s
from sds_ros.static_tf import TF_STATIC_TOPIC, rig_transforms, static_tf_qos
from sds_tracker.spots import is_measured
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import String

from sds_msgs.msg import (
    LaserLineProfile,
    LaserSpotArray,
    SurfaceFit,
)
from tf2_msgs.msg import TFMessage

EXIT_CONFIG_ERROR = 2
IDLE_FLUSH_S = 1.0
"""With no spots for this long, the frame whose fits wait for a next one is fitted."""


def surface_fit_msg(msg: LaserSpotArray, points: SurfacePoints, fits: SurfaceFits
                    ) -> SurfaceFit:
    """The frame's SurfaceFit: plane, modal amplitudes and the rejected points' lasers."""
    fit = SurfaceFit(header=msg.header, frame_index=msg.frame_index,
                     point_count=len(points.laser_ids) - fits.rejected_count,
                     rejected_count=fits.rejected_count,
                     rejected_laser_ids=[int(i) for i in points.laser_ids[fits.rejected]])
    nan = float("nan")
    fit.p00_mm = fit.p10 = fit.p01 = fit.tilt_x_rad = fit.tilt_y_rad = nan
    fit.r_squared = fit.rmse_mm = fit.sse_mm2 = nan
    if fits.plane is not None:
        plane = fits.plane
        fit.p00_mm, fit.p10, fit.p01 = plane.p00_mm, plane.p10, plane.p01
        fit.tilt_x_rad, fit.tilt_y_rad = plane.tilt_x_rad, plane.tilt_y_rad
        fit.r_squared, fit.rmse_mm, fit.sse_mm2 = plane.r_squared, plane.rmse_mm, plane.sse_mm2
    if fits.modal is not None:
        fit.mode_names = list(fits.modal.names)
        fit.modal_amplitudes_mm = [float(a) for a in fits.modal.amplitudes_mm]
    return fit


PARAMETERS = {"rig": "", "beam_weight": 0.5, "default_sigma_px": 0.1, "frame_id": "world",
              "wait_for_consumers": 0, "wait_for_fit_consumers": 0, "live_max_lag_s": 0.1}
"""The node's parameters and defaults (config/params/recon.yaml documents each)."""


class ReconstructionNode(HostedNode):
    """Triangulate every valid spot (Eq. 9) and line sample (Eqs. 10–11); fit the surface."""

    def __init__(self, node_name: str = "recon", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        p = self.declare_parameter_table(PARAMETERS)
        try:
            self._rig: Rig = load_rig(p["rig"])
        except (RigError, OSError) as error:
            self.get_logger().error(f"cannot load the rig: {error}")
            self.exit_code = EXIT_CONFIG_ERROR
            self.finished.set()
            return
        self._instant: InstantFits[int] = InstantFits(self._rig)
        self._unfitted: dict[int, tuple[LaserSpotArray, SurfacePoints]] = {}
        self._taken = 0   # spots and line messages, for the node host's drain at a stop
        self._last_spots = self.get_clock().now()
        self.create_timer(0.25, self._fit_if_idle)
        self._shedding = LiveShedding("points_live", float(p["live_max_lag_s"]))
        report_on_console(self, self._shedding)
        self._beam_weight = float(p["beam_weight"])
        self._default_sigma = float(p["default_sigma_px"])
        self._frame_id = p["frame_id"]
        self._points_pub = self.create_publisher(PointCloud2, "points", stream_qos())
        self._live_pub = self.create_publisher(PointCloud2, "points_live", live_qos())
        self._line_pub = self.create_publisher(PointCloud2, "line_points", stream_qos())
        self._fit_pub = self.create_publisher(SurfaceFit, "surface_fit", stream_qos())
        # The rig, camera inline, latched: a recording carries what it was measured with.
        self._rig_pub = self.create_publisher(String, "rig", QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._rig_pub.publish(String(data=rig_document(self._rig)))
        # The camera's and the Arduino's frames in the world, for tf-aware tools (RViz,
        # Foxglove, tf2_echo) and recordings.
        self._tf_static_pub = self.create_publisher(TFMessage, TF_STATIC_TOPIC, static_tf_qos())
        self._tf_static_pub.publish(rig_transforms(self._rig, self.get_clock().now().to_msg(),
                                                   self._frame_id))
        consumers = int(p["wait_for_consumers"])
        fit_consumers = int(p["wait_for_fit_consumers"]) or consumers
        # No input is taken before every output has its consumers (e.g. the recorder).
        start_when_consumed(self, [(self._points_pub, consumers), (self._line_pub, consumers),
                                   (self._fit_pub, fit_consumers)], self._subscribe_inputs)
        self.get_logger().info(f"rig {p['rig']}: {len(self._rig.diodes)} diodes")

    def _subscribe_inputs(self) -> None:
        self.create_subscription(LaserSpotArray, "spots_live", self._on_live_spots,
                                 live_qos())
        self.create_subscription(LaserSpotArray, "spots", self._on_spots, stream_qos())
        self.create_subscription(LaserLineProfile, "line", self._on_line, stream_qos())

    def _frame_points(self, msg: LaserSpotArray) -> SurfacePoints:
        """The frame's spots triangulated (Eq. 9), those not measured (lost, or the Hampel
        filter's prediction) left out."""
        spots = msg.spots
        return frame_points(
            self._rig, [s.laser_id for s in spots], [[s.x_px, s.y_px] for s in spots],
            [s.sigma_px for s in spots], [not is_measured(s.flags) for s in spots],
            self._beam_weight, self._default_sigma)

    def _sample_offsets_s(self, points: SurfacePoints) -> np.ndarray | None:
        """When each point's row was exposed after the frame's stamp [s]: a rolling shutter's
        (the camera file's readout_s); None for a global shutter (no time field)."""
        if not self._instant.timed:
            return None
        return sample_offsets_s(self._rig, points)

    def _on_live_spots(self, msg: LaserSpotArray, info: MessageInfo) -> None:
        """At once, as measured: flagged by this frame's own fits (shed when late)."""
        if not self._shedding.keep(waited_s(info)):
            return
        points = self._frame_points(msg)
        fits = fit_surface(points, self._rig.container.radius_mm)
        header = msg.header
        header.frame_id = self._frame_id
        self._live_pub.publish(points_to_cloud(header, points, fits.rejected,
                                               self._sample_offsets_s(points)))

    def _on_spots(self, msg: LaserSpotArray) -> None:
        self._taken += 1
        points = self._frame_points(msg)
        self._unfitted[msg.frame_index] = (msg, points)
        self._last_spots = self.get_clock().now()
        self._publish_fitted(self._instant.push(msg.frame_index, stamp_s(msg), points))

    def _publish_fitted(self, fitted: list[InstantFrame[int]]) -> None:
        """Each fitted frame's cloud (its points as measured, flagged by the fits) and fit."""
        for instant in fitted:
            fits = instant.fits
            msg, points = self._unfitted.pop(instant.key)
            header = msg.header
            header.frame_id = self._frame_id
            self._points_pub.publish(points_to_cloud(header, points, fits.rejected,
                                                     self._sample_offsets_s(points)))
            self._fit_pub.publish(surface_fit_msg(msg, points, fits))

    def _fit_if_idle(self) -> None:
        idle_s = (self.get_clock().now() - self._last_spots).nanoseconds * 1e-9
        if self._unfitted and idle_s > IDLE_FLUSH_S:
            self._publish_fitted(self._instant.flush())

    def messages_taken(self) -> int | None:
        """Spots and line messages taken so far: at a stop, the node host takes what the
        tracker published before it stopped, its Hampel window's last frames among them
        (`node_host.drain`), before this node closes; None if the node could not start."""
        return getattr(self, "_taken", None)

    def close(self) -> None:
        """At a stop, the frames still waiting for the next one's fit (a rolling shutter's
        fits hold one) are fitted and published, as after an idle second."""
        if getattr(self, "_unfitted", None):
            self._publish_fitted(self._instant.flush())

    def _on_line(self, msg: LaserLineProfile) -> None:
        self._taken += 1
        result = reconstruct_line(self._rig, np.column_stack([msg.x_px, msg.y_px]),
                                  msg.sigma_px, self._default_sigma)
        header = msg.header
        header.frame_id = self._frame_id
        self._line_pub.publish(points_to_cloud(header, result, None,
                                               self._sample_offsets_s(result)))


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(ReconstructionNode, "recon", False)], args))
