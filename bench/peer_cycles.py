#!/usr/bin/env python3
"""Renders a glTF scene with Blender Cycles (PyPI `bpy`, CPU device) as `icrender --lambertian`
sees it, at several sample counts, raw and with the OpenImageDenoise denoiser; run by
bench/peers.py in its own process.

    python3 bench/peer_cycles.py JOB.json

JOB: {"scene", "view", "width", "height", "ab", "spp": [..], "denoised_spp": [..], "out",
"prefix", "threads"}. Prints one JSON line per render: {"spp", "denoised", "seconds",
"cpu_seconds" (the process's, all threads), "exr"}.

The scene is built from the glTF's arrays (not Blender's importer, which would convert axes
and light units): two-sided diffuse (roughness 0, Lambertian) of the base colour, textures
kept, alpha-blended materials mixed with transparency by their alpha, emitters front-side
emission, point lights of the same radiant intensity (a Cycles point light of power P has
intensity P / 4 pi, checked against I cos / d^2), black world. Max bounces = -ab, clamping,
caustics filtering and adaptive sampling off, box pixel filter one pixel wide. Persistent data
keeps the BVH between renders, and a 1-sample render first builds it, so the times are
rendering alone, as icrender's render_s is.
"""

import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import gltf_scene  # noqa: E402


def material(bpy, index, mat):
    m = bpy.data.materials.new(f"m{index}_{mat['name']}")
    m.use_nodes = True
    nodes, links = m.node_tree.nodes, m.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Roughness"].default_value = 0.0
    diffuse.inputs["Color"].default_value = (*mat["base_color"], 1.0)
    if mat["texture"]:
        if any(abs(c - 1.0) > 1e-6 for c in mat["base_color"]):
            raise gltf_scene.UnsupportedScene(f"material {mat['name']}: texture times a colour factor")
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images.load(mat["texture"])
        tex.interpolation = "Linear"
        tex.extension = "REPEAT"
        links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    shader = diffuse.outputs["BSDF"]
    if max(mat["emission"]) > 0:
        # Emission from the front side only: the back face gets a black emitter.
        strength = max(mat["emission"])
        emission = nodes.new("ShaderNodeEmission")
        emission.inputs["Color"].default_value = (*[c / strength for c in mat["emission"]], 1.0)
        emission.inputs["Strength"].default_value = strength
        black = nodes.new("ShaderNodeEmission")
        black.inputs["Strength"].default_value = 0.0
        geometry = nodes.new("ShaderNodeNewGeometry")
        sides = nodes.new("ShaderNodeMixShader")
        links.new(geometry.outputs["Backfacing"], sides.inputs["Fac"])
        links.new(emission.outputs["Emission"], sides.inputs[1])
        links.new(black.outputs["Emission"], sides.inputs[2])
        add = nodes.new("ShaderNodeAddShader")
        links.new(shader, add.inputs[0])
        links.new(sides.outputs["Shader"], add.inputs[1])
        shader = add.outputs["Shader"]
        m.cycles.emission_sampling = "FRONT"
    else:
        m.cycles.emission_sampling = "NONE"
    if mat["alpha_mode"] == "BLEND" and mat["alpha"] < 1.0:
        transparent = nodes.new("ShaderNodeBsdfTransparent")
        mix = nodes.new("ShaderNodeMixShader")
        mix.inputs["Fac"].default_value = mat["alpha"]
        links.new(transparent.outputs["BSDF"], mix.inputs[1])
        links.new(shader, mix.inputs[2])
        shader = mix.outputs["Shader"]
    elif mat["alpha_mode"] == "MASK":
        raise gltf_scene.UnsupportedScene("alpha-masked materials")
    links.new(shader, out.inputs["Surface"])
    return m


def mesh_object(bpy, k, mesh, blender_material):
    positions, indices = mesh["positions"], mesh["indices"]
    me = bpy.data.meshes.new(f"mesh{k}")
    me.vertices.add(len(positions))
    me.vertices.foreach_set("co", positions.astype(np.float32).ravel())
    me.loops.add(indices.size)
    me.loops.foreach_set("vertex_index", indices.astype(np.int32).ravel())
    me.polygons.add(len(indices))
    me.polygons.foreach_set("loop_start", np.arange(0, indices.size, 3, dtype=np.int32))
    me.update(calc_edges=True)
    me.validate(clean_customdata=False)
    # Flat faces, as glTF without NORMAL asks (and as icrender and Mitsuba shade): smooth
    # vertex normals averaged over a box's corners turned half a face black.
    me.polygons.foreach_set("use_smooth", np.zeros(len(indices), dtype=bool))
    if mesh["uv"] is not None:
        layer = me.uv_layers.new(name="UVMap")
        uv = mesh["uv"][indices.ravel()].astype(np.float32)
        uv[:, 1] = 1.0 - uv[:, 1]  # glTF's v runs down the image, Blender's up
        layer.data.foreach_set("uv", uv.ravel())
    me.materials.append(blender_material)
    obj = bpy.data.objects.new(f"mesh{k}", me)
    bpy.context.scene.collection.objects.link(obj)


