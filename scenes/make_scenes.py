#!/usr/bin/env python3
"""Generate the icrender test scenes as self-contained glTF 2.0 files.

    python3 scenes/make_scenes.py            # writes cornell.gltf and corridor.gltf beside this script
    python3 scenes/make_scenes.py --check    # only validate the existing files

Conventions (those of the renderer): +Y up, metres, counter-clockwise winding gives a
triangle's front side, emitters emit from their front side only. Every surface is built
from quads with flat normals; walls face into the room, boxes face outward, and ceiling
lights face down.

Standard library only.
"""

import base64
import json
import math
import os
import struct
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

FLOAT = 5126
UINT = 5125
ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963

# ----------------------------------------------------------------------------------------
# Vector helpers


def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def length(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def normalize(a):
    n = length(a)
    return (a[0] / n, a[1] / n, a[2] / n)


def rotate_y(p, degrees):
    """Right-handed rotation about +Y (positive angles turn +Z towards +X)."""
    t = math.radians(degrees)
    c, s = math.cos(t), math.sin(t)
    return (c * p[0] + s * p[2], p[1], -s * p[0] + c * p[2])


AXES = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

# ----------------------------------------------------------------------------------------
# Geometry: a list of quads, each (p0, p1, p2, p3) counter-clockwise seen from its front.


class Geometry:
    def __init__(self):
        self.quads = []

    def quad(self, center, u, v):
        """The parallelogram center +- u +- v; its front normal is u x v."""
        c = center
        self.quads.append((
            sub(sub(c, u), v),
            sub(add(c, u), v),
            add(add(c, u), v),
            add(sub(c, u), v),
        ))

    def axis_quad(self, center, axis, sign, half):
        """An axis-aligned rectangle whose front normal is sign * e[axis].

        half maps each of the two other axes (0 = x, 1 = y, 2 = z) to the half extent.
        """
        j, k = (axis + 1) % 3, (axis + 2) % 3
        # e_j x e_k = e_axis for cyclic (axis, j, k); swapping the two flips the normal.
        u = scale(AXES[j], half[j])
        v = scale(AXES[k], half[k])
        if sign < 0:
            u, v = v, u
        self.quad(center, u, v)

    def box(self, center, size, yaw_degrees=0.0):
        """A closed box, outward facing, centred at center, rotated about its vertical axis."""
        h = (size[0] / 2.0, size[1] / 2.0, size[2] / 2.0)
        for axis in range(3):
            for sign in (1, -1):
                j, k = (axis + 1) % 3, (axis + 2) % 3
                u = scale(AXES[j], h[j])
                v = scale(AXES[k], h[k])
                if sign < 0:
                    u, v = v, u
                c = scale(AXES[axis], sign * h[axis])
                u, v, c = rotate_y(u, yaw_degrees), rotate_y(v, yaw_degrees), rotate_y(c, yaw_degrees)
                self.quad(add(center, c), u, v)

    def arrays(self):
        """Flat-shaded vertex positions, normals and triangle indices."""
        positions, normals, indices = [], [], []
        for q in self.quads:
            n = normalize(cross(sub(q[1], q[0]), sub(q[2], q[0])))
            base = len(positions)
            positions.extend(q)
            normals.extend([n] * 4)
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3])
        return positions, normals, indices


# ----------------------------------------------------------------------------------------
# glTF document builder


def lambertian(name, rgb):
    return {
        "name": name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [rgb[0], rgb[1], rgb[2], 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": 1.0,
        },
        "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}},
    }


def emitter(name, rgb, strength):
    material = lambertian(name, (0.0, 0.0, 0.0))
    material["emissiveFactor"] = list(rgb)
    material["extensions"]["KHR_materials_emissive_strength"] = {"emissiveStrength": strength}
    return material


def mirror(name, rgb):
    return {
        "name": name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [rgb[0], rgb[1], rgb[2], 1.0],
            "metallicFactor": 1.0,
            "roughnessFactor": 0.0,
        },
    }


