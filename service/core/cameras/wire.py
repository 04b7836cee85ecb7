"""Camera images on the wire: one image as PNG, JPEG or raw bytes, and many in one message.

One image (GET /v1/worlds/{w}/cameras/{name}):
- rgb: PNG (8-bit RGB), JPEG, or raw (height x width x 3 uint8, rows top to bottom)
- depth: PNG (16-bit grey, millimetres along the optical axis, 0 = nothing hit, clipped at
  65535), or raw (float32 little-endian metres, 0 = nothing hit): ROS's 16UC1 and 32FC1
- seg: PNG (16-bit grey, geom id + 1, 0 = background), or raw (int32 little-endian geom id,
  -1 = background)

Many (GET /v1/cameras/{name}/images, the camera WebSocket): one binary message,

    IMAGE_MAGIC | u32 header length (little-endian) | header (JSON, UTF-8) | image 0 | ...

(the magic and the reader, `unpack_images`, in clients/wire.py),

the header saying `tick`, `camera`, `image`, `format`, `content_type`, `width`, `height`,
`worlds` and each image's `sizes` in bytes, in the order of `worlds`.
"""

from __future__ import annotations

import io

import numpy as np
import orjson
from PIL import Image

from clients.wire import HEADER_LENGTH, IMAGE_MAGIC
from service.core.cameras.feed import Shot
from service.core.errors import BadCommand

IMAGES = ("rgb", "depth", "seg")
FORMATS = {"rgb": ("png", "jpeg", "raw"), "depth": ("png", "raw"), "seg": ("png", "raw")}
CONTENT_TYPES = {"png": "image/png", "jpeg": "image/jpeg", "raw": "application/octet-stream"}
MULTI_TYPE = "application/x-armfleet-images"


def choose(image: str, fmt: str | None, accept: str | None) -> str:
    """The format for `image`: `fmt` when given, else the first of Accept's types that fits,
    else PNG. JPEG cannot hold depth (16-bit) or segment ids exactly, so asked for them it is
    PNG (the reply's Content-Type says so): every pair the query schema allows is served."""
    if image not in FORMATS:
        raise BadCommand("query.image", f"{image!r}: choose one of {', '.join(IMAGES)}")
    served = FORMATS[image]
    if fmt is None:
        for part in (accept or "").split(","):
            kind = part.split(";")[0].strip().lower()
            found = [f for f in served if CONTENT_TYPES[f] == kind]
            if found:
                return found[0]
        return "png"
    if fmt == "jpeg" and image != "rgb":
        return "png"
    if fmt not in served:
        raise BadCommand("query.format", f"{fmt!r}: {image} images come as {', '.join(served)}")
    return fmt


def encode(pixels: np.ndarray, image: str, fmt: str, quality: int = 90) -> bytes:
    """One image (h, w[, 3]) of kind `image` in format `fmt` (see the module docstring)."""
    if fmt == "raw":
        dtype = {"rgb": np.uint8, "depth": "<f4", "seg": "<i4"}[image]
        return np.ascontiguousarray(pixels, dtype=dtype).tobytes()
    if image == "depth":
        mm = np.clip(np.rint(pixels.astype(np.float64) * 1000.0), 0, 65535).astype(np.uint16)
        pic = Image.fromarray(mm)
    elif image == "seg":
        pic = Image.fromarray(np.clip(pixels.astype(np.int64) + 1, 0, 65535).astype(np.uint16))
    else:
        pic = Image.fromarray(np.ascontiguousarray(pixels, dtype=np.uint8), "RGB")
    buf = io.BytesIO()
    if fmt == "jpeg":
        pic.save(buf, "JPEG", quality=quality)
    else:
        pic.save(buf, "PNG", compress_level=1)  # fast: the images are small, the CPU is not
    return buf.getvalue()


def pack(shot: Shot, image: str, fmt: str, quality: int = 90) -> bytes:
    """Every world of `shot` in one binary message (layout in the module docstring)."""
    return b"".join(pack_parts(shot, image, fmt, quality))


def pack_parts(shot: Shot, image: str, fmt: str, quality: int = 90) -> list[bytes | memoryview]:
    """The message of `pack` as parts to be written one after the other: the magic, length and
    header, then the images. Raw images are one part, a view of the drawn array's bytes as
    they lie: 16,384 64x64 RGB images are 201 MB, and a socket that writes the parts as a
    gather list (service/api/ws_bulk.py) sends them with no copy at all; PNG and JPEG are
    encoded one image at a time, then joined (they are small)."""
    arr = shot.image(image)
    if fmt == "raw":
        dtype = {"rgb": np.uint8, "depth": "<f4", "seg": "<i4"}[image]
        per = int(np.prod(arr.shape[1:]))
        flat = np.ascontiguousarray(arr, dtype=dtype).reshape(len(shot.worlds), per)
        body: bytes | memoryview = memoryview(flat).cast("B")
        sizes = [flat.shape[1] * flat.itemsize] * len(shot.worlds)
    else:
        encoded = [encode(arr[i], image, fmt, quality) for i in range(len(shot.worlds))]
        body, sizes = b"".join(encoded), [len(p) for p in encoded]
    header = {
        "tick": shot.tick,
        "camera": shot.camera.name,
        "image": image,
        "format": fmt,
        "content_type": CONTENT_TYPES[fmt],
        "width": shot.camera.width,
        "height": shot.camera.height,
        "worlds": np.asarray(shot.worlds, dtype=np.int64).tolist(),
        "sizes": sizes,
    }
    head = orjson.dumps(header)
    return [IMAGE_MAGIC + HEADER_LENGTH.pack(len(head)) + head, body]