def camera(bpy, view, width, height):
    right, up, forward = gltf_scene.camera_frame(view)
    cam = bpy.data.cameras.new("camera")
    cam.sensor_fit = "HORIZONTAL"
    cam.angle = math.radians(view["horizontal"])
    cam.clip_start = 1e-4
    cam.clip_end = 1e7
    obj = bpy.data.objects.new("camera", cam)
    from mathutils import Matrix

    m = Matrix.Identity(4)
    for row in range(3):
        m[row][0], m[row][1], m[row][2], m[row][3] = right[row], up[row], -forward[row], view["position"][row]
    obj.matrix_world = m
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.scene.camera = obj


def build(bpy, job):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = gltf_scene.load(job["scene"])
    materials = [material(bpy, i, m) for i, m in enumerate(scene["materials"])]
    for k, mesh in enumerate(scene["meshes"]):
        mesh_object(bpy, k, mesh, materials[mesh["material"]])
    for k, light in enumerate(scene["point_lights"]):
        power = max(light["intensity"])
        data = bpy.data.lights.new(f"light{k}", "POINT")
        data.energy = 4.0 * math.pi * power
        data.color = [c / power for c in light["intensity"]]
        data.shadow_soft_size = 0.0
        obj = bpy.data.objects.new(f"light{k}", data)
        obj.location = light["position"]
        bpy.context.scene.collection.objects.link(obj)
    camera(bpy, gltf_scene.parse_view(job["view"]), job["width"], job["height"])
    s = bpy.context.scene
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    s.world = world
    s.render.engine = "CYCLES"
    s.cycles.device = "CPU"
    s.render.threads_mode = "FIXED"
    s.render.threads = job.get("threads", os.cpu_count())
    s.render.resolution_x, s.render.resolution_y = job["width"], job["height"]
    s.render.resolution_percentage = 100
    s.render.use_persistent_data = True
    s.render.film_transparent = False
    s.cycles.pixel_filter_type = "BOX"
    s.cycles.filter_width = 1.0
    ab = int(job["ab"])
    s.cycles.max_bounces = ab
    s.cycles.diffuse_bounces = ab
    s.cycles.glossy_bounces = ab
    s.cycles.transmission_bounces = ab
    s.cycles.volume_bounces = 0
    s.cycles.transparent_max_bounces = 16
    s.cycles.sample_clamp_direct = 0.0
    s.cycles.sample_clamp_indirect = 0.0
    s.cycles.caustics_reflective = False
    s.cycles.caustics_refractive = False
    s.cycles.blur_glossy = 0.0
    s.cycles.use_adaptive_sampling = False
    s.cycles.seed = 1
    s.view_settings.view_transform = "Standard"
    s.render.image_settings.file_format = "OPEN_EXR"
    s.render.image_settings.color_depth = "32"


def render(bpy, job, spp, denoised):
    s = bpy.context.scene
    s.cycles.samples = spp
    s.cycles.use_denoising = denoised
    if denoised:
        s.cycles.denoiser = "OPENIMAGEDENOISE"
        s.cycles.denoising_input_passes = "RGB_ALBEDO_NORMAL"
    tag = "cycles-oidn" if denoised else "cycles"
    exr = os.path.join(job["out"], f"{job['prefix']}-{tag}-{spp}spp.exr")
    s.render.filepath = exr
    start, cpu_start = time.perf_counter(), time.process_time()
    bpy.ops.render.render(write_still=False)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    bpy.data.images["Render Result"].save_render(exr)
    return seconds, cpu, exr


def main():
    with open(sys.argv[1]) as f:
        job = json.load(f)
    import bpy

    build(bpy, job)
    render(bpy, job, 1, False)  # builds the BVH and compiles the kernels (kept: persistent data)
    for spp in job["spp"]:
        seconds, cpu, exr = render(bpy, job, spp, False)
        print(json.dumps({"spp": spp, "denoised": False, "seconds": seconds, "cpu_seconds": cpu, "exr": exr}),
              flush=True)
    for spp in job.get("denoised_spp", []):
        seconds, cpu, exr = render(bpy, job, spp, True)
        print(json.dumps({"spp": spp, "denoised": True, "seconds": seconds, "cpu_seconds": cpu, "exr": exr}),
              flush=True)


if __name__ == "__main__":
    main()
