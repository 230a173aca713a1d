// Mesh extraction: accessors proven to lie inside their buffers, triangle primitives converted to
// the ABI's flat arrays, and the placements EXT_mesh_gpu_instancing gives a mesh.
//
// Part of the glTF loader (see scene_io.cpp and scene_io_internal.h).

#include "scene_io_internal.h"

namespace icr_io {

const char *type_name(int type) {
    switch (type) {
        case TINYGLTF_TYPE_SCALAR: return "SCALAR";
        case TINYGLTF_TYPE_VEC2: return "VEC2";
        case TINYGLTF_TYPE_VEC3: return "VEC3";
        case TINYGLTF_TYPE_VEC4: return "VEC4";
        case TINYGLTF_TYPE_MAT2: return "MAT2";
        case TINYGLTF_TYPE_MAT3: return "MAT3";
        case TINYGLTF_TYPE_MAT4: return "MAT4";
        default: return "unknown type";
    }
}

const char *component_name(int ct) {
    switch (ct) {
        case TINYGLTF_COMPONENT_TYPE_BYTE: return "byte";
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return "unsigned byte";
        case TINYGLTF_COMPONENT_TYPE_SHORT: return "short";
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return "unsigned short";
        case TINYGLTF_COMPONENT_TYPE_INT: return "int";
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: return "unsigned int";
        case TINYGLTF_COMPONENT_TYPE_FLOAT: return "float";
        case TINYGLTF_COMPONENT_TYPE_DOUBLE: return "double";
        default: return "unknown component type";
    }
}

// Every byte an accessor can address is proven to lie inside its bufferView and its buffer
// before a view is returned.
AccessorView view_accessor(const tinygltf::Model &model, int index, const std::string &ctx) {
    if (index < 0 || size_t(index) >= model.accessors.size())
        fail(ctx + ": accessor " + std::to_string(index) + " out of range");
    const tinygltf::Accessor &acc = model.accessors[size_t(index)];
    const std::string what = ctx + ": accessor " + std::to_string(index);
    if (acc.sparse.isSparse) fail(what + " is sparse, which is not supported");
    if (acc.bufferView < 0) fail(what + " has no bufferView, which is not supported");
    if (size_t(acc.bufferView) >= model.bufferViews.size())
        fail(what + ": bufferView " + std::to_string(acc.bufferView) + " out of range");
    const tinygltf::BufferView &bv = model.bufferViews[size_t(acc.bufferView)];
    if (bv.buffer < 0 || size_t(bv.buffer) >= model.buffers.size())
        fail(what + ": buffer " + std::to_string(bv.buffer) + " out of range");
    const tinygltf::Buffer &buf = model.buffers[size_t(bv.buffer)];

    int csize = tinygltf::GetComponentSizeInBytes(uint32_t(acc.componentType));
    int ncomp = tinygltf::GetNumComponentsInType(uint32_t(acc.type));
    if (csize <= 0 || ncomp <= 0) fail(what + " has an invalid type or component type");
    uint64_t elem = uint64_t(csize) * uint64_t(ncomp);
    uint64_t stride = bv.byteStride ? uint64_t(bv.byteStride) : elem;
    if (stride < elem)
        fail(what + ": byteStride " + std::to_string(stride) + " is smaller than the element size " +
             std::to_string(elem));
    // glTF 2.0: an accessor's start in its buffer is aligned to its component size;
    // a misaligned one would be read as shifted bytes (garbage indices and positions).
    if ((bv.byteOffset + acc.byteOffset) % uint64_t(csize) != 0)
        fail(what + ": byteOffset " + std::to_string(acc.byteOffset) + " in bufferView " +
             std::to_string(acc.bufferView) + " (offset " + std::to_string(bv.byteOffset) +
             ") is not a multiple of its component size " + std::to_string(csize));
    if (acc.count == 0) fail(what + ": count is 0 (an accessor holds at least one element)");
    if (acc.normalized && (acc.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT ||
                           acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
        fail(what + ": normalized is true for " + component_name(acc.componentType) +
             " components (only 8- and 16-bit integers may be normalized)");

    uint64_t view_end = add_checked(bv.byteOffset, bv.byteLength, what);
    if (view_end > buf.data.size())
        fail(what + ": bufferView " + std::to_string(acc.bufferView) + " (offset " + std::to_string(bv.byteOffset) +
             ", length " + std::to_string(bv.byteLength) + ") exceeds buffer " + std::to_string(bv.buffer) +
             " of " + std::to_string(buf.data.size()) + " bytes");
    if (acc.count > 0) {
        uint64_t span = add_checked(mul_checked(stride, uint64_t(acc.count) - 1, what), elem, what);
        uint64_t end_in_view = add_checked(acc.byteOffset, span, what);
        if (end_in_view > bv.byteLength)
            fail(what + " (offset " + std::to_string(acc.byteOffset) + ", count " + std::to_string(acc.count) +
                 ", stride " + std::to_string(stride) + ") exceeds its bufferView of " +
                 std::to_string(bv.byteLength) + " bytes");
    }

    AccessorView v;
    v.first = buf.data.data() + bv.byteOffset + acc.byteOffset;
    v.stride = stride;
    v.count = acc.count;
    v.component_type = acc.componentType;
    v.components = ncomp;
    v.normalized = acc.normalized;
    return v;
}

const std::vector<int64_t> &Converter::mesh_primitives(size_t mesh_index) {
    if (mesh_done_[mesh_index]) return mesh_prims_[mesh_index];
    const tinygltf::Mesh &mesh = m_.meshes[mesh_index];
    std::vector<int64_t> out;
    for (size_t p = 0; p < mesh.primitives.size(); ++p) {
        std::string ctx = "primitive " + std::to_string(p) + " of " + quoted_or_index(mesh.name, "mesh", mesh_index);
        out.push_back(convert_primitive(mesh.primitives[p], ctx));
    }
    mesh_prims_[mesh_index] = std::move(out);
    mesh_done_[mesh_index] = true;
    return mesh_prims_[mesh_index];
}

int64_t Converter::convert_primitive(const tinygltf::Primitive &prim, const std::string &ctx) {
    if (prim.mode < TINYGLTF_MODE_POINTS || prim.mode > TINYGLTF_MODE_TRIANGLE_FAN)
        fail(ctx + ": mode " + std::to_string(prim.mode) + " is not a glTF primitive mode (0-6)");
    if (prim.mode != TINYGLTF_MODE_TRIANGLES) {
        warnings.push_back(ctx + ": mode " + std::to_string(prim.mode) + " is not TRIANGLES, skipped");
        return -1;
    }
    if (prim.material < -1 || (prim.material >= 0 && size_t(prim.material) >= m_.materials.size()))
        fail(ctx + ": material " + std::to_string(prim.material) + " out of range");

    auto pos_it = prim.attributes.find("POSITION");
    if (pos_it == prim.attributes.end()) fail(ctx + ": no POSITION attribute");
    AccessorView pos = view_accessor(m_, pos_it->second, ctx + ": POSITION");
    if (pos.component_type != TINYGLTF_COMPONENT_TYPE_FLOAT || pos.components != 3)
        fail(ctx + ": POSITION must be float VEC3, got " + component_name(pos.component_type) + " " +
             type_name(m_.accessors[size_t(pos_it->second)].type));
    if (pos.count > std::numeric_limits<uint32_t>::max()) fail(ctx + ": too many vertices");
    if (pos.count == 0) {
        warnings.push_back(ctx + ": no vertices, skipped");
        return -1;
    }
    const uint64_t nv = pos.count;

    MeshData md;
    md.material = prim.material;
    md.positions.resize(size_t(nv) * 3);
    for (uint64_t i = 0; i < nv; ++i)
        for (int c = 0; c < 3; ++c)
            md.positions[size_t(i * 3 + uint64_t(c))] = load<float>(pos.first + i * pos.stride + uint64_t(c) * 4);

    auto nrm_it = prim.attributes.find("NORMAL");
    if (nrm_it != prim.attributes.end()) {
        AccessorView nrm = view_accessor(m_, nrm_it->second, ctx + ": NORMAL");
        if (nrm.component_type != TINYGLTF_COMPONENT_TYPE_FLOAT || nrm.components != 3)
            fail(ctx + ": NORMAL must be float VEC3, got " + component_name(nrm.component_type) + " " +
                 type_name(m_.accessors[size_t(nrm_it->second)].type));
        if (nrm.count != nv)
            fail(ctx + ": NORMAL count " + std::to_string(nrm.count) + " differs from POSITION count " +
                 std::to_string(nv));
        md.normals.resize(size_t(nv) * 3);
        for (uint64_t i = 0; i < nv; ++i)
            for (int c = 0; c < 3; ++c)
                md.normals[size_t(i * 3 + uint64_t(c))] = load<float>(nrm.first + i * nrm.stride + uint64_t(c) * 4);
        md.has_normals = true;
    }

    auto uv_it = prim.attributes.find("TEXCOORD_0");
    if (uv_it != prim.attributes.end()) {
        AccessorView uv = view_accessor(m_, uv_it->second, ctx + ": TEXCOORD_0");
        bool ok = uv.components == 2 &&
                  (uv.component_type == TINYGLTF_COMPONENT_TYPE_FLOAT ||
                   (uv.normalized && (uv.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                                      uv.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT)));
        if (!ok)
            fail(ctx + ": TEXCOORD_0 must be VEC2 of float or normalized unsigned byte/short, got " +
                 (uv.normalized ? "normalized " : "") + component_name(uv.component_type) + " " +
                 type_name(m_.accessors[size_t(uv_it->second)].type));
        if (uv.count != nv)
            fail(ctx + ": TEXCOORD_0 count " + std::to_string(uv.count) + " differs from POSITION count " +
                 std::to_string(nv));
        md.texcoords.resize(size_t(nv) * 2);
        for (uint64_t i = 0; i < nv; ++i) {
            const unsigned char *e = uv.first + i * uv.stride;
            for (int c = 0; c < 2; ++c) {
                float v;
                switch (uv.component_type) {
                    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: v = float(e[c]) / 255.0f; break;
                    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
                        v = float(load<uint16_t>(e + c * 2)) / 65535.0f;
                        break;
                    default: v = load<float>(e + c * 4); break;
                }
                md.texcoords[size_t(i * 2 + uint64_t(c))] = v;
            }
        }
        md.has_texcoords = true;
    }

    if (prim.indices < -1) fail(ctx + ": indices accessor " + std::to_string(prim.indices) + " out of range");
    if (prim.indices >= 0) {
        AccessorView ix = view_accessor(m_, prim.indices, ctx + ": indices");
        int ct = ix.component_type;
        if (ix.components != 1 ||
            (ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
             ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
            fail(ctx + ": indices must be SCALAR unsigned byte/short/int, got " + component_name(ct) + " " +
                 type_name(m_.accessors[size_t(prim.indices)].type));
        if (ix.count % 3 != 0)
            fail(ctx + ": index count " + std::to_string(ix.count) + " is not a multiple of 3");
        if (ix.count / 3 > std::numeric_limits<uint32_t>::max()) fail(ctx + ": too many triangles");
        md.indices.resize(size_t(ix.count));
        for (uint64_t i = 0; i < ix.count; ++i) {
            const unsigned char *e = ix.first + i * ix.stride;
            uint32_t v = ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE    ? uint32_t(e[0])
                         : ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? uint32_t(load<uint16_t>(e))
                                                                        : load<uint32_t>(e);
            if (uint64_t(v) >= nv)
                fail(ctx + ": index " + std::to_string(v) + " out of range (vertex count " + std::to_string(nv) + ")");
            md.indices[size_t(i)] = v;
        }
    } else {
        if (nv % 3 != 0)
            fail(ctx + ": non-indexed vertex count " + std::to_string(nv) + " is not a multiple of 3");
        md.indices.resize(size_t(nv));
        for (uint64_t i = 0; i < nv; ++i) md.indices[size_t(i)] = uint32_t(i);
    }
    if (md.indices.empty()) {
        warnings.push_back(ctx + ": no triangles, skipped");
        return -1;
    }
    s_.mesh_data.push_back(std::move(md));
    return int64_t(s_.mesh_data.size() - 1);
}

// The extension's attributes on a node, checked for what an index can be; false when the
// node does not use it. `report`: warn about attributes it ignores.
bool Converter::gpu_instancing(const tinygltf::Node &node, const std::string &label, GpuInstancing *out,
                               bool report) {
    auto it = node.extensions.find("EXT_mesh_gpu_instancing");
    if (it == node.extensions.end()) return false;
    const std::string ctx = label + ": EXT_mesh_gpu_instancing";
    const tinygltf::Value &ext = it->second;
    if (!ext.IsObject() || !ext.Has("attributes") || !ext.Get("attributes").IsObject())
        fail(ctx + " has no \"attributes\" object");
    const tinygltf::Value &attributes = ext.Get("attributes");
    for (const std::string &key : attributes.Keys()) {
        const tinygltf::Value &v = attributes.Get(key);
        int *slot = key == "TRANSLATION" ? &out->translation
                    : key == "ROTATION"  ? &out->rotation
                    : key == "SCALE"     ? &out->scale
                                         : nullptr;
        if (!slot) {
            // Custom attributes (_ID, _COLOR, ...) are the application's; others are unknown.
            if (report && (key.empty() || key[0] != '_'))
                warnings.push_back(ctx + ": unknown attribute " + shorten(key) + " ignored");
            continue;
        }
        if (!v.IsNumber() || v.GetNumberAsDouble() != std::floor(v.GetNumberAsDouble()) ||
            v.GetNumberAsDouble() < 0.0 || v.GetNumberAsDouble() >= double(m_.accessors.size()))
            fail(ctx + ": " + key + " is not an accessor index");
        *slot = int(v.GetNumberAsDouble());
    }
    return true;
}

// How many instances the attributes give (their common count); 0 when they give no
// transform at all. Accessors are checked against their buffers (view_accessor).
uint64_t Converter::gpu_instance_count(const GpuInstancing &g, const std::string &ctx) {
    uint64_t count = 0;
    for (auto [index, name] : {std::pair<int, const char *>{g.translation, "TRANSLATION"},
                               {g.rotation, "ROTATION"},
                               {g.scale, "SCALE"}}) {
        if (index < 0) continue;
        const uint64_t n = view_accessor(m_, index, ctx + ": " + name).count;
        if (count != 0 && n != count)
            fail(ctx + ": " + name + " has " + std::to_string(n) + " instances where another attribute has " +
                 std::to_string(count) + " (all must have the same count)");
        count = n;
    }
    return count;
}

// Element i of a float VEC3/VEC4 accessor, or of a normalized byte/short VEC4 (ROTATION).
void Converter::read_vector(const AccessorView &a, uint64_t i, double *out) {
    const unsigned char *e = a.first + i * a.stride;
    for (int c = 0; c < a.components; ++c) {
        switch (a.component_type) {
            case TINYGLTF_COMPONENT_TYPE_FLOAT: out[c] = load<float>(e + 4 * c); break;
            case TINYGLTF_COMPONENT_TYPE_BYTE: out[c] = std::max(double(load<int8_t>(e + c)) / 127.0, -1.0); break;
            case TINYGLTF_COMPONENT_TYPE_SHORT:
                out[c] = std::max(double(load<int16_t>(e + 2 * c)) / 32767.0, -1.0);
                break;
            default: out[c] = 0.0;
        }
    }
}

// The world matrices of a node's placements: its own, or with EXT_mesh_gpu_instancing one
// per instance, node world * (translation * rotation * scale) of the instance.
std::vector<Mat4> Converter::placements_of(const tinygltf::Node &node, const std::string &label, const Mat4 &world) {
    GpuInstancing g;
    if (!gpu_instancing(node, label, &g)) return {world};
    const std::string ctx = label + ": EXT_mesh_gpu_instancing";
    const uint64_t count = gpu_instance_count(g, ctx);
    if (count == 0) {
        warnings.push_back(ctx + " gives no TRANSLATION, ROTATION or SCALE; the mesh is placed once");
        return {world};
    }
    auto view = [&](int index, const char *name, std::initializer_list<int> types, int components) {
        AccessorView a;
        if (index < 0) return a;
        a = view_accessor(m_, index, ctx + ": " + name);
        const bool float_ok = a.component_type == TINYGLTF_COMPONENT_TYPE_FLOAT;
        bool type_ok = false;
        for (int t : types) type_ok = type_ok || a.component_type == t;
        if (a.components != components || !type_ok || (!float_ok && !a.normalized))
            fail(ctx + ": " + name + " must be " +
                 (components == 4 ? "VEC4 float, or normalized byte or short" : "VEC3 float") + ", got " +
                 component_name(a.component_type) + (a.normalized ? " normalized " : " ") +
                 type_name(m_.accessors[size_t(index)].type));
        return a;
    };
    const AccessorView t = view(g.translation, "TRANSLATION", {TINYGLTF_COMPONENT_TYPE_FLOAT}, 3);
    const AccessorView r = view(g.rotation, "ROTATION",
                                {TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_COMPONENT_TYPE_BYTE,
                                 TINYGLTF_COMPONENT_TYPE_SHORT},
                                4);
    const AccessorView sc = view(g.scale, "SCALE", {TINYGLTF_COMPONENT_TYPE_FLOAT}, 3);
    std::vector<Mat4> out;
    out.reserve(size_t(count));
    bool no_length = false;
    for (uint64_t i = 0; i < count; ++i) {
        double tv[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
        if (t.first) read_vector(t, i, tv);
        if (r.first) read_vector(r, i, q);
        if (sc.first) read_vector(sc, i, s);
        out.push_back(mul(world, trs_matrix(tv, q, s, &no_length)));
    }
    if (no_length) warnings.push_back(ctx + ": a ROTATION quaternion has no length, taken as none");
    return out;
}

}  // namespace icr_io
