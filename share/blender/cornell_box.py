"""Builds the measured Cornell box as a .blend, lit by one animated point light.

Run by Blender:

    blender -b --factory-startup --python-exit-code 2 --python cornell_box.py -- --out cornell.blend \
        [--grid 12] [--path 30] [--power 60]

Geometry and reflectances: the Cornell Program of Computer Graphics' measured box (millimetres,
y up; docs/blender.md has the table), converted to Blender's z-up metres (x, y, z) -> (x, z, y) /
1000 with the faces' winding kept inward. Every surface is diffuse. The light is a point light,
the paper's experiment (section 8) as pmsc's own Cornell demo sets it: frames 1 .. grid^2 put it on
a grid x grid lattice 60 mm below the ceiling (the training frames), frames grid^2 + 1 .. grid^2 +
path move it along a closed curve across the lattice, between its nodes and up to 4 mm off its plane
(positions training never saw).
The camera is the measured one, so a render of any frame shows the box as the data describe it.
"""
import argparse
import math
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pmsc_blender import key_light_and_save, new_point_light  # noqa: E402  (beside this script)

QUADS = {
    "floor": ("white", [(552.8, 0, 0), (0, 0, 0), (0, 0, 559.2), (549.6, 0, 559.2)]),
    "ceiling": ("white", [(556, 548.8, 0), (556, 548.8, 559.2), (0, 548.8, 559.2), (0, 548.8, 0)]),
    "back": ("white", [(549.6, 0, 559.2), (0, 0, 559.2), (0, 548.8, 559.2), (556, 548.8, 559.2)]),
    "left": ("red", [(552.8, 0, 0), (549.6, 0, 559.2), (556, 548.8, 559.2), (556, 548.8, 0)]),
    "right": ("green", [(0, 0, 559.2), (0, 0, 0), (0, 548.8, 0), (0, 548.8, 559.2)]),
}
BLOCKS = {
    "short": [
        [(130, 165, 65), (82, 165, 225), (240, 165, 272), (290, 165, 114)],
        [(290, 0, 114), (290, 165, 114), (240, 165, 272), (240, 0, 272)],
        [(130, 0, 65), (130, 165, 65), (290, 165, 114), (290, 0, 114)],
        [(82, 0, 225), (82, 165, 225), (130, 165, 65), (130, 0, 65)],
        [(240, 0, 272), (240, 165, 272), (82, 165, 225), (82, 0, 225)],
    ],
    "tall": [
        [(423, 330, 247), (265, 330, 296), (314, 330, 456), (472, 330, 406)],
        [(423, 0, 247), (423, 330, 247), (472, 330, 406), (472, 0, 406)],
        [(472, 0, 406), (472, 330, 406), (314, 330, 456), (314, 0, 456)],
        [(314, 0, 456), (314, 330, 456), (265, 330, 296), (265, 0, 296)],
        [(265, 0, 296), (265, 330, 296), (423, 330, 247), (423, 0, 247)],
    ],
}
REFLECTANCE = {"white": (0.886, 0.699, 0.666), "red": (0.570, 0.043, 0.044), "green": (0.105, 0.378, 0.076)}


def to_blender(p):
    """Millimetres, y up -> metres, z up (a proper rotation: (x, y, z) -> (x, -z, y))."""
    x, y, z = p
    return (x / 1000.0, -z / 1000.0, y / 1000.0)


def material(name, rgb):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    bsdf = m.node_tree.nodes["Principled BSDF"]
    m.node_tree.nodes.remove(bsdf)
    diffuse = m.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*rgb, 1.0)
    m.node_tree.links.new(diffuse.outputs["BSDF"], m.node_tree.nodes["Material Output"].inputs["Surface"])
    return m


def mesh_object(name, quads, mat):
    verts, faces = [], []
    for quad in quads:
        faces.append(tuple(range(len(verts), len(verts) + 4)))
        verts.extend(to_blender(p) for p in quad)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.materials.append(mat)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def light_positions(grid, path):
    """The training lattice, then the path (millimetres, y up): pmsc's own Cornell rig
    (evaluators/cornell/CornellScene.h, LightRig): a lattice 396 mm across centred under the
    ceiling, 60 mm below it (12 x 12 at a 36 mm pitch by default), and a Lissajous path across 90%
    of it, rising and falling 4 mm."""
    span, cx, cz, y = 396.0, 278.0, 279.6, 548.8 - 60.0
    pitch = span / (grid - 1)
    lattice = [(cx + (i - 0.5 * (grid - 1)) * pitch, y, cz + (j - 0.5 * (grid - 1)) * pitch)
               for j in range(grid) for i in range(grid)]
    half = 0.5 * span * 0.9
    curve = [(cx + half * math.sin(t), y + 4.0 * math.sin(3 * t), cz + half * math.sin(2 * t + 0.5))
             for t in (2 * math.pi * k / path for k in range(path))]
    return lattice + curve


def main(argv):
    p = argparse.ArgumentParser(prog="cornell_box.py")
    p.add_argument("--out", required=True, help="the .blend to write")
    p.add_argument("--grid", type=int, default=12, help="training lattice side (grid^2 frames)")
    p.add_argument("--path", type=int, default=30, help="frames of the validation path")
    p.add_argument("--power", type=float, default=60.0, help="point light power in watts")
    args = p.parse_args(argv)
    if args.grid < 2 or args.path < 1:
        sys.exit("cornell_box.py: --grid must be at least 2 and --path at least 1")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.world = bpy.data.worlds.new("black")  # no light but the box's
    scene.world.color = (0, 0, 0)
    mats = {k: material(k, v) for k, v in REFLECTANCE.items()}
    for name, (colour, quad) in QUADS.items():
        mesh_object(name, [quad], mats[colour])
    for name, quads in BLOCKS.items():
        mesh_object(name + "_block", quads, mats["white"])
    light = new_point_light("Light", args.power)
    positions = light_positions(args.grid, args.path)
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = math.radians(39.3077)
    cam = bpy.data.objects.new("Camera", cam_data)
    cam.location = to_blender((278, 273, -800))
    cam.rotation_euler = (math.radians(90), 0, math.radians(180))  # looks along -y (the data's +z), z up
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x = scene.render.resolution_y = 256
    key_light_and_save(light, [to_blender(p) for p in positions], args.grid * args.grid, args.out, "cornell_box.py")


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
