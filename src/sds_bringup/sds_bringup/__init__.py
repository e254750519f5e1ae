"""The launcher of the SDS graph: a graph file's processes, their environment, the chain.

`launcher` starts a graph file's processes (`sds_ros.graph_file` reads the file) and stops them
on a signal or a failure; `ros_env` is the one place for the graph's environment; `chain` runs
the measuring chain (drop.yaml, arduino.yaml, view.yaml) with a progress bar and a stand-in
Arduino for `sds demo` and `sds run`. What the commands do is in `sds_workflows`; the `sds`
command is `sds_cli`.
"""
