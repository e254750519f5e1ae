"""The SDS Arduino: accelerometer, time-of-flight sensor and sync LED over a serial line.

`protocol` states the line protocol (version 1) and reads logs; `stream` turns bytes into
records; `clock` puts the device clock on the camera's (sync LED, or the acceleration both
feel); `replay` paces a log in device time. Pure Python: the records become ROS messages in
`sds_ros.arduino_msg`, the graph's serial bridge is `sds_nodes.arduino_bridge` and `sds import-sd`
is `sds_record.import_sd`.
"""
