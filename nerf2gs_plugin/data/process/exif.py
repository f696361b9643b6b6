"""The focal length from a JPEG's EXIF, without PIL (the project reads images with OpenCV only,
and OpenCV does not expose EXIF).

Only what is needed: ``FocalLengthIn35mmFilm`` (0xA405), else ``FocalLength`` (0x920A) with
``FocalPlaneXResolution`` / ``FocalPlaneResolutionUnit`` (0xA20E / 0xA210). Anything unreadable
gives ``None`` (the SfM then guesses the focal and refines it).
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Optional

_EXIF_IFD = 0x8769
_F35 = 0xA405
_FOCAL = 0x920A
_FP_XRES = 0xA20E
_FP_UNIT = 0xA210
_TYPE_SIZE = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 7: 1, 9: 4, 10: 8}


def _app1_tiff(data: bytes) -> Optional[bytes]:
    """The TIFF block of the first ``Exif`` APP1 segment of a JPEG."""
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 4 <= len(data) and data[i] == 0xFF:
        marker, length = data[i + 1], struct.unpack(">H", data[i + 2:i + 4])[0]
        if marker == 0xE1 and data[i + 4:i + 10] == b"Exif\x00\x00":
            return data[i + 10:i + 2 + length]
        if marker in (0xDA, 0xD9):  # start of scan / end: no more metadata
            return None
        i += 2 + length
    return None


def _ifd(tiff: bytes, offset: int, endian: str) -> dict[int, object]:
    """Tags of one IFD: SHORT/LONG as int, RATIONAL as float (first value only)."""
    out: dict[int, object] = {}
    if offset + 2 > len(tiff):
        return out
    (n,) = struct.unpack(endian + "H", tiff[offset:offset + 2])
    for k in range(n):
        e = offset + 2 + 12 * k
        if e + 12 > len(tiff):
            break
        tag, typ, count = struct.unpack(endian + "HHI", tiff[e:e + 8])
        size = _TYPE_SIZE.get(typ, 1) * count
        raw = tiff[e + 8:e + 12] if size <= 4 else tiff[struct.unpack(endian + "I", tiff[e + 8:e + 12])[0]:][:size]
        try:
            if typ == 3:
                out[tag] = struct.unpack(endian + "H", raw[:2])[0]
            elif typ in (4, 9):
                out[tag] = struct.unpack(endian + ("I" if typ == 4 else "i"), raw[:4])[0]
            elif typ in (5, 10):
                num, den = struct.unpack(endian + ("II" if typ == 5 else "ii"), raw[:8])
                out[tag] = num / den if den else 0.0
        except struct.error:
            continue
    return out


def exif_focal_px(path: Path, width: int, height: int) -> Optional[float]:
    """Focal length in pixels for an image of ``width x height`` (its stored size), or ``None``."""
    try:
        with open(path, "rb") as f:
            data = f.read(1 << 17)
        tiff = _app1_tiff(data)
        if tiff is None or len(tiff) < 8:
            return None
        endian = {b"II": "<", b"MM": ">"}.get(tiff[:2])
        if endian is None:
            return None
        ifd0 = _ifd(tiff, struct.unpack(endian + "I", tiff[4:8])[0], endian)
        exif = _ifd(tiff, int(ifd0[_EXIF_IFD]), endian) if _EXIF_IFD in ifd0 else {}
    except (OSError, struct.error, ValueError, KeyError):
        return None
    f35 = exif.get(_F35)
    if isinstance(f35, int) and f35 > 0:
        return float(f35) / 36.0 * max(width, height)
    focal, xres, unit = exif.get(_FOCAL), exif.get(_FP_XRES), exif.get(_FP_UNIT, 2)
    mm_per_unit = {2: 25.4, 3: 10.0, 4: 1.0}.get(int(unit) if isinstance(unit, int) else 2)
    if isinstance(focal, float) and focal > 0 and isinstance(xres, float) and xres > 0 and mm_per_unit:
        # FocalPlaneXResolution is pixels per unit at the sensor's full width; scale to this image
        # assuming the stored image spans that width.
        return focal * xres / mm_per_unit
    return None
