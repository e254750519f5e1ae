"""Rerun views of SDS data.

`scene` says what is shown where (entity paths, units); `messages` turns the graph's messages
into the scene; `viewer_node` shows a running graph (live or saved); `from_mcap` turns a
recording into a `.rrd` file (`sds view`, and the demo's Rerun file).
"""
