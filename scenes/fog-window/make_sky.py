#!/usr/bin/env python3
"""Writes sky.exr, the lat-long environment map of scenes/fog-window: a clear sky with a low sun.

Why a script: the map is data the repository ships, and a script of a few lines says exactly what
it holds and remakes it bit for bit, where a binary file from a paint program would say nothing.
Pure Python (no numpy, no OpenEXR bindings): the file is a plain single-part scanline OpenEXR,
half-float B, G, R channels, ZIP-compressed in blocks of 16 lines, as the format's specification
(openexr.com, "OpenEXR File Layout") describes; tessera's loader reads it through the `exr` crate.

The map, in tessera's orientation (scenes/README.md, "Environment maps": +y up, the top row
straight up, the centre column along +z, three quarters across along +x):
- the sky: a blue zenith fading to a pale horizon, radiance about 0.3 to 1;
- the ground below the horizon: a dull brown, 0.08;
- the sun: a disc of 5 degrees' radius around SUN (the direction towards it: low in the west,
  -x, slightly behind the room's back wall, +z), warm white at radiance 150. Its disc covers a
  few dozen texels, so importance sampling finds it and BSDF sampling can still hit it.

Usage (from the repository root): python3 scenes/fog-window/make_sky.py
"""

import math
import struct
import zlib
from pathlib import Path

WIDTH, HEIGHT = 128, 64
SUN = (-1.0, 0.8, 0.8)
SUN_RADIUS_DEGREES = 5.0
SUN_RADIANCE = (150.0, 140.0, 120.0)
LINES_PER_BLOCK = 16  # ZIP_COMPRESSION's block height


def radiance(direction):
    """The sky's RGB radiance along a unit direction (away from the scene)."""
    x, y, z = direction
    sun = normalise(SUN)
    if sum(a * b for a, b in zip(direction, sun)) >= math.cos(math.radians(SUN_RADIUS_DEGREES)):
        return SUN_RADIANCE
    if y < 0.0:
        return (0.08, 0.07, 0.05)
    # 0 at the horizon, 1 at the zenith.
    up = y ** 0.5
    horizon, zenith = (1.0, 0.95, 0.85), (0.25, 0.45, 0.9)
    return tuple(h + (t - h) * up for h, t in zip(horizon, zenith))


def direction(column, row):
    """The direction at a texel's centre, as tessera's `EnvironmentMap::direction` maps it."""
    u, v = (column + 0.5) / WIDTH, (row + 0.5) / HEIGHT
    theta, phi = math.pi * v, 2.0 * math.pi * (u - 0.5)
    return (math.sin(theta) * math.sin(phi), math.cos(theta), math.sin(theta) * math.cos(phi))


def normalise(v):
    length = math.sqrt(sum(c * c for c in v))
    return tuple(c / length for c in v)


def attribute(name, kind, value):
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def header():
    channels = b"".join(
        name.encode() + b"\0" + struct.pack("<iB3xii", 1, 0, 1, 1) for name in ("B", "G", "R")
    ) + b"\0"
    window = struct.pack("<iiii", 0, 0, WIDTH - 1, HEIGHT - 1)
    return (
        struct.pack("<ii", 20000630, 2)
        + attribute("channels", "chlist", channels)
        + attribute("compression", "compression", bytes([3]))
        + attribute("dataWindow", "box2i", window)
        + attribute("displayWindow", "box2i", window)
        + attribute("lineOrder", "lineOrder", bytes([0]))
        + attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0))
        + attribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0))
        + attribute("screenWindowWidth", "float", struct.pack("<f", 1.0))
        + b"\0"
    )


def zip_block(raw):
    """OpenEXR's ZIP: bytes split into even and odd halves, delta-coded, then zlib."""
    reordered = bytearray(raw[0::2] + raw[1::2])
    previous = reordered[0] if reordered else 0
    for i in range(1, len(reordered)):
        current = reordered[i]
        reordered[i] = (current - previous + 128 + 256) & 0xFF
        previous = current
    packed = zlib.compress(bytes(reordered), 9)
    # A block that does not shrink is stored as it is; readers tell by its size.
    return packed if len(packed) < len(raw) else raw


def main():
    texels = [[radiance(direction(c, r)) for c in range(WIDTH)] for r in range(HEIGHT)]
    blocks = []
    for first in range(0, HEIGHT, LINES_PER_BLOCK):
        raw = b""
        for row in texels[first : first + LINES_PER_BLOCK]:
            for channel in (2, 1, 0):  # B, G, R: the channels in name order
                raw += struct.pack(f"<{WIDTH}e", *(texel[channel] for texel in row))
        data = zip_block(raw)
        blocks.append(struct.pack("<ii", first, len(data)) + data)
    head = header()
    offsets, at = [], len(head) + 8 * len(blocks)
    for block in blocks:
        offsets.append(at)
        at += len(block)
    out = Path(__file__).with_name("sky.exr")
    out.write_bytes(head + struct.pack(f"<{len(offsets)}Q", *offsets) + b"".join(blocks))
    print(f"wrote {out} ({out.stat().st_size} bytes, {WIDTH}x{HEIGHT})")


if __name__ == "__main__":
    main()
