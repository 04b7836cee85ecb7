"""Cameras as the service serves them: which the scene has, at what size, with which outputs.

The scene's MJCF is the one source of the cameras (name, pose, field of view); the size of
each image and whether it carries colour, depth and segmentation are chosen when the service
starts (`--camera-size`, `--camera-outputs`, `--cameras`), because the batch renderer is
built for them once. Everything here is plain arithmetic on the compiled model, so the HTTP
listing, the ROS/Foxglove calibration and the tests agree on one intrinsic matrix.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass

import mujoco

from mjcf import SCENE_XML

OUTPUTS = ("rgb", "depth", "seg")
MAX_SIDE = 4096  # pixels, either side of one image
_SIZE = re.compile(r"^(\d+)x(\d+)$")


@dataclass(frozen=True)
class CameraSpec:
    """One camera as served: the model's camera at the chosen size with the chosen outputs.

    K follows the OpenCV/ROS convention (pixel centres at integer coordinates, v down):
    MuJoCo casts pixel (u, v)'s ray through ((u + 0.5) / width, (v + 0.5) / height) of an
    image plane whose height is 2 tan(fovy / 2), so both focal lengths are
    (height / 2) / tan(fovy / 2) and the principal point is ((width - 1) / 2, (height - 1) / 2).
    """

    name: str
    id: int  # MuJoCo camera id
    width: int
    height: int
    fovy: float  # vertical field of view [deg]
    rgb: bool
    depth: bool
    seg: bool

    @property
    def outputs(self) -> tuple[str, ...]:
        return tuple(o for o in OUTPUTS if getattr(self, o))

    @property
    def focal(self) -> float:
        """Focal length in pixels (fx = fy)."""
        return 0.5 * self.height / math.tan(math.radians(self.fovy) / 2)

    @property
    def K(self) -> list[float]:
        """The 3x3 intrinsic matrix, row-major (as ROS CameraInfo.k)."""
        f = self.focal
        return [f, 0.0, (self.width - 1) / 2, 0.0, f, (self.height - 1) / 2, 0.0, 0.0, 1.0]


def parse_size(text: str, field: str) -> tuple[int, int]:
    """'128x96' -> (128, 96); ValueError naming `field` and the limit otherwise."""
    m = _SIZE.match(text.strip())
    if not m:
        raise ValueError(f"{field}: {text!r} is not WIDTHxHEIGHT, e.g. 128x96")
    w, h = int(m.group(1)), int(m.group(2))
    if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE):
        raise ValueError(f"{field}: {text!r}: each side must be 1..{MAX_SIDE} pixels")
    return w, h


def parse_outputs(text: str, field: str, sep: str = ",") -> frozenset[str]:
    """'rgb,depth' -> {'rgb', 'depth'}; at least one of OUTPUTS, nothing else."""
    parts = [p.strip() for p in text.split(sep) if p.strip()]
    bad = [p for p in parts if p not in OUTPUTS]
    if bad or not parts:
        raise ValueError(f"{field}: {text!r}: choose one or more of {', '.join(OUTPUTS)}")
    return frozenset(parts)


def parse_overrides(text: str, field: str = "cameras") -> dict[str, tuple | None]:
    """'wrist=320x240:rgb+depth,overview=off' -> {name: ((w, h) | None, outputs | None) | None}.

    None for a camera turned off; a part left out keeps the default.
    """
    out: dict[str, tuple | None] = {}
    for item in (p.strip() for p in text.split(",")):
        if not item:
            continue
        name, eq, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not eq or not name or not value:
            raise ValueError(f"{field}: {item!r} is not NAME=WxH[:OUTPUTS] or NAME=off")
        if name in out:
            raise ValueError(f"{field}: camera {name!r} given twice")
        if value == "off":
            out[name] = None
            continue
        size_text, _, outputs_text = value.partition(":")
        size = parse_size(size_text, f"{field}.{name}") if size_text else None
        outputs = parse_outputs(outputs_text, f"{field}.{name}", "+") if outputs_text else None
        out[name] = (size, outputs)
    return out


def model_cameras(mjm: mujoco.MjModel) -> list[str]:
    """The model's camera names in id order."""
    return [
        mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_CAMERA, i) or f"camera{i}"
        for i in range(mjm.ncam)
    ]


@functools.cache
def scene_cameras() -> tuple[str, ...]:
    """The default scene's cameras (what settings are checked against at start)."""
    return tuple(model_cameras(mujoco.MjModel.from_xml_path(str(SCENE_XML))))


def camera_specs(
    mjm: mujoco.MjModel, size: str, outputs: str, overrides: str = ""
) -> list[CameraSpec]:
    """The served cameras of `mjm` from the settings' three strings; ValueError naming the
    setting when one is malformed or names a camera the model does not have."""
    default_size = parse_size(size, "camera_size")
    default_outputs = parse_outputs(outputs, "camera_outputs")
    changes = parse_overrides(overrides)
    names = model_cameras(mjm)
    unknown = sorted(set(changes) - set(names))
    if unknown:
        have = ", ".join(names) or "none"
        raise ValueError(f"cameras: the scene has no camera {unknown[0]!r} (it has: {have})")
    specs = []
    for cid, name in enumerate(names):
        if name in changes and changes[name] is None:
            continue
        got_size, got_outputs = changes.get(name) or (None, None)
        w, h = got_size or default_size
        outs = got_outputs or default_outputs
        if mjm.cam_projection[cid] != mujoco.mjtProjection.mjPROJ_PERSPECTIVE:
            continue  # orthographic cameras have no pinhole K: not served
        if mjm.cam_sensorsize[cid][1] != 0:
            continue  # sensor size + focal length cameras: K is not fovy's (not served yet)
        specs.append(
            CameraSpec(
                name=name,
                id=cid,
                width=w,
                height=h,
                fovy=float(mjm.cam_fovy[cid]),
                rgb="rgb" in outs,
                depth="depth" in outs,
                seg="seg" in outs,
            )
        )
    return specs
