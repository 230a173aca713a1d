#!/usr/bin/env python3
"""Renders a glTF scene with Mitsuba 3 (PyPI `mitsuba`, variant scalar_rgb) as `icrender
--lambertian` sees it, at several sample counts; run by bench/peers.py in its own process.

    python3 bench/peer_mitsuba.py JOB.json

JOB: {"scene", "view" (icrender's -vt.. options), "width", "height", "ab", "spp": [..],
"out": folder, "prefix", "sampler"}. Prints one JSON line per render:
{"spp", "seconds", "cpu_seconds", "exr"}; times are mi.render's alone (the scene and its BVH are
built before), cpu_seconds the process's CPU time over it (all threads).

The scene: every material a two-sided diffuse of its base colour (texture kept), alpha-blended
ones a mask of their alpha, emitters one-sided area lights of their emission, point lights
as Mitsuba point lights of the same radiant intensity; integrator `path` with max_depth =
-ab + 2 (camera ray, direct light, -ab bounces); box pixel filter one pixel wide.
"""

import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import gltf_scene  # noqa: E402


def write_ply(path, positions, indices, uv):
    """Binary little-endian PLY of a triangle mesh (with u, v per vertex when given)."""
    used = np.unique(indices)
    remap = np.full(len(positions), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    faces = remap[indices].astype(np.int32)
    vertex_fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if uv is not None:
        vertex_fields += [("u", "<f4"), ("v", "<f4")]
    vertices = np.empty(len(used), dtype=vertex_fields)
    for axis, name in enumerate("xyz"):
        vertices[name] = positions[used, axis]
    if uv is not None:
        vertices["u"], vertices["v"] = uv[used, 0], uv[used, 1]
    face_records = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face_records["n"] = 3
    face_records["i"] = faces
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vertices)}"]
    header += [f"property float {name}" for name, _ in vertex_fields]
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode())
        f.write(vertices.tobytes())
        f.write(face_records.tobytes())


def bsdf(material):
    reflectance = ({"type": "bitmap", "filename": material["texture"]} if material["texture"]
                   else {"type": "rgb", "value": material["base_color"]})
    if material["texture"] and any(abs(c - 1.0) > 1e-6 for c in material["base_color"]):
        raise gltf_scene.UnsupportedScene(f"material {material['name']}: texture times a colour factor")
    surface = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": reflectance}}
    if material["alpha_mode"] == "BLEND" and material["alpha"] < 1.0:
        surface = {"type": "mask", "opacity": {"type": "rgb", "value": [material["alpha"]] * 3}, "bsdf": surface}
    elif material["alpha_mode"] == "MASK":
        raise gltf_scene.UnsupportedScene("alpha-masked materials")
    return surface


def scene_dict(job, work):
    import mitsuba as mi

    scene = gltf_scene.load(job["scene"])
    view = gltf_scene.parse_view(job["view"])
    position = np.array(view["position"])
    right, up, forward = gltf_scene.camera_frame(view)
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(job["ab"]) + 2},
        "sensor": {
            "type": "perspective",
            "fov": view["horizontal"],
            "fov_axis": "x",
            "to_world": mi.ScalarTransform4f().look_at(origin=position.tolist(),
                                                       target=(position + forward).tolist(), up=up.tolist()),
            "film": {"type": "hdrfilm", "width": job["width"], "height": job["height"],
                     "rfilter": {"type": "box"}, "pixel_format": "rgb", "component_format": "float32"},
            "sampler": {"type": job.get("sampler", "independent"), "sample_count": 1},
        },
    }
    for i, mat in enumerate(scene["materials"]):
        d[f"bsdf{i}"] = dict(bsdf(mat), id=f"bsdf{i}")
    for k, mesh in enumerate(scene["meshes"]):
        mat = scene["materials"][mesh["material"]]
        path = os.path.join(work, f"mesh{k}.ply")
        write_ply(path, mesh["positions"], mesh["indices"], mesh["uv"] if mat["texture"] else None)
        shape = {"type": "ply", "filename": path, "face_normals": True,
                 "bsdf": {"type": "ref", "id": f"bsdf{mesh['material']}"}}
        if max(mat["emission"]) > 0:
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": mat["emission"]}}
        d[f"mesh{k}"] = shape
    for k, light in enumerate(scene["point_lights"]):
        d[f"light{k}"] = {"type": "point", "position": light["position"],
                          "intensity": {"type": "rgb", "value": light["intensity"]}}
    return d


def main():
    with open(sys.argv[1]) as f:
        job = json.load(f)
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    work = os.path.join(job["out"], f"{job['prefix']}-mitsuba-meshes")
    os.makedirs(work, exist_ok=True)
    scene = mi.load_dict(scene_dict(job, work))
    for spp in job["spp"]:
        start, cpu_start = time.perf_counter(), time.process_time()
        image = mi.render(scene, spp=spp, seed=spp)
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
        exr = os.path.join(job["out"], f"{job['prefix']}-mitsuba-{spp}spp.exr")
        mi.Bitmap(image).write(exr)
        print(json.dumps({"spp": spp, "seconds": seconds, "cpu_seconds": cpu, "exr": exr}), flush=True)


if __name__ == "__main__":
    main()
