"""pmsc's Blender child: Cycles computes the light arriving at points of a .blend, for pmsc.

Run by Blender (Debian's: its Python is the system Python 3, with numpy):

  blender -b SCENE.blend --python-exit-code 2 --python pmsc_blender.py -- sample --out POINTS.npy \\
      --count N [--seed S] [--skip NAME,...]
  blender -b SCENE.blend --python-exit-code 2 --python pmsc_blender.py -- serve --points POINTS.npy \\
      --frames FIRST-LAST [--samples 64] [--light direct,indirect] [--threads 1] [--seed 0] 1>&2
  blender -b CHARACTER.blend --python-exit-code 2 --python pmsc_blender.py -- pose --object NAME \\
      --frames FIRST-LAST [--action NAME] [--space root|world] 1>&2

`sample` draws N points on the scene's mesh surfaces, by area, with the surface normal at each
(an N x 6 float64 .npy: x y z nx ny nz, world space), deterministically for a seed. `serve` is an
exec-protocol child (docs/exec-protocol.md): pmsc's frame f is the scene's frame FIRST + f (its
animated lights, objects and materials), and the values of a point are the RGB irradiance Cycles
computes there (a diffuse bake without colour: the light arriving, as a white diffuse surface
facing the normal would reflect it). `pose` is an exec-protocol child too: the points are a mesh
object's evaluated vertices, posed by its armature (pmsc_blender_pose.py). `1>&2` keeps Blender's own messages off the protocol: the
child answers on its standard input, which is the socket pmsc gives it.

How a point is computed: one small triangle (a probe) per asked point, at the point and facing its
normal, in a mesh of its own; a Cycles bake of type DIFFUSE with the asked passes and no colour
into a float colour attribute on the probe's vertices; the value is the mean of its three. The
probes are invisible to every secondary ray (diffuse, glossy, transmission, volume, shadow), so
they cast no shadow and light nothing; they stay visible to the camera, which the bake needs. A
bake seeds each corner's samples with its vertex number, and point p's probe is always vertices
3p .. 3p + 2 (the other points' are loose vertices the bake skips), so a point's value does not
depend on the other points of its call. The probe mesh of a point set is kept and reused (the key
points are asked every frame), so a call pays Cycles' synchronisation of the scene and the
samples, not a mesh build.

Failures answer with one line (status 1), and pmsc fails the frame: a frame outside the range, a
point outside the file. A .blend that does not open, a bad argument or a missing numpy ends Blender
with exit code 2 before the hello, which pmsc reports with the child's last stderr line.
"""
import argparse
import os
import re
import socket
import struct
import sys
import time

import bpy
import numpy as np

HELLO = struct.Struct("<8sIIQQ")   # magic, version, channels, points, frames
REQUEST = struct.Struct("<IIqQQ")  # kind (1 list, 2 range, 3 positions), 0, frame, count, first
RESPONSE = struct.Struct("<IIQ")   # status (0 values, 1 error), 0, length
LIST, RANGE, POSITIONS = 1, 2, 3
PASSES = {"direct": "DIRECT", "indirect": "INDIRECT"}


def fail(message):
    print("pmsc_blender.py: " + message, file=sys.stderr, flush=True)
    sys.exit(2)


