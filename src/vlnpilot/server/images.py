"""The server's image input: one definition for what the schema promises and what the decoder accepts.

`IMAGE_PATTERN` is strict base64 (padded or not, standard or URL-safe alphabet) of a JPEG (/9j/, _9j_) or a PNG
(iVBORw0KGgo), optionally a data: URL; `IMAGE_MIN_LENGTH` is the base64 length of the smallest image the decoder
accepts. The OpenAPI schema states both, and `decode_image` checks both first, so a string the schema refuses
is refused by the decoder with the same words, and vice versa up to what no schema can say (a truncated JPEG).

Memory is spent last: the format and the size come from the header (Pillow reads it without decoding the pixels),
the pixel count is bounded before any decoding, at most `MAX_CONCURRENT_DECODES` images are decoded at once, and
the server holds at most `PIXELS_IN_FLIGHT` decoded pixels over all the requests it is answering (`PixelBudget`).
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import io
import re
import threading
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

MAX_IMAGE_SIDE = 4096
MAX_IMAGE_PIXELS = 4096 * 2160  # a 4K frame (the Tello's is 960x720): at most 27 MB once decoded to RGB
MAX_CONCURRENT_DECODES = 2  # the machine's cores; the other requests wait here, holding only their base64 text
PIXELS_IN_FLIGHT = 3 * MAX_IMAGE_PIXELS  # decoded and not yet answered: 80 MB of RGB, or 38 of the Tello's frames

_B64 = "[A-Za-z0-9+/_-]"
_TAIL = f"(?:{_B64}{{2}}(?:==)?|{_B64}{{3}}=?)?"  # the last 2 or 3 characters, padded or not
# The prefixes are 4 and 11 characters long, so a PNG's first group of four ends one character after it.
IMAGE_PATTERN = (rf"^(?:data:image/(?:jpeg|png);base64,)?"
                 rf"(?:(?:/9j/|_9j_)(?:{_B64}{{4}})*|iVBORw0KGgo{_B64}(?:{_B64}{{4}})*){_TAIL}$")
_IMAGE_RE = re.compile(IMAGE_PATTERN)
_DECODES = threading.BoundedSemaphore(MAX_CONCURRENT_DECODES)
_OBJECT_REPR = re.compile(r"<[\w.]+ object at 0x[0-9a-fA-F]+>")


class BadImage(ValueError):
    """The image field cannot be used; the message says why (no object reprs, no internals)."""


def _smallest_image_length() -> int:
    from PIL import Image

    buf = io.BytesIO()
    Image.new("L", (1, 1)).save(buf, format="PNG", optimize=True)
    return len(base64.b64encode(buf.getvalue()).rstrip(b"="))


IMAGE_MIN_LENGTH = _smallest_image_length()  # anything shorter cannot be a decodable JPEG or PNG


def image_bytes(data: str) -> tuple[bytes, str]:
    """The raw bytes of an image field and its claimed format ('JPEG' or 'PNG'); BadImage otherwise."""
    if len(data) < IMAGE_MIN_LENGTH:
        raise BadImage(f"image is {len(data)} characters; the smallest JPEG or PNG is {IMAGE_MIN_LENGTH} in base64")
    if not _IMAGE_RE.match(data):
        raise BadImage("image must be base64 (no spaces) of a JPEG (/9j/...) or a PNG (iVBORw0KGgo...), "
                       "optionally as data:image/jpeg;base64,...")
    text = data.partition(",")[2] if data.startswith("data:") else data
    text = text.rstrip("=").replace("-", "+").replace("_", "/")
    try:
        raw = base64.b64decode(text + "=" * (-len(text) % 4), validate=True)
    except (binascii.Error, ValueError):
        raise BadImage("image is not valid base64") from None
    if raw[:3] == b"\xff\xd8\xff":
        return raw, "JPEG"
    if raw[:8] == b"\x89PNG\r\n\x1a\n":
        return raw, "PNG"
    raise BadImage("image must be a base64 JPEG or PNG")


@dataclass(frozen=True)
class ImageHeader:
    """What the header says: read, checked and bounded before a single pixel is decoded."""

    raw: bytes
    kind: str  # 'JPEG' or 'PNG'
    width: int
    height: int

    @property
    def pixels(self) -> int:
        return self.width * self.height


def read_header(data: str) -> ImageHeader:
    """An image field's format and size, from its header; BadImage when it is not a JPEG or PNG within the limits."""
    from PIL import Image

    raw, kind = image_bytes(data)
    with _readable(kind), Image.open(io.BytesIO(raw)) as img:  # reads the header only
        if img.format != kind:
            raise BadImage(f"image claims {kind} but decodes as {img.format}")
        check_size(img.width, img.height)
        return ImageHeader(raw, kind, img.width, img.height)


def decode(header: ImageHeader) -> np.ndarray:
    """The pixels of a checked header as an HxWx3 uint8 RGB array (at most MAX_CONCURRENT_DECODES at once)."""
    from PIL import Image

    with _readable(header.kind), _DECODES, Image.open(io.BytesIO(header.raw)) as img:
        img.load()
        rgb = img if img.mode == "RGB" else img.convert("RGB")
        return np.asarray(rgb, dtype=np.uint8)


def decode_image(data: str) -> np.ndarray:
    """An image field as an HxWx3 uint8 RGB array, bounded before it is decoded; BadImage otherwise."""
    return decode(read_header(data))


@contextlib.contextmanager
def _readable(kind: str) -> Iterator[None]:
    """Pillow's failures as BadImage, in words (no '<_io.BytesIO object at 0x...>')."""
    from PIL import Image, UnidentifiedImageError

    try:
        yield
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError, Image.DecompressionBombError) as exc:
        if isinstance(exc, BadImage):
            raise
        why = _OBJECT_REPR.sub("the image", str(exc)) or type(exc).__name__
        raise BadImage(f"image cannot be decoded as {kind}: {why}") from None


class PixelBudget:
    """The decoded pixels alive at once, over all requests: a request takes its image's share before decoding it
    and gives it back when its answer is sent, so that N slow pilot calls cannot each hold a large image."""

    def __init__(self, limit: int = PIXELS_IN_FLIGHT):
        if limit < MAX_IMAGE_PIXELS:
            raise ValueError(f"a pixel budget of {limit} could never admit a {MAX_IMAGE_PIXELS}-pixel image")
        self.limit, self.used = limit, 0
        self._free = threading.Condition()

    @contextlib.contextmanager
    def hold(self, pixels: int) -> Iterator[None]:
        with self._free:
            self._free.wait_for(lambda: self.used + pixels <= self.limit)
            self.used += pixels
        try:
            yield
        finally:
            with self._free:
                self.used -= pixels
                self._free.notify_all()


def check_size(width: int, height: int) -> None:
    if max(width, height) > MAX_IMAGE_SIDE or min(width, height) < 1:
        raise BadImage(f"image is {width}x{height}; each side must be 1..{MAX_IMAGE_SIDE}")
    if width * height > MAX_IMAGE_PIXELS:
        raise BadImage(f"image is {width}x{height} = {width * height} pixels; the limit is {MAX_IMAGE_PIXELS} "
                       f"(e.g. 4096x2160); send the camera frame, or scale it down")
