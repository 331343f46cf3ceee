"""Imports a BVH in Blender (run by `make bvh-blender`, inside Blender: blender -b --python THIS -- FILE.bvh) and
prints what an animator sees: the frame count, and each limb's rest direction in Blender's world (Z up, the
front view looking along +Y at a character that faces -Y)."""
import builtins
import sys

import bpy

path = sys.argv[sys.argv.index("--") + 1]
_open = builtins.open
# Debian's Blender 3.4 runs on Python 3.11, whose open() no longer takes the mode "rU" its BVH importer uses
builtins.open = lambda file, mode="r", *a, **k: _open(file, mode.replace("U", ""), *a, **k)
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath=path, axis_forward="-Z", axis_up="Y", update_scene_fps=True,
                        update_scene_duration=True)
arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
action = arm.animation_data.action
first, last = (int(v) for v in action.frame_range)
print(f"{path}: armature {arm.name!r}, {len(arm.data.bones)} bones, frames {first}-{last} ({last - first + 1})")
for bone in arm.data.bones:
    if bone.parent is None or bone.name.lower().startswith(("spine", "neck", "head", "hips", "pelvis")):
        continue
    d = (arm.matrix_world.to_3x3() @ (bone.tail_local - bone.head_local)).normalized()
    side = "lateral" if abs(d.x) > 0.9 else "down" if d.z < -0.9 else "forward" if d.y < -0.6 else "other"
    print(f"  {bone.name:16s} rest direction ({d.x:+.2f}, {d.y:+.2f}, {d.z:+.2f})  {side}")
