"""The graph's nodes: thin rclpy wrappers that turn messages into calls of the algorithm packages.

`frame_source` (video, camera or image folder → images, camera model, sync events, the camera's
IMU) and `frame_monitor` (rates and gaps); `tracker` (images → spots and line profile,
`sds_tracker`); `reconstruction` (spots → surface points and fits, `sds_recon.reconstruction`);
`sloshing` (running frequency and damping estimates); `recorder` and `player` (MCAP,
`sds_record`); `arduino_bridge` (the Arduino's serial line, `sds_arduino`); `viewer` (Rerun,
`sds_viz`). Each derives from `sds_ros.hosted_node.HostedNode` and is started by the node host
(`plugin: sds_nodes.<module>:<Class>` in a graph file); nothing below imports from here.
"""
