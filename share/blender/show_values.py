"""Renders values at points of a .blend with Blender: Cycles' full result | pmsc's | their difference.

    blender -b SCENE.blend --python-exit-code 2 --python show_values.py -- --points POINTS.npy \\
        --full FULL.npy --pmsc PMSC.npy [--index 0] [--gain 10] [--size 256] [--surfaces [--subdivide 4]] \\
        [--frame F] --out IMAGE.png

POINTS.npy is the N x 6 file of `pmsc-blender ... sample` (positions and normals); FULL.npy and
PMSC.npy are frames of values at those points ((F, N, 3) or (N, 3); --index picks the frame of a
file with more than one, so a frame of `pmsc export-frames`' file compares with `pmsc run`'s
one-frame file of it), or a light cache `pmsc run --format vdb` wrote (PMSC.vdb: its grid
'light', read at the points' positions with OpenVDB's Python module, python3-openvdb). The three
renders go side by side into one PNG, through the scene's camera (at scene frame --frame, default
the current one), scaled so the full result's 99th percentile is white; the difference
|pmsc - full| is scaled by --gain more.

Two ways to draw the values:
- by default each point is a small square facing its normal, emitting its value: the values
  themselves, the scene's own objects hidden;
- --surfaces renders the scene's own meshes lit by the values, as a renderer shows a light cache:
  each visible mesh (subdivided --subdivide times, simple, so its vertices are about as dense as
  the points) takes at each vertex the inverse-distance mean of its 8 nearest points that face
  within 60 degrees of its normal (the nearest when none does), times its material's base colour,
  as emission. The picture is the scene as it renders with pmsc's light; the value is the light a
  white diffuse surface reflects (pmsc_blender.py), so the base colour is the surface's albedo.
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


def load_vdb(path, positions):
    """The values of a `pmsc run --format vdb` light cache (its grid 'light', one voxel per point
    or the mean of the few that share one) read back at the points, through OpenVDB's Python
    module."""
    try:
        import pyopenvdb as vdb
    except ImportError:
        fail(f"{path}: reading a .vdb needs OpenVDB's Python module (apt-get install python3-openvdb)")
    try:
        grid = vdb.read(path, "light")
    except Exception as error:  # noqa: BLE001 (pyopenvdb raises KeyError, IOError, RuntimeError)
        fail(f"{path}: not a pmsc light cache ({type(error).__name__}: {error})")
    if not isinstance(grid, vdb.Vec3SGrid):
        fail(f"{path}: grid 'light' is not RGB (a Vec3SGrid)")
    to_index, read = grid.transform.worldToIndexCellCentered, grid.getConstAccessor().probeValue
    out = np.empty((len(positions), 3))
    outside = 0
    for i, p in enumerate(positions):
        value, active = read(to_index(tuple(float(x) for x in p)))
        out[i] = value
        outside += not active
    if outside:
        fail(f"{path}: {outside} of the {len(positions)} points have no voxel (a cache of other points?)")
    return out


def load(path, index, count, positions=None):
    if path.endswith(".vdb"):
        return load_vdb(path, positions)
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


def emission_material(name, base_colour):
    """Emission of the colour attribute "value" times base_colour."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    attr = nodes.new("ShaderNodeVertexColor")
    attr.layer_name = "value"
    albedo = nodes.new("ShaderNodeMixRGB")
    albedo.blend_type = "MULTIPLY"
    albedo.inputs["Fac"].default_value = 1.0
    albedo.inputs["Color2"].default_value = tuple(base_colour[:3]) + (1.0,)
    emit = nodes.new("ShaderNodeEmission")
    links.new(attr.outputs["Color"], albedo.inputs["Color1"])
    links.new(albedo.outputs["Color"], emit.inputs["Color"])
    links.new(emit.outputs["Emission"], nodes["Material Output"].inputs["Surface"])
    return mat


def paint(mesh, colours):
    rgba = np.concatenate([colours, np.ones((len(colours), 1))], axis=1)
    mesh.color_attributes["value"].data.foreach_set("color", rgba.astype(np.float32).reshape(-1))
    mesh.update()


