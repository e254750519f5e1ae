"""The top of SDS: the launcher, the `sds` command and the jobs its commands run.

`launcher` starts a graph file's processes (`graph` reads the file) and stops them on a signal
or a failure; `ros_env` is the one place for the graph's environment; `cli` and `commands/`
(one module per subcommand) are the `sds` command; `demo` runs the whole chain (`sds demo`,
`sds run`); `offline` (`sds process`, `sds export`), `rig_calibration`, `line_plane_calibration`,
`calibration_trial`, `clock_link`, `camera_imu_mcap` and `analyze` hold what the commands do.
"""
