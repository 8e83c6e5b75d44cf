"""Builds a character posed by Blender's own rig from motion capture: a .blend for pmsc-blender pose.

Run by Blender:

    blender -b --python-exit-code 2 --python bvh_character.py -- --bvh TAKE.bvh[,TAKE2.bvh ...] \\
        --out character.blend [--scale 0.065] [--cage-levels 1] [--levels 2] [--smooth 8]

What it builds, from the first take's skeleton (its bones and their rest positions):
- the armature, as Blender's BVH importer makes it, with one action per take (named by the file's
  stem; the takes must share the skeleton, as a subject's CMU clips do);
- a body: Blender's Skin modifier around the skeleton (a radius per joint, by the joint's name),
  applied and subdivided --cage-levels times into the rig's cage mesh;
- skinning weights: each cage vertex takes its three nearest bones, weighted by the inverse fourth
  power of its distance to each bone's segment (smooth across the joints, deterministic);
- the modifier stack a production body carries, evaluated by Blender every frame: Armature (linear
  blend skinning), Corrective Smooth (--smooth iterations, rest shape from the cage: it restores
  the rest's detail where the skinning collapses it) and Subdivision Surface (--levels, viewport and
  render alike, so the evaluated mesh is the same in the background and in a render).
The points pmsc computes are the evaluated body's vertices; `pmsc-blender character.blend pose`
serves them (pmsc_blender.py). The object is named "Body", the armature "Rig".

Debian 12's Blender 3.4 BVH importer opens its file with mode 'rU', which its Python 3.11 no
longer accepts; this script gives the importer an `open` that drops the 'U' (the only change).

Fails with one line and exit code 2: a take that does not read, takes whose skeletons differ, bad
arguments.
"""
import argparse
import builtins
import os
import sys

import bpy
import numpy as np

# Radii of the body around each joint (metres at the default scale), by the first name part that
# matches: a plain human build, thick at the hips and chest, thin at the wrists.
RADII = (("Head", 0.095), ("Neck", 0.055), ("Spine1", 0.13), ("Spine", 0.13), ("LowerBack", 0.135),
         ("Hips", 0.14), ("HipJoint", 0.11), ("UpLeg", 0.085), ("Leg", 0.06), ("Foot", 0.045),
         ("Toe", 0.035), ("Shoulder", 0.06), ("ForeArm", 0.04), ("Arm", 0.05), ("Hand", 0.035),
         ("Finger", 0.02), ("Thumb", 0.015))


def fail(message):
    print("bvh_character.py: " + message, file=sys.stderr, flush=True)
    sys.exit(2)


def radius_of(name):
    for part, radius in RADII:
        if part in name:
            return radius
    return 0.05


def import_take(path, scale):
    """The take's armature object (its action named by the file's stem)."""
    import io_anim_bvh.import_bvh as importer
    importer.open = lambda f, mode="r", *a, **k: builtins.open(f, mode.replace("U", ""), *a, **k)
    # Blender's importer prints its own traceback for a file that is not BVH: check first.
    with builtins.open(path, "rb") as f:
        whole = f.read()
    if not whole.lstrip().startswith(b"HIERARCHY") or b"MOTION" not in whole:
        fail(f"{path}: not a BVH file (it must begin with HIERARCHY and hold a MOTION section)")
    before = set(bpy.data.objects)
    try:
        bpy.ops.import_anim.bvh(filepath=path, global_scale=scale, rotate_mode="NATIVE", axis_forward="-Z",
                                axis_up="Y", update_scene_fps=False, update_scene_duration=False)
    except (RuntimeError, ValueError, IndexError) as error:
        lines = [l for l in str(error).strip().splitlines() if l.strip() and not l.startswith("Location:")]
        fail(f"{path}: Blender's BVH importer failed ({lines[-1].strip() if lines else 'no reason given'})")
    made = [o for o in bpy.data.objects if o not in before and o.type == "ARMATURE"]
    if not made:
        fail(f"{path}: the BVH importer made no armature")
    arm = made[0]
    arm.animation_data.action.name = os.path.splitext(os.path.basename(path))[0]
    arm.animation_data.action.use_fake_user = True
    return arm


def skeleton(arm):
    """Joint positions (rest, world) and segments (joint, joint, bone name): each bone from its head
    to its children's heads, a leaf bone to its tail; coincident joints merged."""
    joints, segments = [], []

    def joint(p):
        for i, q in enumerate(joints):
            if np.linalg.norm(q - p) < 1e-6:
                return i
        joints.append(p)
        return len(joints) - 1

    for bone in arm.data.bones:
        head = joint(np.array(bone.head_local))
        ends = [np.array(c.head_local) for c in bone.children] or [np.array(bone.tail_local)]
        for end in ends:
            j = joint(end)
            if j != head:
                segments.append((head, j, bone.name))
    names = [""] * len(joints)
    for a, b, bone in segments:  # a joint is sized by the bone that starts there (else the one ending)
        names[b] = names[b] or bone
    for a, b, bone in segments:
        names[a] = bone
    return np.array(joints), segments, names


