"""MJCF model files of the armfleet work cell (UR10e + Robotiq 2F-140, table, cube).

This directory is a Python package only so that the model files can be found the same way
from a source checkout and from an installed wheel: setuptools ships the ``*.xml`` files as
package data next to this module, and code locates them through ``MJCF_DIR`` instead of a
path relative to the current directory or the repository root.
"""

from pathlib import Path

MJCF_DIR = Path(__file__).parent
SCENE_XML = MJCF_DIR / "scene.xml"
ROBOT_XML = MJCF_DIR / "ur10e_2f140.xml"

__all__ = ["MJCF_DIR", "ROBOT_XML", "SCENE_XML"]
