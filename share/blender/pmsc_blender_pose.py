"""pmsc_blender.py's `pose`: the evaluated vertices of a mesh posed by the scene's own rig.

The points are the vertices of the object's evaluated mesh (its whole modifier stack, as Blender
evaluates it in the scene's view layer: the modifiers' viewport settings, which bvh_character.py
sets equal to the render's), in the root bone's space or world space; pmsc's frame f is the
scene's frame FIRST + f, with the armature playing --action. A call for every point is Blender's own evaluation of the object.

A call for some points (the key points, the sentinels, what a miss needs) evaluates only what they
depend on. Decision: when the stack ends in Subdivision Surface modifiers, the child evaluates the
stack before them with Blender (the deforming part: armature, corrective smooth, ... on the cage)
and the trailing subdivisions for the asked points only, by their stencils: a subdivided vertex is
a fixed linear combination of the cage's vertices (Catmull-Clark, limit surface or not, depends on
the cage's topology alone), so its stencil is measured once from Blender's own modifier (the cage
set to one-hot coordinates, three vertices per evaluation) and a call costs the cage's deformation
plus one small product per point. Why: the subdivision is most of a character's evaluation (it
makes 16 points of each cage vertex at two levels), and a point depends on it only through ~25
cage vertices. At start the child checks the stencils against Blender's full evaluation on three
frames; where they differ by more than 1e-5 of the mesh's size (a stack whose end is not linear
in the cage after all), every call evaluates the whole stack and stderr says so.
"""
import time

import bpy
import numpy as np

LINEAR_TAIL = ("SUBSURF",)    # modifiers whose output is linear in their input's vertices
STENCIL_MATCH = 1e-5          # largest stencil error accepted, as a share of the mesh's diagonal


class PoseError(Exception):
    """What the .blend does not have: one line, exit code 2 before the hello."""


def world_vertices(obj, depsgraph):
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    evaluated.to_mesh_clear()
    m = np.array(evaluated.matrix_world)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def copy_modifier(source, target):
    made = target.modifiers.new(source.name, source.type)
    for prop in source.bl_rna.properties:
        if not prop.is_readonly and prop.identifier not in ("name", "type"):
            setattr(made, prop.identifier, getattr(source, prop.identifier))
    return made