def frame_range(text):
    try:
        first, last = (int(v) for v in text.split("-"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not FIRST-LAST")
    if last < first:
        raise argparse.ArgumentTypeError(f"'{text}': LAST is before FIRST")
    return first, last


def scene_meshes(skip):
    """The scene's visible mesh objects (evaluated: modifiers applied), minus those named in skip."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for obj in bpy.context.scene.objects:
        if obj.type == "MESH" and obj.name not in skip and not obj.name.startswith("pmsc_probe") \
                and not obj.hide_render:
            yield obj.evaluated_get(depsgraph)


def sample(args):
    """N points on the surfaces by area, with their normals (deterministic for a seed)."""
    tris, normals, areas = [], [], []
    for obj in scene_meshes(set(args.skip.split(",")) if args.skip else set()):
        mesh = obj.to_mesh()
        mesh.calc_loop_triangles()
        m = np.array(obj.matrix_world)
        verts = np.empty(len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", verts)
        verts = verts.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        idx = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
        mesh.loop_triangles.foreach_get("vertices", idx)
        t = verts[idx.reshape(-1, 3)]
        cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        area = 0.5 * np.linalg.norm(cross, axis=1)
        keep = area > 0
        tris.append(t[keep])
        normals.append(cross[keep] / (2 * area[keep, None]))
        areas.append(area[keep])
        obj.to_mesh_clear()
    if not tris:
        fail("the scene has no mesh surface to sample")
    tris, normals, areas = np.concatenate(tris), np.concatenate(normals), np.concatenate(areas)
    rng = np.random.default_rng(args.seed)
    which = rng.choice(len(areas), size=args.count, p=areas / areas.sum())
    u, v = rng.random(args.count), rng.random(args.count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tris[which]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    out = np.concatenate([points, normals[which]], axis=1)
    tmp = args.out + ".partial.npy"
    np.save(tmp, out)
    os.replace(tmp, args.out)
    lo, hi = points.min(0), points.max(0)
    print(f"pmsc_blender.py: wrote {args.out}: {args.count} points on {len(areas)} triangles, "
          f"bounding-box diagonal {np.linalg.norm(hi - lo):.6g}", file=sys.stderr, flush=True)


def polygon_corners(centres, normals, corners):
    """The corners of one polygon per point, (N, k, 3): `corners` (k, 2) offsets in units of the
    point's tangent frame (t, b), counter-clockwise about the normal, so each polygon faces its
    normal."""
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    t = np.cross(helper, normals)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(normals, t)
    return centres[:, None, :] + corners[None, :, :1] * t[:, None, :] + corners[None, :, 1:] * b[:, None, :]


def facing_polygons(name, centres, normals, corners):
    """A mesh of one polygon per point (polygon_corners)."""
    verts = polygon_corners(centres, normals, corners)
    count, k = verts.shape[0], verts.shape[1]
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(k * count)
    mesh.vertices.foreach_set("co", verts.reshape(-1))
    mesh.loops.add(k * count)
    mesh.loops.foreach_set("vertex_index", np.arange(k * count, dtype=np.int32))
    mesh.polygons.add(count)
    mesh.polygons.foreach_set("loop_start", np.arange(0, k * count, k, dtype=np.int32))
    mesh.polygons.foreach_set("loop_total", np.full(count, k, dtype=np.int32))
    mesh.update()
    return mesh


class Probes:
    """Probe meshes of point sets, kept for reuse; one bake per call."""

    def __init__(self, points, normals, passes, keep=4):
        self.points, self.normals, self.passes, self.keep = points, normals, passes, keep
        lo, hi = points.min(0), points.max(0)
        diagonal = float(np.linalg.norm(hi - lo)) or 1.0
        self.size = 1e-4 * diagonal    # probe radius: far below the scene's detail
        self.lift = 1e-4 * diagonal    # above its surface, so its own surface does not shadow it
        self.cache = []                # (key, object), most recent last
        self.corners = None            # every point's probe corners (N, 3, 3), built on first use

    def _build(self, ids):
        # Every point's probe has its three vertices at 3p, 3p + 1, 3p + 2, in every set: a bake
        # to a colour attribute seeds each corner's samples with its vertex number, so a point
        # draws the same samples whichever points share its call. Only the asked points' probes
        # are polygons; the rest are loose vertices, which the bake skips.
        if self.corners is None:
            s, h = self.size, self.size * np.sqrt(3) / 2
            triangle = np.array([[s, 0.0], [-0.5 * s, h], [-0.5 * s, -h]])
            self.corners = polygon_corners(self.points + self.lift * self.normals, self.normals, triangle)
        mesh = bpy.data.meshes.new("pmsc_probe")
        mesh.vertices.add(3 * len(self.corners))
        mesh.vertices.foreach_set("co", self.corners.reshape(-1))
        loops = (3 * ids[:, None] + np.arange(3)[None, :]).reshape(-1).astype(np.int32)
        mesh.loops.add(len(loops))
        mesh.loops.foreach_set("vertex_index", loops)
        mesh.polygons.add(len(ids))
        mesh.polygons.foreach_set("loop_start", np.arange(0, len(loops), 3, dtype=np.int32))
        mesh.polygons.foreach_set("loop_total", np.full(len(ids), 3, dtype=np.int32))
        mesh.update()
        # On the corners: the bake writes the asked probes' corners only (on the points, it would
        # also clear and average every loose vertex).
        mesh.color_attributes.new("pmsc_light", "FLOAT_COLOR", "CORNER")
        mesh.attributes.active_color = mesh.color_attributes["pmsc_light"]
        mat = bpy.data.materials.get("pmsc_probe") or bpy.data.materials.new("pmsc_probe")
        mesh.materials.append(mat)
        obj = bpy.data.objects.new("pmsc_probe", mesh)
        for ray in ("visible_diffuse", "visible_glossy", "visible_transmission", "visible_volume_scatter",
                    "visible_shadow"):
            setattr(obj, ray, False)
        bpy.context.scene.collection.objects.link(obj)
        return obj

    def object_for(self, ids):
        key = ids.tobytes()
        for i, (k, obj) in enumerate(self.cache):
            if k == key:
                self.cache.append(self.cache.pop(i))
                return obj
        obj = self._build(ids)
        self.cache.append((key, obj))
        if len(self.cache) > self.keep:
            _, old = self.cache.pop(0)
            mesh = old.data
            bpy.data.objects.remove(old)
            bpy.data.meshes.remove(mesh)
        return obj

    def bake(self, ids):
        obj = self.object_for(ids)
        for other in bpy.context.view_layer.objects:
            other.select_set(False)
        for _, probe in self.cache:
            probe.hide_render = probe is not obj  # the other probe sets stay out of the scene's sync
        obj.select_set(True)
        bpy.context.view_layer.objects.active = obj
        if self.passes == {"INDIRECT"}:
            # Cycles (Blender 3.4) bakes the indirect pass alone as zeros. Both passes less the direct
            # one, at the same seed, is the indirect light: a corner draws the same direct samples in
            # both bakes (measured on the Cornell box: every difference >= 0, and the two draws of
            # another seed agree), at the price of a second bake.
            both = self._bake_once(obj, {"DIRECT", "INDIRECT"})
            return np.maximum(both - self._bake_once(obj, {"DIRECT"}), 0.0)
        return self._bake_once(obj, self.passes)

    @staticmethod
    def _bake_once(obj, passes):
        bpy.ops.object.bake(type="DIFFUSE", pass_filter=passes, target="VERTEX_COLORS", margin=0,
                            use_clear=True)
        colors = np.empty(len(obj.data.loops) * 4, dtype=np.float32)
        obj.data.color_attributes["pmsc_light"].data.foreach_get("color", colors)
        return colors.reshape(-1, 3, 4)[:, :, :3].mean(axis=1).astype(np.float64)  # in the asked order


def new_point_light(name, power):
    """A point light of `power` W with hard shadows (no radius), linked into the scene."""
    data = bpy.data.lights.new(name, type="POINT")
    data.energy = power
    data.shadow_soft_size = 0.0
    light = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(light)
    return light


def key_light_and_save(light, positions, training_frames, out, script):
    """Keys `light` at positions[f - 1] on frames 1 .. len(positions) (constant between keys, so a
    frame is exactly its position), makes that the scene's frame range, marks frames
    1 .. training_frames as "pmsc_training_frames" and the rest as "pmsc_path_frames", and saves
    the .blend to `out` (cornell_box.py, animate_light.py)."""
    scene = bpy.context.scene
    light.animation_data_clear()
    for f, position in enumerate(positions, start=1):
        light.location = position
        light.keyframe_insert("location", frame=f)
    for fc in light.animation_data.action.fcurves:
        for k in fc.keyframe_points:
            k.interpolation = "CONSTANT"
    scene.frame_start, scene.frame_end = 1, len(positions)
    scene["pmsc_training_frames"] = f"1-{training_frames}"
    scene["pmsc_path_frames"] = f"{training_frames + 1}-{len(positions)}"
    bpy.ops.wm.save_as_mainfile(filepath=out)
    print(f"{script}: wrote {out}: light '{light.name}', training frames {scene['pmsc_training_frames']}, "
          f"path frames {scene['pmsc_path_frames']}")


def read_exactly(sock, size):
    data = bytearray()
    while len(data) < size:
        chunk = sock.recv(size - len(data))
        if not chunk:
            raise EOFError
        data += chunk
    return bytes(data)


def load_points(path):
    try:
        table = np.load(path)
    except (OSError, ValueError) as error:
        fail(f"{path}: {error}")
    if table.ndim != 2 or table.shape[1] != 6 or not np.isfinite(table).all():
        fail(f"{path}: expected N x 6 finite values (x y z nx ny nz), got shape {table.shape}")
    if not (np.linalg.norm(table[:, 3:], axis=1) > 0).all():
        fail(f"{path}: a point has a zero normal")
    return table


class Controls:
    """Named properties set from a table every frame: `--set PATH` (repeated) names each, as
    Blender's Python writes it from bpy.data (`objects["Light"].data.energy`,
    `objects["Light"].location`, `materials["Red"].node_tree.nodes["Diffuse BSDF"].inputs[0].default_value`),
    and row f of `--controls TABLE.npy` holds pmsc frame f's values: one column per number, a vector
    property taking as many columns as it has components, in the order of the --set options. The
    values are set after the scene's frame (so they override what is animated there)."""

    def __init__(self, paths, table_path, frames):
        self.targets, width = [], 0
        for path in paths:
            owner, name, kind, size = self._resolve(path)
            self.targets.append((owner, name, kind, size, width))
            width += size
        try:
            self.table = np.load(table_path)
        except (OSError, ValueError) as error:
            fail(f"{table_path}: {error}")
        if not isinstance(self.table, np.ndarray) or self.table.dtype.kind not in "iuf":
            fail(f"{table_path}: expected one array of numbers (an .npy, not an .npz or text)")
        if self.table.ndim == 1:
            self.table = self.table[:, None]
        if self.table.ndim != 2 or self.table.shape != (frames, width) or not np.isfinite(self.table).all():
            fail(f"{table_path}: expected {frames} x {width} finite values (a row per frame of --frames, "
                 f"a column per number of the --set properties), got shape {self.table.shape}")

    @staticmethod
    def _resolve(path):
        """(the struct holding the property, its name, its kind: a float, an int or a length) of
        bpy.data's `path`."""
        # COLLECTION["NAME"].REST, the name quoted (it may hold dots: "Light.001") or bare.
        match = re.fullmatch(r"""(\w+)\[(?:"([^"]*)"|'([^']*)'|([^\]"']*))\]\.(.+)""", path)
        holder = getattr(bpy.data, match.group(1), None) if match else None
        if not isinstance(holder, bpy.types.bpy_prop_collection):
            fail(f"--set '{path}': not COLLECTION[\"NAME\"].PROPERTY (objects[\"Light\"].data.energy)")
        collection, rest = match.group(1), match.group(5)
        name = next(g for g in match.groups()[1:4] if g is not None)
        if name not in holder:
            fail(f"--set '{path}': bpy.data.{collection} has no '{name}'")
        owner, _, prop = rest.rpartition(".")
        try:
            struct = holder[name].path_resolve(owner) if owner else holder[name]
            value = getattr(struct, prop)
        except (ValueError, AttributeError):
            fail(f"--set '{path}': '{holder[name].name}' has no property '{rest}'")
        scalar = isinstance(value, (int, float)) and not isinstance(value, bool)
        vector = hasattr(value, "__len__") and not isinstance(value, str) and len(value) > 0 and \
            all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        if not (scalar or vector):
            fail(f"--set '{path}': '{rest}' is not a number or a vector of numbers")
        kind = int if isinstance(value if scalar else value[0], int) else float
        return struct, prop, kind, (1 if scalar else len(value))

    def apply(self, frame):
        row = self.table[frame]
        for struct, name, kind, size, column in self.targets:
            values = [kind(v) for v in row[column:column + size]]
            setattr(struct, name, values[0] if size == 1 else tuple(values))
        bpy.context.view_layer.update()


def serve_loop(channels, count, frames, compute, positions):
    """The exec protocol, version 2, on standard input (docs/exec-protocol.md): hello, then one
    answer per request, `compute(frame, ids)` giving the values (len(ids) x channels) and
    `positions()` where the points are (N x 3); an exception answers with one line and pmsc fails
    the frame."""
    sock = socket.socket(fileno=os.dup(0))
    sock.sendall(HELLO.pack(b"PMSCEXEC", 2, channels, count, frames))
    timing = os.environ.get("PMSC_BLENDER_TIMING")
    while True:
        try:
            kind, _, frame, asked, start = REQUEST.unpack(read_exactly(sock, REQUEST.size))
            if kind == POSITIONS:
                answer(sock, lambda: positions().reshape(-1))
                continue
            if kind not in (LIST, RANGE):
                answer(sock, None, ValueError(f"unknown request kind {kind}"))
                continue
            ids = (np.frombuffer(read_exactly(sock, 8 * asked), dtype="<u8").astype(np.int64) if kind == LIST
                   else np.arange(start, start + asked, dtype=np.int64))
        except (EOFError, ConnectionError):  # pmsc closed the socket, or went away
            return
        try:
            if not 0 <= frame < frames:
                raise ValueError(f"frame {frame} outside [0, {frames - 1}]")
            if asked and (ids.min() < 0 or ids.max() >= count):
                raise ValueError(f"a point outside [0, {count})")
            began = time.perf_counter()
            values = np.ascontiguousarray(compute(frame, ids), dtype="<f8")
            if timing:
                with open(timing, "a") as log:
                    log.write(f"{frame} {asked} {time.perf_counter() - began:.6f}\n")
        except Exception as error:  # one line; pmsc fails the frame
            answer(sock, None, error)
        else:
            answer(sock, lambda: values)


def answer(sock, values, error=None):
    """Sends values() (float64), or one line for an error (raised by values() or given)."""
    if error is None:
        try:
            data = np.ascontiguousarray(values(), dtype="<f8")
        except Exception as raised:  # noqa: BLE001 (any failure is one line to pmsc)
            error = raised
    try:
        if error is not None:
            text = f"{type(error).__name__}: {error}".replace("\n", " ").encode()
            sock.sendall(RESPONSE.pack(1, 0, len(text)) + text)
        else:
            sock.sendall(RESPONSE.pack(0, 0, data.size) + data.tobytes())
    except ConnectionError:  # pmsc went away (it was killed, or gave up on this child): end quietly
        sys.exit(0)


def serve(args):
    table = load_points(args.points)
    normals = table[:, 3:] / np.linalg.norm(table[:, 3:], axis=1, keepdims=True)
    passes = set()
    for name in args.light.split(","):
        if name not in PASSES:
            fail(f"--light: '{name}' is not direct or indirect")
        passes.add(PASSES[name])
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = args.samples
    scene.cycles.seed = args.seed
    scene.cycles.use_animated_seed = False
    scene.cycles.use_adaptive_sampling = False  # the same samples at every point
    # A bake with denoising on and no denoiser in the build (Debian's has no OpenImageDenoise)
    # finishes with every value 0: off, the values are the samples' mean.
    scene.cycles.use_denoising = False
    scene.render.threads_mode = "FIXED"
    scene.render.threads = args.threads
    first, last = args.frames
    probes = Probes(table[:, :3], normals, passes)
    controls = Controls(args.set, args.controls, last - first + 1) if args.set else None

    def compute(frame, ids):
        scene.frame_set(first + frame)
        if controls:
            controls.apply(frame)
        return probes.bake(ids)

    serve_loop(3, len(table), last - first + 1, compute, lambda: table[:, :3])


def pose(args):
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from pmsc_blender_pose import Pose, PoseError  # beside this script

    first, last = args.frames
    try:
        posed = Pose(args.object, args.action, args.space, first, last - first + 1,
                     lambda text: print("pmsc_blender.py: pose: " + text, file=sys.stderr, flush=True))
    except PoseError as error:
        fail(str(error))
    except Exception as error:  # noqa: BLE001 (whatever the .blend makes Blender raise: one line)
        fail(f"pose: {type(error).__name__}: {str(error).strip().splitlines()[-1] if str(error).strip() else ''}")
    serve_loop(3, posed.count, last - first + 1, posed.compute, posed.rest)


class Parser(argparse.ArgumentParser):
    """Argument mistakes end with one line (the last line of stderr is what pmsc reports)."""

    def error(self, message):
        fail(message)


def main(argv):
    p = Parser(prog="pmsc_blender.py")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    s = sub.add_parser("sample", help="points on the scene's surfaces")
    s.add_argument("--out", required=True)
    s.add_argument("--count", type=int, required=True)
    s.add_argument("--seed", type=int, default=1)
    s.add_argument("--skip", default="", help="mesh objects not to sample, comma-separated")
    v = sub.add_parser("serve", help="an exec-protocol child")
    v.add_argument("--points", required=True, help="N x 6 .npy from `sample` (or your own)")
    v.add_argument("--frames", required=True, type=frame_range, help="the scene's frames FIRST-LAST")
    v.add_argument("--samples", type=int, default=64)
    v.add_argument("--light", default="direct,indirect", help="passes: direct, indirect or both")
    v.add_argument("--threads", type=int, default=1)
    v.add_argument("--seed", type=int, default=0, help="Cycles' seed (another seed: another draw of the noise)")
    v.add_argument("--set", action="append", default=[], metavar="PATH",
                   help="a property set every frame from --controls, as bpy.data's path (repeat for more)")
    v.add_argument("--controls", default="", metavar="TABLE.npy",
                   help="the --set properties' values: a row per frame, a column per number")
    o = sub.add_parser("pose", help="an exec-protocol child: a mesh's evaluated vertices, posed by its rig")
    o.add_argument("--object", required=True, help="the mesh object whose evaluated vertices are the points")
    o.add_argument("--action", default="", help="the action its armature plays (default: the one it has)")
    o.add_argument("--frames", required=True, type=frame_range, help="the scene's frames FIRST-LAST")
    o.add_argument("--space", choices=("root", "world"), default="root",
                   help="the points in the armature's root bone's space (default) or in world space")
    args = p.parse_args(argv)
    # Blender goes on with its default scene when the .blend it was given does not open.
    if not bpy.data.filepath:
        fail("Blender opened no .blend (a missing or unreadable file, or none given before --python)")
    if args.command == "sample":
        if args.count < 1:
            fail("--count must be at least 1")
        sample(args)
    elif args.command == "pose":
        pose(args)
    else:
        if args.samples < 1 or args.threads < 1:
            fail("--samples and --threads must be at least 1")
        if bool(args.set) != bool(args.controls):
            fail("--set and --controls go together")
        serve(args)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
