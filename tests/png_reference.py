"""A PNG decoder written from the specification, to check clrt's own PNG writer
(clrt/output/png.py) without reading its output the way it was written: any
row filter, 8 or 16 bits a sample, every chunk's CRC checked."""

import struct
import zlib

import numpy as np


def spec_decode(data: bytes) -> np.ndarray:
    """The pixels of a PNG file, as the specification (W3C, PNG 2nd edition,
    sections 7-9) decodes them: chunks, IHDR, the concatenated IDAT zlib stream,
    and the five row filters undone -- not clrt's writer read backwards."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    at, idat = 8, b""
    while at < len(data):
        length, kind = struct.unpack(">I4s", data[at:at + 8])
        body = data[at + 8:at + 8 + length]
        assert struct.unpack(">I", data[at + 8 + length:at + 12 + length])[0] == zlib.crc32(kind + body)
        if kind == b"IHDR":
            width, height, bits, color_type = struct.unpack(">IIBB", body[:10])
        elif kind == b"IDAT":
            idat += body
        at += 12 + length
    channels = {0: 1, 4: 2, 2: 3, 6: 4}[color_type]
    step, stride = channels * bits // 8, width * channels * bits // 8
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(height, stride + 1).astype(np.int64)
    rows, above = np.zeros((height, stride), np.int64), np.zeros(stride, np.int64)
    for r in range(height):
        kind, line = raw[r, 0], raw[r, 1:]
        row = np.zeros(stride, np.int64)
        for i in range(stride):
            a, b = (row[i - step] if i >= step else 0), above[i]
            c = above[i - step] if i >= step else 0
            p = a + b - c
            paeth = a if abs(p - a) <= abs(p - b) and abs(p - a) <= abs(p - c) else b if abs(p - b) <= abs(p - c) else c
            row[i] = (line[i] + (0, a, b, (a + b) // 2, paeth)[kind]) & 0xFF
        rows[r], above = row, row
    pixels = rows.astype(np.uint8).view(">u2" if bits == 16 else np.uint8).astype(np.uint16 if bits == 16 else np.uint8)
    return pixels.reshape((height, width, channels) if channels > 1 else (height, width))