class Document:
    def __init__(self):
        self.blob = bytearray()
        self.buffer_views = []
        self.accessors = []
        self.materials = []
        self.material_index = {}
        self.meshes = []
        self.nodes = []
        self.cameras = []

    def material(self, material):
        name = material["name"]
        if name not in self.material_index:
            self.material_index[name] = len(self.materials)
            self.materials.append(material)
        return self.material_index[name]

    def _view(self, data, target):
        while len(self.blob) % 4:
            self.blob.append(0)
        self.buffer_views.append({
            "buffer": 0,
            "byteOffset": len(self.blob),
            "byteLength": len(data),
            "target": target,
        })
        self.blob.extend(data)
        return len(self.buffer_views) - 1

    def _accessor(self, view, component, count, kind, extra=None):
        accessor = {"bufferView": view, "byteOffset": 0, "componentType": component,
                    "count": count, "type": kind}
        if extra:
            accessor.update(extra)
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def mesh_node(self, name, geometry, material):
        positions, normals, indices = geometry.arrays()
        pos_data = b"".join(struct.pack("<3f", *p) for p in positions)
        nrm_data = b"".join(struct.pack("<3f", *n) for n in normals)
        idx_data = struct.pack("<%dI" % len(indices), *indices)
        # min/max of the values as stored (float32), as the spec asks.
        stored = [struct.unpack("<3f", struct.pack("<3f", *p)) for p in positions]
        lo = [min(p[i] for p in stored) for i in range(3)]
        hi = [max(p[i] for p in stored) for i in range(3)]
        pos = self._accessor(self._view(pos_data, ARRAY_BUFFER), FLOAT, len(positions), "VEC3",
                             {"min": lo, "max": hi})
        nrm = self._accessor(self._view(nrm_data, ARRAY_BUFFER), FLOAT, len(normals), "VEC3")
        idx = self._accessor(self._view(idx_data, ELEMENT_ARRAY_BUFFER), UINT, len(indices), "SCALAR")
        self.meshes.append({
            "name": name,
            "primitives": [{
                "attributes": {"POSITION": pos, "NORMAL": nrm},
                "indices": idx,
                "material": self.material(material),
                "mode": 4,
            }],
        })
        self.nodes.append({"name": name, "mesh": len(self.meshes) - 1})

    def camera_node(self, name, translation, yfov, rotation=None):
        self.cameras.append({
            "name": name,
            "type": "perspective",
            "perspective": {"yfov": yfov, "znear": 0.01},
        })
        node = {"name": name, "camera": len(self.cameras) - 1, "translation": list(translation)}
        if rotation is not None:
            node["rotation"] = list(rotation)
        self.nodes.append(node)

    def to_json(self, scene_name):
        used = set()
        for m in self.materials:
            used.update(m.get("extensions", {}).keys())
        while len(self.blob) % 4:
            self.blob.append(0)
        uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode("ascii")
        doc = {
            "asset": {"version": "2.0", "generator": "icrender scenes/make_scenes.py"},
            "extensionsUsed": sorted(used),
            "scene": 0,
            "scenes": [{"name": scene_name, "nodes": list(range(len(self.nodes)))}],
            "nodes": self.nodes,
            "cameras": self.cameras,
            "meshes": self.meshes,
            "materials": self.materials,
            "accessors": self.accessors,
            "bufferViews": self.buffer_views,
            "buffers": [{"byteLength": len(self.blob), "uri": uri}],
        }
        return doc


def quad_geometry(center, axis, sign, half):
    g = Geometry()
    g.axis_quad(center, axis, sign, half)
    return g


X, Y, Z = 0, 1, 2

# ----------------------------------------------------------------------------------------
# Scene 1: the Cornell box (2 x 2 x 2 m, open at z = +1) with a mirror tall box


