# Runs inside Blender (Debian's `blender`, Cycles on the CPU): bakes the irradiance at every face
# corner of a glTF scene with Cycles, an independent path tracer, for scripts/cycles/check.sh.
#
#   blender -b --factory-startup --python scripts/cycles/bake_cycles.py -- IN.glb OUT.json \
#       [--samples 256] [--environment-color R,G,B] [--back-faces black|diffuse]
#
# What it bakes: Cycles' diffuse light (bake type DIFFUSE, passes DIRECT and INDIRECT, not
# COLOR) into a float colour attribute on the face corners, with every material replaced by a
# Lambert (Diffuse BSDF) of the glTF base colour factor and its emission, so that the light is
# what penumbra's solvers compute for the same scene (penumbra's F0 = 0.04 specular layer of
# a dielectric is left out: a few percent). Cycles' diffuse light is the reflected radiance of a white
# surface, E / π, so each value is multiplied by π: irradiance in penumbra's units (lux for
# emission and skies given in nits; scripts/cycles/check.sh checks that scale on a plane under
# a constant sky, where E = π L).
#
# OUT.json: {"corners": [[node, material, x, y, z, weight, r, g, b], ...]}: the glTF node and
# material indices (check.sh names every node n<index> and every material m<index> before the
# import, so Blender's object and material names carry them), the corner's position in the
# mesh's own glTF space (Blender's +Z up turned back to glTF's +Y up), a third of its face's
# area (the weight a vertex's corners are merged with) and the irradiance.
import json
import math
import struct
import sys

import bmesh
import bpy
import numpy
from mathutils import Vector

# Debian 12's glTF importer (Blender 3.4) still says numpy.bool, which numpy 1.24 removed.
if not hasattr(numpy, "bool") or numpy.bool is not bool:
    numpy.bool = bool

args = sys.argv[sys.argv.index("--") + 1:]
if len(args) < 2:
    sys.exit("usage: blender -b --python bake_cycles.py -- IN.glb OUT.json [--samples N] "
             "[--environment-color r,g,b]")
source, out = args[0], args[1]
samples, sky, back = 256, (0.0, 0.0, 0.0), "diffuse"
i = 2
while i < len(args):
    if args[i] == "--samples":
        samples = int(args[i + 1])
    elif args[i] == "--environment-color":
        sky = tuple(float(x) for x in args[i + 1].split(","))
    elif args[i] == "--back-faces":
        back = args[i + 1]
    else:
        sys.exit("unknown option " + args[i])
    i += 2

bpy.ops.wm.read_factory_settings(use_empty=True)
# RAW: light strengths as the file has them (punctual lights are not converted).
bpy.ops.import_scene.gltf(filepath=source, convert_lighting_mode="RAW")

scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.use_denoising = False
scene.cycles.max_bounces = 64
scene.cycles.diffuse_bounces = 64
scene.cycles.sample_clamp_direct = 0.0
scene.cycles.sample_clamp_indirect = 0.0

world = bpy.data.worlds.new("sky")
world.use_nodes = True
background = world.node_tree.nodes["Background"]
background.inputs["Color"].default_value = (*sky, 1.0)
background.inputs["Strength"].default_value = 1.0
scene.world = world

# Lambert materials of the glTF base colour factor (a texture's mean is not taken) and its
# emission, read from the file itself (material j is m<j>): the importer turns extensions
# such as KHR_materials_pbrSpecularGlossiness into node trees of their own (a glossy layer),
# which penumbra does not read.
with open(source, "rb") as f:
    data = f.read()