def splats(points, normals, radius):
    """One emitting square per point; returns the painter of point values."""
    square = radius * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    mesh = facing_polygons("pmsc_show", points + 1e-4 * normals, normals, square)
    mesh.color_attributes.new("value", "FLOAT_COLOR", "POINT")
    mesh.materials.append(emission_material("pmsc_show", (1.0, 1.0, 1.0)))
    obj = bpy.data.objects.new("pmsc_show", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return lambda values: paint(mesh, np.repeat(values, 4, axis=0))


def base_colour(obj):
    """The albedo of an object's first material: its Principled BSDF's base colour or its Diffuse
    BSDF's colour (unconnected inputs), or its viewport diffuse colour; white without a material."""
    mat = obj.active_material
    if mat is None:
        return (1.0, 1.0, 1.0)
    if mat.use_nodes:
        for node in mat.node_tree.nodes:
            if node.type == "BSDF_PRINCIPLED":
                return tuple(node.inputs["Base Color"].default_value)[:3]
            if node.type == "BSDF_DIFFUSE":
                return tuple(node.inputs["Color"].default_value)[:3]
    return tuple(mat.diffuse_color)[:3]


def surfaces(points, normals, subdivide):
    """The scene's visible meshes lit by point values (module docstring); returns the painter."""
    from mathutils import Vector
    from mathutils.kdtree import KDTree
    tree = KDTree(len(points))
    for i, p in enumerate(points):
        tree.insert(Vector(p), i)
    tree.balance()
    scene = bpy.context.scene
    painters = []
    for obj in [o for o in scene.objects if o.type == "MESH" and not o.hide_render]:
        if subdivide > 0:
            mod = obj.modifiers.new("pmsc_subdivide", "SUBSURF")
            mod.subdivision_type = "SIMPLE"
            mod.levels = mod.render_levels = subdivide
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        mesh = bpy.data.meshes.new_from_object(evaluated)
        mesh.transform(obj.matrix_world)
        mesh.color_attributes.new("value", "FLOAT_COLOR", "POINT")
        mesh.materials.clear()
        mesh.materials.append(emission_material("pmsc_lit_" + obj.name, base_colour(obj)))
        lit = bpy.data.objects.new("pmsc_lit_" + obj.name, mesh)
        scene.collection.objects.link(lit)
        obj.hide_render = True
        idx = np.zeros((len(mesh.vertices), 8), dtype=np.int64)
        weight = np.zeros((len(mesh.vertices), 8))
        for v in mesh.vertices:
            found = tree.find_n(v.co, 8)
            facing = [(i, d) for (_, i, d) in found if float(np.dot(normals[i], v.normal)) > 0.5]
            chosen = facing or [(found[0][1], found[0][2])]
            w = np.array([1.0 / max(d, 1e-6) for _, d in chosen])
            idx[v.index, :len(chosen)] = [i for i, _ in chosen]
            weight[v.index, :len(chosen)] = w / w.sum()
        painters.append(lambda values, mesh=mesh, idx=idx, weight=weight:
                        paint(mesh, (values[idx] * weight[:, :, None]).sum(axis=1)))
    if not painters:
        fail("the scene has no visible mesh to light")
    return lambda values: [p(values) for p in painters]


def render(painter, colours, path):
    painter(colours)
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
    p.add_argument("--surfaces", action="store_true", help="the scene's meshes lit by the values")
    p.add_argument("--subdivide", type=int, default=4, help="--surfaces: simple subdivisions of each mesh")
    p.add_argument("--frame", type=int, default=None, help="the scene frame to render (default: the current)")
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    if not 0 <= args.subdivide <= 6:
        fail("--subdivide must be 0 to 6")
    if not bpy.data.filepath:
        fail("Blender opened no .blend")
    scene = bpy.context.scene
    if scene.camera is None:
        fail("the scene has no camera")
    table = np.load(args.points)
    if table.ndim != 2 or table.shape[1] != 6:
        fail(f"{args.points}: expected N x 6 (x y z nx ny nz)")
    full = load(args.full, args.index, len(table), table[:, :3])
    pmsc = load(args.pmsc, args.index, len(table), table[:, :3])
    normals = table[:, 3:] / np.linalg.norm(table[:, 3:], axis=1, keepdims=True)
    if args.frame is not None:
        scene.frame_set(args.frame)
    if args.surfaces:
        painter = surfaces(table[:, :3], normals, args.subdivide)
        for obj in scene.objects:
            if obj.type not in ("CAMERA", "MESH"):
                obj.hide_render = True
    else:
        extent = float(np.linalg.norm(table[:, :3].max(0) - table[:, :3].min(0)))
        for obj in scene.objects:
            if obj.type != "CAMERA":
                obj.hide_render = True
        painter = splats(table[:, :3], normals, 1.2 * extent / np.sqrt(len(table)))
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
        images = [render(painter, full / white, os.path.join(tmp, "full.png")),
                  render(painter, pmsc / white, os.path.join(tmp, "pmsc.png")),
                  render(painter, args.gain * np.abs(pmsc - full) / white, os.path.join(tmp, "difference.png"))]
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
