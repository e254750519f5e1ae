"""Frame sources of the SDS graph: video files, live cameras and image folders."""
