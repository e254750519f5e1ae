"""Recordings: MCAP files of the graph's messages.

`mcap_files` holds the crash-safe writer, the one reader (unfinished files too) and repair;
`schemas` the message definitions embedded in the files; `recorded_series` what the tools
read from a recording (its rig, the surface points, the accelerometers); `recorder_node` and
`player_node` record a running graph and play a recording back into one.
"""
