#!/usr/bin/env python3
"""Seed corpora for the fuzz targets (python3, standard library only).

    python3 fuzz/make_seeds.py OUT_DIR [HOSTILE_SCENES_DIR]

writes OUT_DIR/scene_load, OUT_DIR/cache_file and OUT_DIR/records. Scene seeds are the
project's scenes (scenes/*.gltf), the shared Cornell box (../shared/scenes/cornell_box, made
self-contained as .gltf with a data URI and as .glb), a few small hand-made scenes using every
feature the loader reads, and the hostile corpus of tests/hostile.rs (its scenes folder as the
second argument). Record seeds are
encoded here with the same layouts as src/irradiance/codec.rs, src/parallel/protocol.rs and
src/parallel/component/requests.rs.
"""

import base64
import json
import os
import struct
import sys
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

# Must match SETTINGS in fuzz_targets/cache_file.rs.
CACHE_SETTINGS = b"-aa 0.1 -ar 64 -ad 512 -as 0 -ab 1 -lr 8 -lw 0.001 -st 0.15"


def minify(doc):
    return json.dumps(doc, separators=(",", ":")).encode()


def glb(doc, bin_bytes=b""):
    js = minify(doc)
    js += b" " * (-len(js) % 4)
    out = struct.pack("<I", len(js)) + b"JSON" + js
    if bin_bytes:
        b = bin_bytes + b"\0" * (-len(bin_bytes) % 4)
        out += struct.pack("<I", len(b)) + b"BIN\0" + b
    return b"glTF" + struct.pack("<II", 2, 12 + len(out)) + out


def png(width, height, rgba_rows):
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    raw = b"".join(b"\0" + row for row in rgba_rows)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def triangle_doc(buffer_uri, byte_length, image=None):
    """One textured, lit triangle under a small node hierarchy, with a camera."""
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_materials_specular"],
        "scene": 0,
        "scenes": [{"nodes": [0, 3]}],
        "nodes": [
            {"name": "root", "children": [1, 2], "translation": [0, 0, -1], "rotation": [0, 0, 0, 1], "scale": [1, 1, 1]},
            {"name": "tri", "mesh": 0, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]},
            {"name": "lamp", "translation": [0, 1, 1], "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"name": "cam", "camera": 0, "translation": [0.3, 0.3, 2]},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.01, "aspectRatio": 1.0}}],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "color": [1, 1, 1], "intensity": 5},
            {"type": "spot", "intensity": 5, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
        ]}},
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 2, "TEXCOORD_0": 3}, "indices": 1,
                                    "material": 0, "mode": 4}]}],
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1],
                                                             "metallicFactor": 0, "roughnessFactor": 0.5},
                       "emissiveFactor": [0, 0, 0], "alphaMode": "MASK", "alphaCutoff": 0.5,
                       "extensions": {"KHR_materials_specular": {"specularFactor": 0.5,
                                                                 "specularColorFactor": [1, 1, 1]},
                                      "KHR_materials_emissive_strength": {"emissiveStrength": 1}}}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
            {"bufferView": 0, "componentType": 5126, "count": 1, "type": "VEC3", "byteOffset": 0},
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC2"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 8},
        ],
        "buffers": [{"byteLength": byte_length}],
    }
    # NORMAL must have the POSITION count: reuse positions as (odd but valid) normals.
    doc["accessors"][2] = {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}
    if buffer_uri is not None:
        doc["buffers"][0]["uri"] = buffer_uri
    if image is not None:
        doc["images"] = [image]
        doc["textures"] = [{"source": 0, "sampler": 0}]
        doc["samplers"] = [{"wrapS": 33071, "wrapT": 33648}]
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    return doc


TRI_BIN = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<4H", 0, 1, 2, 0)
PNG_2X2 = png(2, 2, [bytes([255, 0, 0, 255, 0, 255, 0, 255]), bytes([0, 0, 255, 255, 255, 255, 255, 255])])


