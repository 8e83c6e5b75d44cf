"""Keys a point light of any .blend on a training lattice and a path training never saw.

Run by Blender, on the scene to light:

    blender -b SCENE.blend --python-exit-code 2 --python animate_light.py -- --out LIT.blend \
        [--grid 10] [--path 30] [--power 200] [--above 0.5] [--light NAME]

The light (a new point light `pmsc_light`, or the scene's light --light names, which must be a point
light) moves over the scene's visible meshes: frames 1 .. grid^2 put it on a grid x grid lattice
covering their bounding box from above, --above times the box's largest side over its top (the
training frames); frames grid^2 + 1 .. grid^2 + path move it along a closed curve across 90% of the
lattice, between its nodes and up to 1% of the lattice's width off its plane (positions training
never saw), as the Cornell box's rig (cornell_box.py) does. The scene's other lights stay as they
are: their light is the same in every frame. Keys are constant, so a frame is exactly its position.
The scene's frame range becomes 1 .. grid^2 + path and its "pmsc_training_frames" and
"pmsc_path_frames" properties say which is which.

Fails with one line and exit code 2: no visible mesh, a --light that is missing or not a point
light, bad arguments.
"""
import argparse
import math
import sys

import os

import bpy
from mathutils import Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pmsc_blender import key_light_and_save, new_point_light  # noqa: E402  (beside this script)


def fail(message):
    print("animate_light.py: " + message, file=sys.stderr, flush=True)
    sys.exit(2)


def mesh_bounds():
    """The world-space bounding box of the visible meshes (modifiers applied)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    lo, hi = [math.inf] * 3, [-math.inf] * 3
    for obj in bpy.context.scene.objects:
        if obj.type != "MESH" or obj.hide_render:
            continue
        evaluated = obj.evaluated_get(depsgraph)
        for corner in evaluated.bound_box:
            p = evaluated.matrix_world @ Vector(corner)
            lo = [min(a, b) for a, b in zip(lo, p)]
            hi = [max(a, b) for a, b in zip(hi, p)]
    if lo[0] == math.inf:
        fail("the scene has no visible mesh to light")
    return lo, hi


def positions(lo, hi, grid, path, above):
    """The lattice, then the path: a Lissajous curve over 90% of the lattice, 1% off its plane."""
    cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
    side = max(h - l for l, h in zip(lo, hi))
    width = max(hi[0] - lo[0], hi[1] - lo[1])
    z = hi[2] + above * side
    pitch = width / (grid - 1)
    lattice = [(cx + (i - 0.5 * (grid - 1)) * pitch, cy + (j - 0.5 * (grid - 1)) * pitch, z)
               for j in range(grid) for i in range(grid)]
    half = 0.45 * width
    curve = [(cx + half * math.sin(3 * t + 0.4), cy + half * math.sin(2 * t), z + 0.01 * width * math.sin(5 * t))
             for t in (2 * math.pi * k / path for k in range(path))]
    return lattice + curve


def main(argv):
    p = argparse.ArgumentParser(prog="animate_light.py", description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True, help="the .blend to write")
    p.add_argument("--grid", type=int, default=10, help="training lattice side (grid^2 frames)")
    p.add_argument("--path", type=int, default=30, help="frames of the path training never saw")
    p.add_argument("--power", type=float, default=200.0, help="a new light's power (W)")
    p.add_argument("--above", type=float, default=0.5, help="height over the meshes, in their largest side")
    p.add_argument("--light", default="", help="animate this point light of the scene instead of a new one")
    try:
        args = p.parse_args(argv)
    except SystemExit as e:
        sys.exit(2 if e.code else 0)
    if args.grid < 2 or args.path < 1 or not args.power > 0 or not args.above > 0:
        fail("--grid must be at least 2, --path at least 1, --power and --above positive")
    scene = bpy.context.scene
    if args.light:
        light = scene.objects.get(args.light)
        if light is None or light.type != "LIGHT":
            fail(f"the scene has no light named '{args.light}'")
        if light.data.type != "POINT":
            fail(f"'{args.light}' is a {light.data.type.lower()} light, not a point light")
    else:
        light = new_point_light("pmsc_light", args.power)
    lo, hi = mesh_bounds()
    scene.render.engine = "CYCLES"
    key_light_and_save(light, positions(lo, hi, args.grid, args.path, args.above), args.grid * args.grid,
                       args.out, "animate_light.py")


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