doc = json.loads(data[20:20 + struct.unpack_from("<I", data, 12)[0]])
for material in bpy.data.materials:
    try:
        spec = doc["materials"][int(material.name.split(".")[0][1:])]
    except (ValueError, IndexError, KeyError):
        continue
    pbr = spec.get("pbrMetallicRoughness", {})
    if "baseColorTexture" in pbr:
        print("bake_cycles: material %s: a base colour texture; its factor is used" % material.name)
    colour = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
    emission = spec.get("emissiveFactor", [0.0, 0.0, 0.0])
    strength = spec.get("extensions", {}).get("KHR_materials_emissive_strength", {}).get(
        "emissiveStrength", 1.0)
    material.use_nodes = True
    nodes = material.node_tree.nodes
    nodes.clear()
    output = nodes.new("ShaderNodeOutputMaterial")
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*colour[:3], 1.0)
    shader = diffuse.outputs["BSDF"]
    if back == "black":  # a face's back absorbs, as penumbra's surfaces do
        backfacing = nodes.new("ShaderNodeNewGeometry")
        black = nodes.new("ShaderNodeBsdfDiffuse")
        black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        mix = nodes.new("ShaderNodeMixShader")
        material.node_tree.links.new(backfacing.outputs["Backfacing"], mix.inputs["Fac"])
        material.node_tree.links.new(diffuse.outputs["BSDF"], mix.inputs[1])
        material.node_tree.links.new(black.outputs["BSDF"], mix.inputs[2])
        shader = mix.outputs["Shader"]
    # Light passing straight through (penumbra's Material::transmittance): alpha coverage c
    # (BLEND: the factor's alpha; MASK: by the cutoff) and KHR_materials_transmission's t give
    # T = (1 - c) + c t base, a Transparent BSDF of that colour beside the diffuse of c (1 - t).
    alpha = colour[3] if len(colour) > 3 else 1.0
    mode = spec.get("alphaMode", "OPAQUE")
    cover = alpha if mode == "BLEND" else (
        (1.0 if alpha >= spec.get("alphaCutoff", 0.5) else 0.0) if mode == "MASK" else 1.0)
    trans = spec.get("extensions", {}).get("KHR_materials_transmission", {}).get(
        "transmissionFactor", 0.0)
    if cover < 1.0 or trans > 0.0:
        passing = nodes.new("ShaderNodeBsdfTransparent")
        passing.inputs["Color"].default_value = (
            *[(1.0 - cover) + cover * trans * c for c in colour[:3]], 1.0)
        diffuse.inputs["Color"].default_value = (
            *[c * cover * (1.0 - trans) for c in colour[:3]], 1.0)
        add = nodes.new("ShaderNodeAddShader")
        material.node_tree.links.new(shader, add.inputs[0])
        material.node_tree.links.new(passing.outputs["BSDF"], add.inputs[1])
        shader = add.outputs["Shader"]
    if max(emission) * strength > 0.0:
        emit = nodes.new("ShaderNodeEmission")
        emit.inputs["Color"].default_value = (*emission, 1.0)
        emit.inputs["Strength"].default_value = strength
        add = nodes.new("ShaderNodeAddShader")
        material.node_tree.links.new(shader, add.inputs[0])
        material.node_tree.links.new(emit.outputs["Emission"], add.inputs[1])
        shader = add.outputs["Shader"]
    material.node_tree.links.new(shader, output.inputs["Surface"])

# glTF's directional lights are exact directions (penumbra's too); Blender gives a new sun
# the real one's 0.53°, which softens every sun shadow's edge.
for light in bpy.data.lights:
    if light.type == "SUN":
        light.angle = 0.0

meshes = [o for o in scene.objects if o.type == "MESH"]
bpy.ops.object.select_all(action="DESELECT")
for o in meshes:
    o.select_set(True)
bpy.context.view_layer.objects.active = meshes[0]
# A mesh two nodes share gets a copy each: each object bakes its own light.
bpy.ops.object.make_single_user(object=True, obdata=True)

# Where a vertex's light is estimated, as penumbra does (rays/ray_scene.h,
# VertexEstimatePoints): each face corner moved 1e-3 × the scene's diameter into its face,
# towards the centroids of the vertex's triangles in that plane, at most half way to the
# nearest of them. Cycles bakes at the exact
# corners otherwise, and an IFC part's corners mostly lie where it meets another part, inside
# it or on its back, black. The geometry stays as it is: a probe copy of each mesh, every
# face's corners its own vertices placed there (and lifted 1e-4 × the diameter off the face,
# clear of the surface it lies on), is baked, invisible to every ray.
lo = Vector((math.inf,) * 3)
hi = -lo
for o in meshes:
    for v in o.data.vertices:
        w = o.matrix_world @ v.co
        lo = Vector(map(min, lo, w))
        hi = Vector(map(max, hi, w))