class Pose:
    """The posed object, its cage (the stack before the trailing subdivisions) in a scene of its
    own, and the subdivided vertices' stencils over the cage."""

    def __init__(self, name, action, space, first, frames, log):
        self.scene, self.first, self.log = bpy.context.scene, first, log
        self.body = bpy.data.objects.get(name)
        if self.body is None or self.body.type != "MESH":
            raise PoseError(f"the scene has no mesh object named '{name}'")
        self.rigs = [m.object for m in self.body.modifiers if m.type == "ARMATURE" and m.object]
        if action:
            self._play(action)
        self.root = None
        if space == "root":
            if not self.rigs or not self.rigs[0].pose.bones:
                raise PoseError(f"'{name}' has no Armature modifier whose root bone --space root could follow")
            self.root = next(b for b in self.rigs[0].pose.bones if b.parent is None)
        self.scene.frame_set(first)
        self.count = len(world_vertices(self.body, self._depsgraph(self.scene)))
        self.stencil, self.cage_frame = None, None
        tail = 0
        for modifier in reversed(self.body.modifiers):
            if modifier.type not in LINEAR_TAIL or not modifier.show_viewport:
                break
            tail += 1
        if tail:
            began = time.perf_counter()
            self._cage_scene(tail)
            # The stencils index the cage's vertices: a modifier before the subdivisions that
            # changes the topology (mirror, solidify, weld) leaves the whole stack to every call.
            cage_count = len(world_vertices(self.cage, self._depsgraph(self.cage_scene)))
            if cage_count != len(self.body.data.vertices) or not self._measure_stencils(tail):
                self.log("the modifiers before the subdivisions change the mesh's topology: "
                         "every call evaluates the whole stack")
            else:
                self._check([0, frames // 2, frames - 1], began)

    def _play(self, action):
        if action not in bpy.data.actions:
            raise PoseError(f"the .blend has no action named '{action}' "
                            f"(it has {', '.join(sorted(a.name for a in bpy.data.actions)) or 'none'})")
        if not self.rigs:
            raise PoseError(f"'{self.body.name}' has no Armature modifier to play --action on")
        for rig in self.rigs:
            rig.animation_data_create().action = bpy.data.actions[action]

    @staticmethod
    def _depsgraph(scene):
        if scene.view_layers[0].depsgraph is None:  # a new scene has none until it is evaluated
            scene.frame_set(scene.frame_current)
        return scene.view_layers[0].depsgraph

    def _cage_scene(self, tail):
        """A scene holding a copy of the object without its trailing subdivisions; the objects its
        modifiers read (the armature, ...) are linked into it, so it poses as the object does."""
        self.cage_scene = bpy.data.scenes.new("pmsc_cage")
        self.cage = self.body.copy()
        self.cage.name = "pmsc_cage"
        for modifier in list(self.cage.modifiers)[-tail:]:
            self.cage.modifiers.remove(modifier)
        self.cage_scene.collection.objects.link(self.cage)
        for modifier in self.body.modifiers:
            for attr in ("object", "target", "auxiliary_target"):
                other = getattr(modifier, attr, None)
                if isinstance(other, bpy.types.Object) and other.name not in self.cage_scene.objects:
                    self.cage_scene.collection.objects.link(other)
        if self.body.parent and self.body.parent.name not in self.cage_scene.objects:
            self.cage_scene.collection.objects.link(self.body.parent)

    def _measure_stencils(self, tail):
        """Each subdivided vertex's weights over the cage's vertices, from Blender's own modifiers
        on one-hot cage coordinates (x, y and z carry three cage vertices per evaluation). False
        when the subdivisions of the cage alone do not make the object's points."""
        cage_count = len(self.cage.data.vertices)
        probe = bpy.data.objects.new("pmsc_stencil", self.body.data.copy())
        for modifier in list(self.body.modifiers)[-tail:]:
            copy_modifier(modifier, probe)
        scene = bpy.data.scenes.new("pmsc_stencil")
        scene.collection.objects.link(probe)
        depsgraph = self._depsgraph(scene)
        columns, rows, weights = [], [], []
        co = np.zeros((cage_count, 3))
        for j in range(0, cage_count, 3):
            co[:] = 0
            for c in range(min(3, cage_count - j)):
                co[j + c, c] = 1.0
            probe.data.vertices.foreach_set("co", co.ravel())
            probe.data.update()
            depsgraph.update()
            out = world_vertices(probe, depsgraph) - np.array(probe.matrix_world)[:3, 3]
            if len(out) != self.count:
                self._remove(scene, probe)
                return False
            for c in range(min(3, cage_count - j)):
                hit = np.flatnonzero(np.abs(out[:, c]) > 1e-9)
                rows.append(hit)
                columns.append(np.full(len(hit), j + c))
                weights.append(out[hit, c])
        rows, columns, weights = np.concatenate(rows), np.concatenate(columns), np.concatenate(weights)
        order = np.argsort(rows, kind="stable")
        rows, columns, weights = rows[order], columns[order], weights[order]
        width = int(np.bincount(rows, minlength=self.count).max())
        slot = np.arange(len(rows)) - np.searchsorted(rows, rows)
        self.stencil_index = np.zeros((self.count, width), dtype=np.int64)
        self.stencil_weight = np.zeros((self.count, width))
        self.stencil_index[rows, slot] = columns
        self.stencil_weight[rows, slot] = weights
        self.stencil = width
        self._remove(scene, probe)
        return True

    @staticmethod
    def _remove(scene, probe):
        bpy.data.scenes.remove(scene)
        mesh = probe.data
        bpy.data.objects.remove(probe)
        bpy.data.meshes.remove(mesh)

    def _subset(self, frame, ids):
        # A frame's calls (its keys, its sentinels, the regions a blend needs) share one evaluation
        # of the cage: the child is deterministic, so the last frame's cage is kept.
        if self.cage_frame != frame:
            self.cage_frame = None
            self.cage_scene.frame_set(self.first + frame)
            self.cage_values = self._to_space(world_vertices(self.cage, self._depsgraph(self.cage_scene)),
                                              self.cage_scene)
            self.cage_frame = frame
        return np.einsum("pw,pwc->pc", self.stencil_weight[ids], self.cage_values[self.stencil_index[ids]])

    def _full(self, frame):
        self.scene.frame_set(self.first + frame)
        values = world_vertices(self.body, self._depsgraph(self.scene))
        if len(values) != self.count:
            raise ValueError(f"the evaluated mesh has {len(values)} vertices at frame {frame}, not {self.count}")
        return values

    def _check(self, frames, began):
        ids = np.arange(self.count)
        worst, size = 0.0, 0.0
        for frame in sorted(set(frames)):
            full = self._to_space(self._full(frame), self.scene)
            size = max(size, float(np.linalg.norm(full.max(0) - full.min(0))))
            worst = max(worst, float(np.abs(self._subset(frame, ids) - full).max()))
        if worst > STENCIL_MATCH * size:
            self.log(f"the stencils differ from the full evaluation by {worst:.3g} (mesh size {size:.3g}): "
                     "every call evaluates the whole stack")
            self.stencil = None
        else:
            self.log(f"{self.count} points, {len(self.cage.data.vertices)} cage vertices, stencils of up to "
                     f"{self.stencil} weights, within {worst:.2g} of the full evaluation "
                     f"(set-up {time.perf_counter() - began:.2f} s)")

    def _to_space(self, values, scene):
        """World space, or the root bone's space (its pose in `scene`'s evaluation of the frame)."""
        if self.root is None:
            return values
        rig = self.rigs[0].evaluated_get(self._depsgraph(scene))
        m = np.linalg.inv(np.array(rig.matrix_world @ rig.pose.bones[self.root.name].matrix))
        return values @ m[:3, :3].T + m[:3, 3]

    def compute(self, frame, ids):
        if self.stencil is None or len(ids) == self.count:
            return self._to_space(self._full(frame), self.scene)[ids]
        return self._subset(frame, ids)

    def rest(self):
        """Every point at the armatures' rest position (in the chosen space): where the points are,
        for `pmsc train --positions`."""
        for rig in self.rigs:
            rig.data.pose_position = "REST"
        try:
            self.scene.frame_set(self.first)
            return self._to_space(world_vertices(self.body, self._depsgraph(self.scene)), self.scene)
        finally:  # the next frame is posed whatever happened here
            for rig in self.rigs:
                rig.data.pose_position = "POSE"
