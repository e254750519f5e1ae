"""Frames into the SDS graph: video files, live cameras and image folders.

`frame_source` (pure: OpenCV, numpy) opens a source, selects the container's region and the
laser's colour channel, and reads ahead; `camera_imu` reads the camera's own IMU (GoPro GPMF or a
sidecar CSV); `led` finds the sync LED's switches; `video_writer` writes videos (simulator,
tests). No ROS: the graph's frame source and frame monitor are in `sds_nodes`.
"""
