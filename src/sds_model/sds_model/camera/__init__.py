"""Camera models (seed Sec. 3.1).

`model` is the one interface every model implements (pixel ↔ ray, image size, parameters);
`pinhole` (Brown-Conrady distortion) and `scaramuzza` (the omnidirectional model of the GoPro)
implement it; `files` holds the registry of models by name and reads and writes camera files;
`importers` turns OpenCV, OCamCalib, MATLAB and ROS CameraInfo results into camera files.
"""

from sds_model.camera.files import camera_from_dict, load_camera, save_camera
from sds_model.camera.model import CameraModel, CameraModelError
from sds_model.camera.pinhole import PinholeCamera
from sds_model.camera.scaramuzza import ScaramuzzaCamera

__all__ = ["CameraModel", "CameraModelError", "PinholeCamera", "ScaramuzzaCamera",
           "camera_from_dict", "load_camera", "save_camera"]