diameter = (hi - lo).length
inset, lift = 1e-3 * diameter, 1e-4 * diameter
same_plane = 0.9999  # cos 0.81°, as penumbra's flat normals

probes = []
for o in meshes:
    mesh, world = o.data, o.matrix_world
    turn = world.to_3x3().inverted().transposed()
    positions = [world @ v.co for v in mesh.vertices]
    normals = [(turn @ p.normal).normalized() for p in mesh.polygons]
    towards = {}  # (vertex, plane) -> sum of unit vectors to its triangles' centroids
    reach = {}    # (vertex, plane) -> how far it may move
    planes = {}   # vertex -> [(plane normal, key)]
    corner_key = []
    for p in mesh.polygons:
        centre = sum((positions[v] for v in p.vertices), Vector()) / len(p.vertices)
        keys = []
        for v in p.vertices:
            group = next((k for n, k in planes.get(v, []) if n.dot(normals[p.index]) >= same_plane),
                         None)
            if group is None:
                group = (v, len(planes.get(v, [])))
                planes.setdefault(v, []).append((normals[p.index], group))
            d = centre - positions[v]
            if d.length > 0:
                towards[group] = towards.get(group, Vector()) + d.normalized()
                reach[group] = min(reach.get(group, inset), 0.5 * d.length)
            keys.append(group)
        corner_key.append(keys)
    probe = o.copy()
    probe.data = mesh.copy()
    scene.collection.objects.link(probe)
    bm = bmesh.new()
    bm.from_mesh(probe.data)
    bm.faces.ensure_lookup_table()
    bmesh.ops.split_edges(bm, edges=bm.edges[:])
    bm.faces.ensure_lookup_table()
    inverse = world.inverted()
    for f in bm.faces:
        n = normals[f.index]
        for corner, loop in enumerate(f.loops):
            group = corner_key[f.index][corner]
            v = group[0]
            d = towards.get(group, Vector())
            d = d - d.dot(n) * n
            step = min(1.0, d.length) * reach.get(group, inset)
            point = positions[v] + (step * d.normalized() if d.length > 1e-6 else Vector())
            loop.vert.co = inverse @ (point + lift * n)
    bm.to_mesh(probe.data)
    bm.free()
    for flag in ("visible_diffuse", "visible_glossy", "visible_transmission",
                 "visible_volume_scatter", "visible_shadow"):
        setattr(probe, flag, False)
    probes.append((o, probe))

bpy.ops.object.select_all(action="DESELECT")
for _, probe in probes:
    probe.select_set(True)
    attribute = probe.data.color_attributes.new("irradiance", "FLOAT_COLOR", "CORNER")
    probe.data.color_attributes.active_color = attribute
bpy.context.view_layer.objects.active = probes[0][1]
scene.render.bake.target = "VERTEX_COLORS"
bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT"}, target="VERTEX_COLORS")

corners = []
for o, probe in probes:
    node = int(o.name.split(".")[0][1:])
    mesh = o.data
    values = probe.data.color_attributes["irradiance"].data
    assert len(probe.data.polygons) == len(mesh.polygons)
    for polygon, baked in zip(mesh.polygons, probe.data.polygons):
        slot = o.material_slots[polygon.material_index] if o.material_slots else None
        material = int(slot.material.name.split(".")[0][1:]) if slot and slot.material else -1
        weight = polygon.area / polygon.loop_total
        for loop, baked_loop in zip(polygon.loop_indices, baked.loop_indices):
            co = mesh.vertices[mesh.loops[loop].vertex_index].co
            c = values[baked_loop].color
            # Blender's importer turns glTF's +Y up to +Z up: (x, y, z) -> (x, -z, y).
            corners.append([node, material, co.x, co.z, -co.y, weight,
                            c[0] * math.pi, c[1] * math.pi, c[2] * math.pi])
with open(out, "w") as f:
    json.dump({"samples": samples, "corners": corners}, f)
print("bake_cycles: %d corners of %d objects -> %s" % (len(corners), len(meshes), out))
