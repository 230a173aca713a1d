"""A small glTF 2.0 reader for the peer benches: world-space triangle meshes, the materials
as `--lambertian` sees them (base colour, base-colour texture, alpha, emission) and punctual
lights, so the same scene can be handed to other renderers.

Only what the shared scenes use is read: triangle lists, POSITION, TEXCOORD_0, node
transforms (matrix or TRS), KHR_materials_emissive_strength and KHR_lights_punctual. Anything
else makes `load` raise, so a bench never compares against a silently different scene.
"""

import json
import os

import numpy as np

COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}


class UnsupportedScene(Exception):
    pass


def _accessor(doc, buffers, index):
    acc = doc["accessors"][index]
    if "sparse" in acc:
        raise UnsupportedScene("sparse accessors")
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = np.dtype(DTYPES[acc["componentType"]])
    width = COMPONENTS[acc["type"]]
    count = acc["count"]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride", 0) or dtype.itemsize * width
    data = buffers[view["buffer"]]
    rows = np.ndarray((count, width), dtype=dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize))
    return np.array(rows)


def _quat_matrix(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _local_matrix(node):
    if "matrix" in node:
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    m[:3, :3] = _quat_matrix(node.get("rotation", [0, 0, 0, 1])) @ np.diag(node.get("scale", [1, 1, 1]))
    m[:3, 3] = node.get("translation", [0, 0, 0])
    return m


def _material(doc, folder, m):
    pbr = m.get("pbrMetallicRoughness", {})
    base = pbr.get("baseColorFactor", [1, 1, 1, 1])
    texture = None
    if "baseColorTexture" in pbr:
        tex = doc["textures"][pbr["baseColorTexture"]["index"]]
        if pbr["baseColorTexture"].get("texCoord", 0) != 0:
            raise UnsupportedScene("texture coordinates other than TEXCOORD_0")
        texture = os.path.join(folder, doc["images"][tex["source"]]["uri"])
    strength = m.get("extensions", {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    emission = [c * strength for c in m.get("emissiveFactor", [0, 0, 0])]
    return {
        "name": m.get("name", ""),
        "base_color": [float(c) for c in base[:3]],
        "alpha": float(base[3]),
        "alpha_mode": m.get("alphaMode", "OPAQUE"),
        "texture": texture,
        "emission": [float(c) for c in emission],
    }


def load(path):
    """{'meshes': [{positions, indices, uv, material}], 'materials': [...], 'point_lights': [...]}.

    Positions are world space (float64), indices int64 with the winding glTF gives the front
    side (a mirroring transform reverses it back), uv as glTF has them (v downwards).
    """
    folder = os.path.dirname(os.path.abspath(path))
    with open(path) as f:
        doc = json.load(f)
    buffers = []
    for b in doc.get("buffers", []):
        with open(os.path.join(folder, b["uri"]), "rb") as f:
            buffers.append(f.read())
    materials = [_material(doc, folder, m) for m in doc.get("materials", [])]
    default_material = len(materials)
    # glTF's default material is metallic white; --lambertian makes it a white diffuser.
    materials.append({"name": "(default)", "base_color": [1, 1, 1], "alpha": 1.0, "alpha_mode": "OPAQUE",
                      "texture": None, "emission": [0, 0, 0]})
    lights_def = doc.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
    meshes, point_lights = [], []

    def visit(index, parent):
        node = doc["nodes"][index]
        world = parent @ _local_matrix(node)
        if "mesh" in node:
            for prim in doc["meshes"][node["mesh"]]["primitives"]:
                if prim.get("mode", 4) != 4:
                    raise UnsupportedScene("primitives other than triangle lists")
                local = _accessor(doc, buffers, prim["attributes"]["POSITION"]).astype(np.float64)
                positions = local @ world[:3, :3].T + world[:3, 3]
                if "indices" in prim:
                    indices = _accessor(doc, buffers, prim["indices"]).astype(np.int64).reshape(-1, 3)
                else:
                    indices = np.arange(len(positions), dtype=np.int64).reshape(-1, 3)
                if np.linalg.det(world[:3, :3]) < 0:
                    indices = indices[:, [0, 2, 1]]
                uv = None
                if "TEXCOORD_0" in prim["attributes"]:
                    uv = _accessor(doc, buffers, prim["attributes"]["TEXCOORD_0"]).astype(np.float64)
                meshes.append({"positions": positions, "indices": indices, "uv": uv,
                               "material": prim.get("material", default_material)})
        light = node.get("extensions", {}).get("KHR_lights_punctual")
        if light is not None:
            spec = lights_def[light["light"]]
            if spec.get("type") != "point" or spec.get("range"):
                raise UnsupportedScene("punctual lights other than point lights without range")
            intensity = [c * spec.get("intensity", 1.0) for c in spec.get("color", [1, 1, 1])]
            point_lights.append({"position": world[:3, 3].tolist(), "intensity": intensity})
        for child in node.get("children", []):
            visit(child, world)

    scene = doc["scenes"][doc.get("scene", 0)]
    for root in scene["nodes"]:
        visit(root, np.eye(4))
    return {"meshes": meshes, "materials": materials, "point_lights": point_lights}


def parse_view(options):
    """icrender's `-vtv -vp x y z -vd ... -vu ... -vh H -vv V` (its EXR's icrender/view) as a dict."""
    words = options.split()
    if words[0] != "-vtv":
        raise UnsupportedScene(f"only perspective views: {options}")
    at = {w: i for i, w in enumerate(words)}
    vec = lambda name: [float(v) for v in words[at[name] + 1:at[name] + 4]]
    return {"position": vec("-vp"), "direction": vec("-vd"), "up": vec("-vu"),
            "horizontal": float(words[at["-vh"] + 1]), "vertical": float(words[at["-vv"] + 1])}


def camera_frame(view):
    """Right, up and forward unit vectors of a view, as icrender builds them."""
    forward = np.array(view["direction"], dtype=np.float64)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, view["up"])
    right /= np.linalg.norm(right)
    return right, np.cross(right, forward), forward
