// The node graph: each node's local transform, the world matrices of a walk over the scene's
// trees, and what each node places (meshes, cameras, lights).
//
// Part of the glTF loader (see scene_io.cpp and scene_io_internal.h).

#include "scene_io_internal.h"

namespace icr_io {

Mat4 identity() {
    Mat4 m{};
    m[0] = m[5] = m[10] = m[15] = 1.0;
    return m;
}

Mat4 mul(const Mat4 &a, const Mat4 &b) {
    Mat4 r{};
    for (int c = 0; c < 4; ++c)
        for (int row = 0; row < 4; ++row) {
            double s = 0.0;
            for (int k = 0; k < 4; ++k) s += a[size_t(k * 4 + row)] * b[size_t(c * 4 + k)];
            r[size_t(c * 4 + row)] = s;
        }
    return r;
}

void transform_dir(const Mat4 &m, double x, double y, double z, float out[3]) {
    double v[3];
    for (int r = 0; r < 3; ++r) v[r] = m[size_t(r)] * x + m[size_t(4 + r)] * y + m[size_t(8 + r)] * z;
    double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    // A singular transform has no direction; pass the raw (zero/NaN) vector on for Rust to judge.
    if (len > 0.0 && std::isfinite(len))
        for (double &c : v) c /= len;
    for (int i = 0; i < 3; ++i) out[i] = float(v[i]);
}

// The node's local transform as the file gives it, into `pose`: its matrix, or its
// translation, rotation (normalised) and scale with glTF's defaults where absent. Animations
// replace parts of the TRS at other times (Rust recomputes the matrix the way
// `local_transform` does).
void Converter::local_pose(const tinygltf::Node &node, const std::string &label, icr_node *pose) {
    if (!node.matrix.empty()) {
        if (node.matrix.size() != 16) fail(label + ": matrix must have 16 elements");
        pose->has_matrix = 1;
        for (size_t i = 0; i < 16; ++i) pose->matrix[i] = node.matrix[i];
        return;
    }
    if (!node.translation.empty() && node.translation.size() != 3)
        fail(label + ": translation must have 3 elements");
    if (!node.rotation.empty() && node.rotation.size() != 4) fail(label + ": rotation must have 4 elements");
    if (!node.scale.empty() && node.scale.size() != 3) fail(label + ": scale must have 3 elements");
    double *t = pose->translation, *s = pose->scale, *q = pose->rotation;
    t[0] = t[1] = t[2] = 0.0;
    s[0] = s[1] = s[2] = 1.0;
    q[0] = q[1] = q[2] = 0.0;
    q[3] = 1.0;
    for (size_t i = 0; i < node.translation.size(); ++i) t[i] = node.translation[i];
    for (size_t i = 0; i < node.scale.size(); ++i) s[i] = node.scale[i];
    for (size_t i = 0; i < node.rotation.size(); ++i) q[i] = node.rotation[i];
    if (!normalise(q)) warnings.push_back(label + ": rotation quaternion has no length, ignored");
}

// Exporters write quaternions rounded to a few digits: the rotation is renormalised so that
// it does not also scale; one without length becomes none (false).
bool Converter::normalise(double q[4]) {
    double ql = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (ql > 0.0 && std::isfinite(ql)) {
        for (int i = 0; i < 4; ++i) q[i] /= ql;
        return true;
    }
    q[0] = q[1] = q[2] = 0.0;
    q[3] = 1.0;
    return false;
}

// Translation * rotation * scale, as glTF composes a node's (and EXT_mesh_gpu_instancing an
// instance's) transform, of a unit quaternion.
Mat4 Converter::compose(const double t[3], const double q[4], const double s[3]) {
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    const double r[3][3] = {
        {1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
        {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
        {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)},
    };
    Mat4 m{};
    for (int c = 0; c < 3; ++c)
        for (int row = 0; row < 3; ++row) m[size_t(c * 4 + row)] = r[row][c] * s[c];
    m[12] = t[0];
    m[13] = t[1];
    m[14] = t[2];
    m[15] = 1.0;
    return m;
}

// `compose` of a quaternion as a file gives it (normalised first; `no_length` set when it
// has none).
Mat4 Converter::trs_matrix(const double t[3], const double q_in[4], const double s[3], bool *no_length) {
    double q[4] = {q_in[0], q_in[1], q_in[2], q_in[3]};
    if (!normalise(q)) *no_length = true;
    return compose(t, q, s);
}

Mat4 Converter::local_transform(const icr_node &pose) {
    if (pose.has_matrix) {
        Mat4 m{};
        for (size_t i = 0; i < 16; ++i) m[i] = pose.matrix[i];
        return m;
    }
    return compose(pose.translation, pose.rotation, pose.scale);
}

// Places one node (instances, camera, light) and returns its world matrix. `parent_index`
// is -1 for a root.
Mat4 Converter::place_node(size_t ni, const Mat4 &parent, int64_t parent_index) {
    if (++visits_ > kMaxNodeVisits)
        fail("node graph expands to more than " + std::to_string(kMaxNodeVisits) + " node visits");
    const tinygltf::Node &node = m_.nodes[ni];
    const std::string label = quoted_or_index(node.name, "node", ni);
    icr_node &pose = s_.nodes[ni];
    pose.parent = int32_t(parent_index);
    pose.in_scene = 1;
    local_pose(node, label, &pose);
    const Mat4 world = mul(parent, local_transform(pose));

    if (node.mesh >= 0) {
        // One copy of the name for all the node's primitives.
        const char *node_name = s_.keep(node.name);
        if (size_t(node.mesh) >= m_.meshes.size())
            fail(label + ": mesh " + std::to_string(node.mesh) + " out of range");
        if (node.skin >= 0 && !warned_skin_) {
            warnings.push_back("skins are ignored; skinned meshes use their bind pose");
            warned_skin_ = true;
        }
        if (node.skin >= 0 && size_t(node.skin) < m_.skins.size()) skinned_.push_back(size_t(node.skin));
        const std::vector<Mat4> placements = placements_of(node, label, world);
        for (int64_t mi : mesh_primitives(size_t(node.mesh))) {
            if (mi < 0) continue;
            for (const Mat4 &placed : placements) {
                icr_instance inst{};
                inst.mesh = uint32_t(mi);
                for (size_t i = 0; i < 16; ++i) inst.world[i] = placed[i];
                inst.node = uint32_t(ni);
                inst.node_name = node_name;
                s_.instances.push_back(inst);
            }
            pose.places |= ICR_PLACES_MESH;
        }
    } else if (node.mesh < -1) {
        fail(label + ": mesh " + std::to_string(node.mesh) + " out of range");
    } else if (node.extensions.count("EXT_mesh_gpu_instancing")) {
        warnings.push_back(label + ": EXT_mesh_gpu_instancing on a node without a mesh is ignored");
    }

    if (node.camera >= 0 || node.camera < -1) {
        add_camera(node, ni, label, world);
        pose.places |= ICR_PLACES_CAMERA;
    }

    auto lp = node.extensions.find("KHR_lights_punctual");
    if (lp != node.extensions.end()) {
        add_light(node, ni, label, lp->second, world);
        pose.places |= ICR_PLACES_LIGHT;
    }
    return world;
}

// Depth-first walk with an explicit stack: 1024 levels of recursion would not fit the 2 MiB
// stack of a Rust thread comfortably. `path` is exactly the chain of ancestors, which is
// what the cycle check needs.
void Converter::walk_from(int root) {
    std::vector<PathEntry> path;
    // `parent` is -1 for the root; messages are only built when they are needed.
    auto enter = [&](int index, const Mat4 &parent_world, int64_t parent) {
        if (index < 0 || size_t(index) >= m_.nodes.size()) {
            if (parent < 0) fail("scene root node " + std::to_string(index) + " out of range");
            fail(quoted_or_index(m_.nodes[size_t(parent)].name, "node", size_t(parent)) + ": child " +
                 std::to_string(index) + " out of range");
        }
        const size_t ni = size_t(index);
        if (on_path_[ni]) fail("node graph has a cycle at node " + std::to_string(index));
        if (path.size() > kMaxNodeDepth)
            fail("node graph deeper than " + std::to_string(kMaxNodeDepth) + " levels");
        Mat4 world = place_node(ni, parent_world, parent);
        on_path_[ni] = 1;
        path.push_back(PathEntry{ni, world, 0});
    };
    enter(root, identity(), -1);
    while (!path.empty()) {
        PathEntry &top = path.back();
        const tinygltf::Node &node = m_.nodes[top.node];
        if (top.next_child < node.children.size()) {
            int child = node.children[top.next_child++];
            const Mat4 parent = top.world;  // `top` dies if `path` reallocates
            enter(child, parent, int64_t(top.node));
        } else {
            on_path_[top.node] = 0;
            path.pop_back();
        }
    }
}

void Converter::walk_scene() {
    mesh_prims_.assign(m_.meshes.size(), {});
    mesh_done_.assign(m_.meshes.size(), false);
    on_path_.assign(m_.nodes.size(), 0);
    s_.nodes.assign(m_.nodes.size(), icr_node{});
    for (size_t i = 0; i < m_.nodes.size(); ++i) {
        icr_node &n = s_.nodes[i];
        n.name = s_.keep(m_.nodes[i].name);
        n.parent = -1;
        n.rotation[3] = 1.0;
        n.scale[0] = n.scale[1] = n.scale[2] = 1.0;
    }
    for (int r : scene_roots()) walk_from(r);
    // The joints of the skins placed meshes use: an animation that moves one would deform a
    // mesh, which the renderer does not do (it refuses such frames, naming the joint).
    for (size_t skin : skinned_)
        for (int joint : m_.skins[skin].joints)
            if (joint >= 0 && size_t(joint) < s_.nodes.size()) s_.nodes[size_t(joint)].places |= ICR_PLACES_JOINT;
}

}  // namespace icr_io