def scene_seeds(out, hostile_dir=None):
    seeds = {}
    for name in ("cornell.gltf", "corridor.gltf"):
        with open(os.path.join(ROOT, "scenes", name), "rb") as f:
            seeds[name] = minify(json.load(f))
    box = os.path.join(ROOT, "..", "shared", "scenes", "cornell_box")
    gltf_path = os.path.join(box, "CornellBox-Original.gltf")
    if os.path.exists(gltf_path):
        with open(gltf_path) as f:
            doc = json.load(f)
        with open(os.path.join(box, doc["buffers"][0]["uri"]), "rb") as f:
            data = f.read()
        embedded = json.loads(json.dumps(doc))
        embedded["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode()
        seeds["cornell_box_embedded.gltf"] = minify(embedded)
        binary = json.loads(json.dumps(doc))
        del binary["buffers"][0]["uri"]
        seeds["cornell_box.glb"] = glb(binary, data)
    # The fuzz target's folder holds tri.bin and tex.png (see fuzz_targets/scene_load.rs).
    seeds["triangle_external.gltf"] = minify(triangle_doc("tri.bin", len(TRI_BIN), {"uri": "tex.png"}))
    uri = "data:application/octet-stream;base64," + base64.b64encode(TRI_BIN).decode()
    png_uri = "data:image/png;base64," + base64.b64encode(PNG_2X2).decode()
    seeds["triangle_data_uri.gltf"] = minify(triangle_doc(uri, len(TRI_BIN), {"uri": png_uri}))
    # GLB with the texture in a bufferView of the BIN chunk.
    body = TRI_BIN + b"\0" * (-len(TRI_BIN) % 4)
    doc = triangle_doc(None, len(body) + len(PNG_2X2), {"bufferView": 2, "mimeType": "image/png"})
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(body), "byteLength": len(PNG_2X2)})
    seeds["triangle_embedded.glb"] = glb(doc, body + PNG_2X2)
    # No scenes array: roots are found from the node graph; orthographic camera, directional light.
    doc = triangle_doc("tri.bin", len(TRI_BIN))
    del doc["scenes"], doc["scene"]
    doc["cameras"][0] = {"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0, "zfar": 10}}
    doc["extensions"]["KHR_lights_punctual"]["lights"][0]["type"] = "directional"
    seeds["triangle_no_scene.gltf"] = minify(doc)

    # The hostile corpus of tests/hostile.rs, when its folder is given (scripts/fuzz.sh writes
    # it with the test's write_corpus entry point).
    if hostile_dir and os.path.isdir(hostile_dir):
        for name in sorted(os.listdir(hostile_dir)):
            path = os.path.join(hostile_dir, name)
            if name.endswith((".gltf", ".glb")) and os.path.isfile(path) and os.path.getsize(path) <= 1 << 16:
                with open(path, "rb") as f:
                    seeds["hostile_" + name] = f.read()
    write_all(os.path.join(out, "scene_load"), seeds)


def fnv1a(data):
    h = 0x811C9DC5
    for b in data:
        h = ((h ^ b) * 0x01000193) & 0xFFFFFFFF
    return h


def record(value=1.0, radius=0.5, level=0, position=(0.0, 0.0, 0.0)):
    floats = list(position) + [0, 0, 1] + [1, 0, 0] + [radius, radius, radius / 0.2, 1.0]
    floats += [value] * 3 + [0.1, 0, 0] + [0, 0.2, 0] + [float("inf")] * 8
    payload = struct.pack("<30f", *floats) + struct.pack("<I", level)
    return payload + struct.pack("<I", fnv1a(payload))


# Byte 0 of a `records` seed picks the message kind, in the order of the harness's KINDS.
KINDS = ["heartbeat", "initial_records", "prepass_start", "prepass_round", "work_request", "records_up",
         "records_broadcast", "final_records", "stats", "requests", "forwarded", "idle", "pa_status",
         "forward_order", "finish", "image", "results", "work", "records_down"]
VERSION = b"\x02"


def seed(kind, body, repair=False):
    return bytes([KINDS.index(kind), int(repair)]) + VERSION + body


def records_body(records):
    return struct.pack("<I", len(records)) + b"".join(records)


def request(pixel, layer=3):
    out = struct.pack("<III", pixel, layer, 1)
    for v in ((1, 2, 3), (0, 1, 0), (0, 1, 0), (0, -1, 0), (0.1, 0.2, 0.3), (1, 0, 0)):
        out += struct.pack("<3f", *v)
    return out + struct.pack("<fIQ", 0.5, 7, 0xDEADBEEF00000001)


def record_seeds(out):
    """Messages in the layouts of `src/parallel/protocol/` (version byte, then the body)."""
    recs = [record(1.0, 0.5), record(2.0, 0.25, 1, (1, 2, 3)), record(0.0, 1e-3, 1024)]
    pixel = struct.pack("<13f", *([0.5] * 12 + [2.0]))
    seeds = {
        "heartbeat": seed("heartbeat", b""),
        "initial_empty": seed("initial_records", records_body([])),
        "initial_three": seed("initial_records", records_body(recs)),
        "initial_repair": seed("initial_records", records_body(recs[:2])[:-4] + b"\0\0\0\0", True),
        "prepass_round": seed("prepass_round", struct.pack("<I", 2) + struct.pack("<I", 3) + recs[0]
                              + struct.pack("<I", 9) + recs[1]),
        "work_request_first": seed("work_request", struct.pack("<IB", 3, 0)),
        "work_request_tile": seed("work_request", struct.pack("<IBIII", 1, 1, 7, 0, 2) + pixel * 2),
        "work_none": seed("work", b"\x00" + struct.pack("<I", 0) + records_body([])),
        "work_tile": seed("work", b"\x01" + struct.pack("<I", 42) + records_body(recs[:1])),
        "records_up": seed("records_up", struct.pack("<I", 2) + records_body(recs[:2])),
        "records_down": seed("records_down", records_body(recs[1:])),
        "broadcast_last": seed("records_broadcast", b"\x01" + records_body(recs[:1])),
        "stats": seed("stats", b'{"rank":1,"role":"pa"}'),
        "requests_two": seed("requests", struct.pack("<I", 2) + request(5) + request(99, 2)),
        "requests_empty": seed("requests", struct.pack("<I", 0)),
        "forwarded": seed("forwarded", struct.pack("<I", 1) + request(7)),
        "idle": seed("idle", struct.pack("<QQ", 10, 20) + records_body(recs[:1]), True),
        "pa_status": seed("pa_status", struct.pack("<QQ", 1, 2) + records_body([])),
        "forward_order": seed("forward_order", struct.pack("<IIB", 4, 17, 1)),
        "finish": seed("finish", b""),
        "image": seed("image", struct.pack("<I3f", 3, 0.0, 1.5, 3.25)),
        "results": seed("results", struct.pack("<III3f", 1, 9, 2, 0.1, 0.2, 0.3)),
    }
    write_all(os.path.join(out, "records"), seeds)


def cache_seeds(out):
    header = b"ICRCACHE" + struct.pack("<II", 1, len(CACHE_SETTINGS)) + CACHE_SETTINGS
    recs = [record(1.0, 0.5), record(2.0, 0.25, 1, (1, 2, 3)), record(0.5, 2.0, 3)]
    seeds = {
        "empty": b"\x00",
        "header_only": b"\x00" + header,
        "three_records": b"\x00" + header + b"".join(recs),
        "torn_tail": b"\x00" + header + b"".join(recs)[:-50],
        "bad_checksum_last": b"\x00" + header + b"".join(recs)[:-1] + b"\x00",
        "repair_checksums": b"\x01" + header + b"".join(r[:-4] + b"\0\0\0\0" for r in recs),
        "other_settings": b"\x00" + b"ICRCACHE" + struct.pack("<II", 1, 3) + b"-ab" + recs[0],
    }
    write_all(os.path.join(out, "cache_file"), seeds)


def write_all(folder, seeds):
    os.makedirs(folder, exist_ok=True)
    for name, data in seeds.items():
        with open(os.path.join(folder, "seed_" + name), "wb") as f:
            f.write(data)
    print(f"{folder}: {len(seeds)} seeds")


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    out = sys.argv[1]
    record_seeds(out)
    cache_seeds(out)
    scene_seeds(out, sys.argv[2] if len(sys.argv) == 3 else None)


if __name__ == "__main__":
    main()
