"""Recordings: MCAP files of the graph's messages.

`mcap_files` holds the crash-safe writer, the one reader (unfinished files too) and repair;
`schemas` the message definitions embedded in the files; `recorded_series` what the tools
read from a recording (its rig, the surface points, the accelerometers); `import_sd` an
Arduino SD-card log as a recording. The recorder and player nodes are in `sds_nodes` (the
recorder writes the rig's `/tf_static`, `sds_ros.static_tf`).
"""