def cornell():
    d = Document()
    white = lambertian("white", (0.725, 0.71, 0.68))
    red = lambertian("red", (0.63, 0.065, 0.05))
    green = lambertian("green", (0.14, 0.45, 0.091))
    light = emitter("light", (1.0, 0.85, 0.6), 20.0)
    glass = mirror("mirror", (0.9, 0.9, 0.9))

    d.mesh_node("floor", quad_geometry((0.0, 0.0, 0.0), Y, +1, {X: 1.0, Z: 1.0}), white)
    d.mesh_node("ceiling", quad_geometry((0.0, 2.0, 0.0), Y, -1, {X: 1.0, Z: 1.0}), white)
    d.mesh_node("backWall", quad_geometry((0.0, 1.0, -1.0), Z, +1, {X: 1.0, Y: 1.0}), white)
    d.mesh_node("leftWall", quad_geometry((-1.0, 1.0, 0.0), X, +1, {Y: 1.0, Z: 1.0}), red)
    d.mesh_node("rightWall", quad_geometry((1.0, 1.0, 0.0), X, -1, {Y: 1.0, Z: 1.0}), green)
    # 0.5 m along x, 0.4 m along z, facing down.
    d.mesh_node("light", quad_geometry((0.0, 1.999, 0.0), Y, -1, {X: 0.25, Z: 0.2}), light)

    short_box = Geometry()
    short_box.box((0.33, 0.3, 0.3), (0.6, 0.6, 0.6), -17.0)
    d.mesh_node("shortBox", short_box, white)
    tall_box = Geometry()
    # Turned far enough that its faces mirror the coloured walls, not the open front.
    tall_box.box((-0.33, 0.6, -0.3), (0.6, 1.2, 0.6), 35.0)
    d.mesh_node("tallBox", tall_box, glass)

    d.camera_node("camera", (0.0, 1.0, 3.9), 0.6911)
    return d.to_json("cornell")


# ----------------------------------------------------------------------------------------
# Scene 2: a long corridor with ceiling lights, pillars and doors


def corridor():
    d = Document()
    width, height, length_ = 2.4, 3.0, 30.0
    hx = width / 2.0
    wall = lambertian("wall", (0.7, 0.7, 0.68))
    floor = lambertian("floor", (0.35, 0.3, 0.25))
    ceiling = lambertian("ceiling", (0.8, 0.8, 0.8))
    pillar = lambertian("pillar", (0.6, 0.6, 0.6))
    door = lambertian("door", (0.3, 0.15, 0.08))
    light = emitter("light", (1.0, 0.95, 0.85), 15.0)

    zc = -length_ / 2.0
    d.mesh_node("floor", quad_geometry((0.0, 0.0, zc), Y, +1, {X: hx, Z: length_ / 2}), floor)
    d.mesh_node("ceiling", quad_geometry((0.0, height, zc), Y, -1, {X: hx, Z: length_ / 2}), ceiling)
    d.mesh_node("leftWall", quad_geometry((-hx, height / 2, zc), X, +1, {Y: height / 2, Z: length_ / 2}), wall)
    d.mesh_node("rightWall", quad_geometry((hx, height / 2, zc), X, -1, {Y: height / 2, Z: length_ / 2}), wall)
    d.mesh_node("nearWall", quad_geometry((0.0, height / 2, 0.0), Z, -1, {X: hx, Y: height / 2}), wall)
    d.mesh_node("farWall", quad_geometry((0.0, height / 2, -length_), Z, +1, {X: hx, Y: height / 2}), wall)

    # Lights every 4 m at z = -2, -6, ..., -26: 0.6 m across, 0.3 m along the corridor.
    lights = Geometry()
    light_z = [-2.0 - 4.0 * i for i in range(7)]
    for z in light_z:
        lights.axis_quad((0.0, height - 0.001, z), Y, -1, {X: 0.3, Z: 0.15})
    d.mesh_node("lights", lights, light)

    # Pillars 0.3 x 3 x 0.3 against both walls, halfway between lights: z = -4, -8, ..., -28.
    pillars = Geometry()
    for i in range(7):
        z = -4.0 - 4.0 * i
        for side in (-1, 1):
            pillars.box((side * (hx - 0.15), height / 2, z), (0.3, height, 0.3))
    d.mesh_node("pillars", pillars, pillar)

    # Three doors, 1 m wide, 2.1 m tall, 0.05 m thick, backs against the wall, between pillars.
    doors = Geometry()
    for side, z in ((-1, -6.0), (1, -14.0), (-1, -22.0)):
        doors.box((side * (hx - 0.025), 1.05, z), (0.05, 2.1, 1.0))
    d.mesh_node("doors", doors, door)

    d.camera_node("camera", (0.0, 1.6, -0.5), 1.0)
    return d.to_json("corridor")


# ----------------------------------------------------------------------------------------
# Validation


