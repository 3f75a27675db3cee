"""A confusion matrix drawn as a PNG with NumPy and zlib only (no matplotlib, no Pillow).

A 3 x 5 pixel font (lower-case letters, digits, ``.``, ``%``, ``-``) scaled up, cells
shaded by the row-normalised count, like the paper's table "Confusion Matrix".
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

__all__ = ["confusion_png", "write_png"]

# Each glyph: 5 rows of 3 bits (most significant bit = left column).
_FONT = {
    "a": (2, 5, 7, 5, 5), "b": (6, 5, 6, 5, 6), "c": (3, 4, 4, 4, 3), "d": (6, 5, 5, 5, 6),
    "e": (7, 4, 6, 4, 7), "f": (7, 4, 6, 4, 4), "g": (3, 4, 5, 5, 3), "h": (5, 5, 7, 5, 5),
    "i": (7, 2, 2, 2, 7), "j": (1, 1, 1, 5, 2), "k": (5, 5, 6, 5, 5), "l": (4, 4, 4, 4, 7),
    "m": (5, 7, 7, 5, 5), "n": (6, 5, 5, 5, 5), "o": (2, 5, 5, 5, 2), "p": (6, 5, 6, 4, 4),
    "q": (2, 5, 5, 6, 3), "r": (6, 5, 6, 5, 5), "s": (3, 4, 2, 1, 6), "t": (7, 2, 2, 2, 2),
    "u": (5, 5, 5, 5, 7), "v": (5, 5, 5, 5, 2), "w": (5, 5, 7, 7, 5), "x": (5, 5, 2, 5, 5),
    "y": (5, 5, 2, 2, 2), "z": (7, 1, 2, 4, 7), "0": (7, 5, 5, 5, 7), "1": (2, 6, 2, 2, 7),
    "2": (6, 1, 2, 4, 7), "3": (6, 1, 2, 1, 6), "4": (5, 5, 7, 1, 1), "5": (7, 4, 6, 1, 6),
    "6": (3, 4, 7, 5, 7), "7": (7, 1, 2, 2, 2), "8": (7, 5, 7, 5, 7), "9": (7, 5, 7, 1, 6),
    ".": (0, 0, 0, 0, 2), "%": (5, 1, 2, 4, 5), "-": (0, 0, 7, 0, 0), " ": (0, 0, 0, 0, 0),
}


def write_png(path: str | Path, rgb: npt.NDArray[np.uint8]) -> None:
    """Write an ``(h, w, 3)`` uint8 image as an 8-bit RGB PNG.

    Examples
    --------
    >>> import tempfile, os
    >>> p = os.path.join(tempfile.mkdtemp(), "x.png")
    >>> write_png(p, np.zeros((2, 3, 3), dtype=np.uint8))
    >>> open(p, "rb").read()[:8]
    b'\\x89PNG\\r\\n\\x1a\\n'
    """
    img = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w, _ = img.shape
    raw = np.concatenate([np.zeros((h, 1), np.uint8), img.reshape(h, w * 3)], axis=1).tobytes()

    def chunk(tag: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)

    data = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
    Path(path).write_bytes(data)


def _text(img: npt.NDArray[np.uint8], s: str, x: int, y: int, scale: int, colour: tuple[int, int, int]) -> None:
    for n, ch in enumerate(s.lower()):
        rows = _FONT.get(ch, _FONT[" "])
        for r, bits in enumerate(rows):
            for c in range(3):
                if bits >> (2 - c) & 1:
                    y0, x0 = y + r * scale, x + (n * 4 + c) * scale
                    img[y0:y0 + scale, x0:x0 + scale] = colour


def confusion_png(path: str | Path, matrix: npt.NDArray[np.integer], names: Sequence[str]) -> None:
    """Draw ``matrix`` (rows: true class, columns: predicted) with class ``names`` to ``path``."""
    m = np.asarray(matrix, dtype=np.int64)
    k = len(names)
    s, cell = 2, 44
    label_w = (max(len(n) for n in names) * 4 + 2) * s
    top = 8 * s + 4 + max(len(n) for n in names) * 6 * s + 4
    img = np.full((top + k * cell + 4, label_w + 8 + k * cell + 4, 3), 255, dtype=np.uint8)
    _text(img, "true - predicted", label_w + 8, 2, s, (0, 0, 0))
    frac = m / np.maximum(m.sum(axis=1, keepdims=True), 1)
    for i, name in enumerate(names):
        _text(img, name, 2, top + i * cell + cell // 2 - 5, s, (0, 0, 0))
        # column labels written vertically, one letter under the other
        for n, ch in enumerate(name):
            _text(img, ch, label_w + 8 + i * cell + cell // 2 - 3, 8 * s + 4 + n * 6 * s, s, (0, 0, 0))
        for j in range(k):
            y0, x0 = top + i * cell, label_w + 8 + j * cell
            v = float(frac[i, j])
            base = np.array([40, 110, 200]) if i == j else np.array([210, 60, 40])
            colour = (255 - v * (255 - base)).astype(np.uint8)
            img[y0 + 1:y0 + cell - 1, x0 + 1:x0 + cell - 1] = colour
            txt = str(int(m[i, j]))
            ink = (255, 255, 255) if v > 0.5 else (0, 0, 0)
            _text(img, txt, x0 + (cell - len(txt) * 4 * s) // 2, y0 + cell // 2 - 5, s, ink)
    write_png(path, img)
