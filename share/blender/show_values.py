"""Renders values at points of a .blend with Blender: Cycles' full result | pmsc's | their difference.

    blender -b SCENE.blend --python-exit-code 2 --python show_values.py -- --points POINTS.npy \\
        --full FULL.npy --pmsc PMSC.npy [--index 0] [--gain 10] [--size 256] --out IMAGE.png

POINTS.npy is the N x 6 file of `pmsc-blender ... sample` (positions and normals); FULL.npy and
PMSC.npy are frames of values at those points ((F, N, 3) or (N, 3); --index picks the frame of a
file with more than one, so a frame of `pmsc export-frames`' file compares with `pmsc run`'s
one-frame file of it). Each point is drawn through the scene's camera as a
small square facing its normal, emitting its value (scaled so the full result's 99th percentile
is white; the difference |pmsc - full| is scaled by --gain more); the scene's own objects are hidden.
The three renders go side by side into one PNG.
"""
import argparse
import os
import sys
import tempfile

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pmsc_blender import facing_polygons  # noqa: E402  (beside this script, installed or not)


def fail(message):
    print("show_values.py: " + message, file=sys.stderr, flush=True)
    sys.exit(2)


def load(path, index, count):
    try:
        a = np.load(path)
    except (OSError, ValueError) as error:
        fail(f"{path}: {error}")
    if a.ndim == 3 and a.shape[0] == 1:
        a = a[0]
    elif a.ndim == 3:
        if not 0 <= index < a.shape[0]:
            fail(f"{path}: no frame {index} (it has {a.shape[0]})")
        a = a[index]
    if a.shape != (count, 3):
        fail(f"{path}: values of shape {a.shape}, expected ({count}, 3)")
    return a.astype(np.float64)


def splats(points, normals, radius):
    square = radius * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    mesh = facing_polygons("pmsc_show", points + 1e-4 * normals, normals, square)
    mesh.color_attributes.new("value", "FLOAT_COLOR", "POINT")
    mat = bpy.data.materials.new("pmsc_show")
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    attr = nodes.new("ShaderNodeVertexColor")
    attr.layer_name = "value"
    emit = nodes.new("ShaderNodeEmission")
    links.new(attr.outputs["Color"], emit.inputs["Color"])
    links.new(emit.outputs["Emission"], nodes["Material Output"].inputs["Surface"])
    mesh.materials.append(mat)
    obj = bpy.data.objects.new("pmsc_show", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def render(obj, colours, path):
    rgba = np.concatenate([np.repeat(colours, 4, axis=0), np.ones((4 * len(colours), 1))], axis=1)
    obj.data.color_attributes["value"].data.foreach_set("color", rgba.astype(np.float32).reshape(-1))
    obj.data.update()
    bpy.context.scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(path)
    pixels = np.empty(image.size[0] * image.size[1] * 4, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    shape = (image.size[1], image.size[0], 4)
    bpy.data.images.remove(image)
    return pixels.reshape(shape)


def main(argv):
    p = argparse.ArgumentParser(prog="show_values.py")
    p.add_argument("--points", required=True)
    p.add_argument("--full", required=True)
    p.add_argument("--pmsc", required=True)
    p.add_argument("--index", type=int, default=0)
    p.add_argument("--gain", type=float, default=10.0)
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    if not bpy.data.filepath:
        fail("Blender opened no .blend")
    scene = bpy.context.scene
    if scene.camera is None:
        fail("the scene has no camera")
    table = np.load(args.points)
    if table.ndim != 2 or table.shape[1] != 6:
        fail(f"{args.points}: expected N x 6 (x y z nx ny nz)")
    full, pmsc = load(args.full, args.index, len(table)), load(args.pmsc, args.index, len(table))
    normals = table[:, 3:] / np.linalg.norm(table[:, 3:], axis=1, keepdims=True)
    extent = float(np.linalg.norm(table[:, :3].max(0) - table[:, :3].min(0)))
    for obj in scene.objects:
        if obj.type != "CAMERA":
            obj.hide_render = True
    obj = splats(table[:, :3], normals, 1.2 * extent / np.sqrt(len(table)))
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 16
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 0
    scene.world = bpy.data.worlds.new("black")
    scene.world.color = (0, 0, 0)
    scene.view_settings.view_transform = "Standard"
    scene.render.resolution_x = scene.render.resolution_y = args.size
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    white = float(np.percentile(np.linalg.norm(full, axis=1), 99)) / np.sqrt(3) or 1.0
    with tempfile.TemporaryDirectory() as tmp:
        images = [render(obj, full / white, os.path.join(tmp, "full.png")),
                  render(obj, pmsc / white, os.path.join(tmp, "pmsc.png")),
                  render(obj, args.gain * np.abs(pmsc - full) / white, os.path.join(tmp, "difference.png"))]
    side = np.concatenate(images, axis=1)
    out = bpy.data.images.new("pmsc_show", side.shape[1], side.shape[0], alpha=True)
    out.pixels.foreach_set(side.reshape(-1))
    out.filepath_raw = args.out
    out.file_format = "PNG"
    out.save()
    print(f"show_values.py: wrote {args.out}: full | pmsc | {args.gain:g} x difference, white = "
          f"{white * np.sqrt(3):.4g} (the full result's 99th percentile)", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
