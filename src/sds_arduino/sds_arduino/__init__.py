"""The SDS Arduino: accelerometer, time-of-flight sensor and sync LED over a serial line.

`protocol` states the line protocol (version 1) and reads logs; `stream` turns bytes into
records; `clock` puts the device clock on the camera's (sync LED, or the acceleration both
feel); `messages` turns records into ROS messages; `replay` paces a log in device time;
`import_sd` writes an SD-card log as an MCAP; `bridge_node` is the serial bridge of the graph.
"""
