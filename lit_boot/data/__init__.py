"""Data on top of the core: file I/O (Middlebury .flo, flow sets, scene folders) and pictures."""

from .flo import FLO_MAGIC, FloFormatError, read_flo, write_flo
from .flows import FlowSourceError, read_flows, write_flows, write_flows_npz
from .scene_io import SCENE_FORMAT, SCENE_FORMAT_VERSION, SceneFormatError, load_scene, save_scene
from .visualize import draw_skeleton, flow_image, read_png, scene_preview, write_png

__all__ = [
    "FLO_MAGIC",
    "FloFormatError",
    "read_flo",
    "write_flo",
    "FlowSourceError",
    "read_flows",
    "write_flows",
    "write_flows_npz",
    "SCENE_FORMAT",
    "SCENE_FORMAT_VERSION",
    "SceneFormatError",
    "load_scene",
    "save_scene",
    "draw_skeleton",
    "flow_image",
    "read_png",
    "scene_preview",
    "write_png",
]
