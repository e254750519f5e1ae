"""Rerun views of SDS data.

`scene` says what is shown where (entity paths, units); `messages` turns the graph's messages
into the scene; `from_mcap` turns a recording into a `.rrd` file (`sds view`, and the demo's
Rerun file). The viewer node, which shows a running graph, is `sds_nodes.viewer`.
"""
