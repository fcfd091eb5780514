#!/usr/bin/env python3
"""Writes a scene of many moving objects, for measuring how the tracer scales with their number.

A Cornell room (metres, as scenes/cornell-blur) holding COUNT small balls on a grid of columns
and layers, each falling 0.3 m during frame 0 with a shutter open the whole frame: every ball
is motion-blurred, and a ray meets few of them. docs/bench.md ("moving objects by the
hundred") times `tessera bench` on it at several counts.

Usage: scripts/moving_crowd.py COUNT OUT.toml
"""

import math
import sys

ROOM = """# Written by scripts/moving_crowd.py: {count} falling balls in a Cornell room.
[render]
width = 256
height = 256
spp = 16
max_depth = 8
frames = 1

[camera]
position = [2.78, 2.73, -8]
look_at = [2.78, 2.73, 0]
vfov = 39.3077
shutter = [0, 1]

[materials.white]
type = "diffuse"
albedo = 0.73

[materials.red]
type = "diffuse"
albedo = [0.63, 0.065, 0.05]

[materials.green]
type = "diffuse"
albedo = [0.14, 0.45, 0.091]

[materials.lamp]
type = "emissive"
emission = [15, 12, 8]

"""

# The room's walls, floor and ceiling, every face towards the inside, and the lamp just below
# the ceiling: (corners, material), as scenes/cornell-blur places them.
QUADS = [
    ("[[0, 0, 0], [0, 0, 5.59], [5.56, 0, 5.59], [5.56, 0, 0]]", "white"),
    ("[[0, 5.49, 0], [5.56, 5.49, 0], [5.56, 5.49, 5.59], [0, 5.49, 5.59]]", "white"),
    ("[[0, 0, 5.59], [0, 5.49, 5.59], [5.56, 5.49, 5.59], [5.56, 0, 5.59]]", "white"),
    ("[[5.56, 0, 0], [5.56, 0, 5.59], [5.56, 5.49, 5.59], [5.56, 5.49, 0]]", "red"),
    ("[[0, 0, 0], [0, 5.49, 0], [0, 5.49, 5.59], [0, 0, 5.59]]", "green"),
    ("[[2.13, 5.48, 2.27], [3.43, 5.48, 2.27], [3.43, 5.48, 3.32], [2.13, 5.48, 3.32]]", "lamp"),
]

QUAD = """[[object]]
shape = "quad"
corners = {corners}
material = "{material}"
"""

BALL = """
[[object]]
shape = "sphere"
radius = {radius:.4f}
subdivisions = 2
material = "{material}"

[[object.keys]]
frame = 0
translate = [{x:.4f}, {y:.4f}, {z:.4f}]

[[object.keys]]
frame = 1
translate = [{x:.4f}, {y_end:.4f}, {z:.4f}]
"""


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    count, out = int(sys.argv[1]), sys.argv[2]
    if count < 1:
        sys.exit("COUNT must be at least 1")
    # As many columns across as deep, and layers so that the balls fill the room's middle.
    side = max(1, math.ceil(count ** (1 / 3)))
    spacing = 3.6 / side
    radius = 0.3 * spacing
    text = ROOM.format(count=count)
    text += "\n".join(QUAD.format(corners=c, material=m) for c, m in QUADS)
    materials = ["white", "red", "green"]
    for k in range(count):
        i, j, layer = k % side, (k // side) % side, k // (side * side)
        x = 1.0 + (i + 0.5) * spacing
        z = 1.0 + (j + 0.5) * spacing
        y = 0.9 + (layer + 0.5) * spacing
        text += BALL.format(
            radius=radius,
            material=materials[k % 3],
            x=x,
            y=y,
            z=z,
            y_end=y - 0.3,
        )
    with open(out, "w") as f:
        f.write(text)


if __name__ == "__main__":
    main()
