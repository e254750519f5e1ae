"""The ROS layer: what every SDS node stands on, and nothing the algorithms need.

`hosted_node` is the base class of every node (done, exit status, close); `node_host` runs one
or more nodes in a process until a required one finishes or a signal arrives (`node_process`
is the program the launcher starts); `executor` the executor each process spins; `qos` holds
the measuring chain's QoS and the start-up wait for consumers; `real_time` the pace of a file
or recording played in real time; the message codecs: `point_cloud` (the surface cloud
on `/recon/points` and `/recon/line_points`, metres, REP-103, and its reader), `image_msg`
(numpy ↔ sensor_msgs/Image), `imu_msg` (IMU samples → sensor_msgs/Imu), `arduino_msg`
(Arduino records → Imu, Range, SyncEvent). Algorithm packages
import nothing from here; nodes and tools do.
"""