def body_cage(joints, segments, names, cage_levels):
    """The Skin modifier's body around the skeleton, applied, subdivided cage_levels times."""
    mesh = bpy.data.meshes.new("Body")
    mesh.from_pydata(joints.tolist(), [(a, b) for a, b, _ in segments], [])
    body = bpy.data.objects.new("Body", mesh)
    bpy.context.scene.collection.objects.link(body)
    bpy.context.view_layer.objects.active = body
    bpy.ops.object.modifier_add(type="SKIN")  # the operator adds the skin radii layer
    for i, v in enumerate(mesh.skin_vertices[0].data):
        r = radius_of(names[i])
        v.radius = (r, r)
    mesh.skin_vertices[0].data[0].use_root = True
    body.modifiers["Skin"].use_smooth_shade = True
    if cage_levels:
        sub = body.modifiers.new("Cage", "SUBSURF")
        sub.levels = sub.render_levels = cage_levels
    for modifier in list(body.modifiers):
        bpy.ops.object.modifier_apply(modifier=modifier.name)
    return body


def skin_weights(body, arm, joints, segments):
    """Vertex groups: each vertex's three nearest bone segments, by inverse fourth power of distance."""
    count = len(body.data.vertices)
    verts = np.empty(count * 3)
    body.data.vertices.foreach_get("co", verts)
    verts = verts.reshape(-1, 3)
    distance = np.empty((count, len(segments)))
    for s, (a, b, _) in enumerate(segments):
        pa, d = joints[a], joints[b] - joints[a]
        t = np.clip((verts - pa) @ d / (d @ d), 0, 1)
        distance[:, s] = np.linalg.norm(verts - (pa + t[:, None] * d), axis=1)
    nearest = np.argsort(distance, axis=1)[:, :3]
    w = 1.0 / np.maximum(np.take_along_axis(distance, nearest, axis=1), 1e-4) ** 4
    w /= w.sum(axis=1, keepdims=True)
    groups = {}
    for v in range(count):
        for s, weight in zip(nearest[v], w[v]):
            bone = segments[s][2]
            if bone not in groups:
                groups[bone] = body.vertex_groups.new(name=bone)
            groups[bone].add([v], float(weight), "ADD")
    body.parent = arm


def rig_stack(body, arm, levels, smooth):
    armature = body.modifiers.new("Armature", "ARMATURE")
    armature.object = arm
    corrective = body.modifiers.new("CorrectiveSmooth", "CORRECTIVE_SMOOTH")
    corrective.iterations = smooth
    corrective.rest_source = "ORCO"
    corrective.smooth_type = "LENGTH_WEIGHTED"
    subdivision = body.modifiers.new("Subdivision", "SUBSURF")
    subdivision.levels = subdivision.render_levels = levels


def main(argv):
    class Parser(argparse.ArgumentParser):
        def error(self, message):
            fail(message)

    p = Parser(prog="bvh_character.py")
    p.add_argument("--bvh", required=True, help="takes, comma-separated; the first gives the skeleton")
    p.add_argument("--out", required=True)
    p.add_argument("--scale", type=float, default=0.065, help="metres per BVH unit (CMU: about 0.065)")
    p.add_argument("--cage-levels", type=int, default=1)
    p.add_argument("--levels", type=int, default=2)
    p.add_argument("--smooth", type=int, default=8)
    args = p.parse_args(argv)
    if args.scale <= 0 or not 0 <= args.cage_levels <= 3 or not 0 <= args.levels <= 4 or args.smooth < 0:
        fail("--scale must be positive, --cage-levels 0 to 3, --levels 0 to 4, --smooth at least 0")
    takes = args.bvh.split(",")
    for path in takes:
        if not os.path.isfile(path):
            fail(f"cannot read '{path}'")
    stems = [os.path.splitext(os.path.basename(path))[0] for path in takes]
    if len(set(stems)) != len(stems):
        fail("two takes have the same name (an action is named by its file's stem): " + ", ".join(stems))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    arm = import_take(takes[0], args.scale)
    arm.name = arm.data.name = "Rig"
    bones = [b.name for b in arm.data.bones]
    for path in takes[1:]:
        other = import_take(path, args.scale)
        if [b.name for b in other.data.bones] != bones:
            fail(f"{path}: its skeleton's bones differ from {takes[0]}'s")
        data = other.data
        bpy.data.objects.remove(other)
        bpy.data.armatures.remove(data)
    arm.animation_data.action = bpy.data.actions[os.path.splitext(os.path.basename(takes[0]))[0]]
    joints, segments, names = skeleton(arm)
    body = body_cage(joints, segments, names, args.cage_levels)
    skin_weights(body, arm, joints, segments)
    rig_stack(body, arm, args.levels, args.smooth)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, int(arm.animation_data.action.frame_range[1])
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = body.evaluated_get(depsgraph)
    points = len(evaluated.to_mesh().vertices)
    evaluated.to_mesh_clear()
    tmp = args.out + ".partial.blend"
    try:
        bpy.ops.wm.save_as_mainfile(filepath=tmp)
        os.replace(tmp, args.out)
    except (RuntimeError, OSError) as error:
        if os.path.exists(tmp):
            os.remove(tmp)
        fail(f"cannot write '{args.out}': {str(error).strip().splitlines()[-1] if str(error).strip() else error}")
    actions = ", ".join(f"{a.name} ({int(a.frame_range[1])} frames)" for a in bpy.data.actions)
    print(f"bvh_character.py: wrote {args.out}: 'Body' ({len(body.data.vertices)} cage vertices, "
          f"{points} evaluated points) on 'Rig' ({len(bones)} bones); actions {actions}")


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