def read_accessor(doc, blob, index):
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    fmt = {FLOAT: "f", UINT: "I"}[acc["componentType"]]
    size = 4 * width
    start = view["byteOffset"] + acc.get("byteOffset", 0)
    end = start + size * acc["count"]
    assert view["byteOffset"] + view["byteLength"] <= len(blob), "buffer view %d overruns the buffer" % acc["bufferView"]
    assert end <= view["byteOffset"] + view["byteLength"], "accessor %d overruns its view" % index
    assert start % 4 == 0, "accessor %d misaligned" % index
    values = struct.unpack_from("<%d%s" % (width * acc["count"], fmt), blob, start)
    if width == 1:
        return list(values)
    return [tuple(values[i:i + width]) for i in range(0, len(values), width)]


def validate(path):
    with open(path) as f:
        doc = json.load(f)
    assert doc["asset"]["version"] == "2.0"
    assert len(doc["buffers"]) == 1
    uri = doc["buffers"][0]["uri"]
    prefix = "data:application/octet-stream;base64,"
    assert uri.startswith(prefix)
    blob = base64.b64decode(uri[len(prefix):])
    assert len(blob) == doc["buffers"][0]["byteLength"]

    used = set(doc.get("extensionsUsed", []))
    assert "extensionsRequired" not in doc
    for m in doc["materials"]:
        pbr = m["pbrMetallicRoughness"]
        for key in ("baseColorFactor", "metallicFactor", "roughnessFactor"):
            assert key in pbr, "%s lacks %s" % (m["name"], key)
        for ext in m.get("extensions", {}):
            assert ext in used, "%s not in extensionsUsed" % ext

    total = 0
    per_node = []
    for node in doc["nodes"]:
        if "mesh" not in node:
            continue
        tris = 0
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            pos_acc = doc["accessors"][prim["attributes"]["POSITION"]]
            positions = read_accessor(doc, blob, prim["attributes"]["POSITION"])
            normals = read_accessor(doc, blob, prim["attributes"]["NORMAL"])
            idx_acc = doc["accessors"][prim["indices"]]
            assert idx_acc["componentType"] == UINT
            indices = read_accessor(doc, blob, prim["indices"])
            assert len(normals) == len(positions)
            assert len(indices) % 3 == 0
            for i in range(3):
                assert pos_acc["min"][i] == min(p[i] for p in positions)
                assert pos_acc["max"][i] == max(p[i] for p in positions)
            for n in normals:
                assert abs(length(n) - 1.0) < 1e-5, "non-unit normal %r" % (n,)
            material = doc["materials"][prim["material"]]
            emissive = any(c > 0 for c in material.get("emissiveFactor", [0, 0, 0]))
            for t in range(0, len(indices), 3):
                a, b, c = indices[t:t + 3]
                assert max(a, b, c) < len(positions), "index out of range in %s" % node["name"]
                g = cross(sub(positions[b], positions[a]), sub(positions[c], positions[a]))
                assert length(g) > 0, "degenerate triangle in %s" % node["name"]
                g = normalize(g)
                for v in (a, b, c):
                    n = normals[v]
                    assert g[0] * n[0] + g[1] * n[1] + g[2] * n[2] > 0.999, \
                        "NORMAL disagrees with the winding in %s" % node["name"]
                if emissive:
                    assert g[1] < -0.999, "light in %s does not face down: %r" % (node["name"], g)
            tris += len(indices) // 3
        per_node.append((node["name"], tris))
        total += tris
    cams = [n for n in doc["nodes"] if "camera" in n]
    assert len(cams) == 1
    print("%s: %d triangles (%s), %d bytes of buffer, extensions %s" % (
        os.path.basename(path), total, ", ".join("%s %d" % p for p in per_node), len(blob),
        ", ".join(sorted(used))))
    return total


def main():
    outputs = {"cornell.gltf": cornell, "corridor.gltf": corridor}
    if "--check" not in sys.argv[1:]:
        for name, build in outputs.items():
            with open(os.path.join(HERE, name), "w") as f:
                json.dump(build(), f, indent=1)
                f.write("\n")
    for name in outputs:
        validate(os.path.join(HERE, name))


if __name__ == "__main__":
    main()
