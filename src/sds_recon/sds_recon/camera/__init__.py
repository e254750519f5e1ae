"""Camera models: the interface, pinhole + Brown-Conrady, Scaramuzza, file I/O and importers."""

from sds_recon.camera.model import (
    CameraModel,
    CameraModelError,
    camera_from_dict,
    load_camera,
    save_camera,
)
from sds_recon.camera.pinhole import PinholeCamera
from sds_recon.camera.scaramuzza import ScaramuzzaCamera

__all__ = ["CameraModel", "CameraModelError", "PinholeCamera", "ScaramuzzaCamera",
           "camera_from_dict", "load_camera", "save_camera"]
