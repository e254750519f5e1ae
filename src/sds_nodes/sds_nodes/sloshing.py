"""ROS 2 node: surface fits in, running sloshing estimates (frequency, damping) out."""

from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
from sds_ros.hosted_node import HostedNode
from sds_ros.point_cloud import stamp_s
from sds_ros.qos import start_when_consumed, stream_qos
from sds_sloshing.modal import ModalSeries
from sds_sloshing.running import RunningAnalysis

from sds_msgs.msg import SloshingEstimate, SurfaceFit

FIT_QUEUE_DEPTH = 1000
"""Fits kept for the node (33 s at 30 fps): an estimate holds the interpreter for up to 0.4 s,
and a flooding replay sends fits faster than real time; none may be dropped meanwhile."""
PARAMETERS = {"estimate_period_s": 1.0, "estimate_window_s": 20.0, "wait_for_consumers": 0}
"""The node's parameters (config/params/sloshing.yaml documents them) and their defaults."""


class SloshingNode(HostedNode):
    """Accumulate each frame's modal amplitudes (from surface_fit) and, every
    `estimate_period_s` of recording time, estimate the lateral modes over the last
    `estimate_window_s` with every method; publish them on `sloshing`.

    A fit takes up to 0.4 s of CPU: the node runs in a process of its own, at a lower priority
    (`nice` in the graph file), so that it never holds up the measuring chain.
    """

    def __init__(self, node_name: str = "sloshing", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        values = self.declare_parameter_table(PARAMETERS)
        self._running = RunningAnalysis(float(values["estimate_period_s"]),
                                        window_s=float(values["estimate_window_s"]))
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="estimate")
        self._estimating: Future | None = None
        self._lock = threading.Lock()   # fits arrive while an estimate ends in the worker
        self._latest_header = None
        self._closing = False
        self._estimate_pub = self.create_publisher(SloshingEstimate, "sloshing", stream_qos())
        # No fit is taken before the estimates have their consumers (e.g. the recorder).
        start_when_consumed(self, [(self._estimate_pub, int(values["wait_for_consumers"]))],
                            self._subscribe)

    def _subscribe(self) -> None:
        self.create_subscription(SurfaceFit, "surface_fit", self._on_fit,
                                 stream_qos(FIT_QUEUE_DEPTH))

    def _on_fit(self, fit: SurfaceFit) -> None:
        if not fit.mode_names:
            return
        with self._lock:
            self._running.add(stamp_s(fit), tuple(fit.mode_names),
                              np.array(fit.modal_amplitudes_mm))
            self._latest_header = fit.header
        self._estimate_if_due()

    def _estimate_if_due(self) -> None:
        """Start an estimate on the series so far when one is due and none is running."""
        with self._lock:
            busy = self._estimating is not None and not self._estimating.done()
            if self._closing or busy or not self._running.due():
                return
            estimating = self._worker.submit(self._publish_estimates, self._latest_header,
                                             self._running.snapshot())
            self._estimating = estimating
        estimating.add_done_callback(self._after_estimate)

    def _after_estimate(self, future: Future) -> None:
        """Log a failed estimate; start the next one if fits came meanwhile (the last ones of
        a drop would otherwise wait for a fit that never comes)."""
        if not future.cancelled() and future.exception() is not None:
            self.get_logger().error(f"running sloshing estimate failed: {future.exception()!r}")
        self._estimate_if_due()

    def _publish_estimates(self, header, series: ModalSeries) -> None:
        """The lateral modes' estimates (in the worker thread, so that fits keep arriving)."""
        for mode in self._running.estimate(series):
            for estimate in mode.estimates:
                self._estimate_pub.publish(SloshingEstimate(
                    header=header, mode=mode.name, method=estimate.method,
                    frequency_hz=estimate.frequency_hz,
                    frequency_sigma_hz=estimate.frequency_sigma_hz,
                    damping_ratio=estimate.damping_ratio,
                    damping_ratio_sigma=estimate.damping_ratio_sigma,
                    window_start_s=estimate.window_start_s, window_end_s=estimate.window_end_s))

    def destroy_node(self) -> None:
        """Let a running estimate finish before the publisher goes."""
        with self._lock:
            self._closing = True
        self._worker.shutdown(wait=True, cancel_futures=True)
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(SloshingNode, "sloshing", False)], args))
