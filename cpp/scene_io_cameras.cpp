// Cameras: a node's glTF camera, perspective or orthographic, as the ABI's icr_camera in world
// space.
//
// Part of the glTF loader (see scene_io.cpp and scene_io_internal.h).

#include "scene_io_internal.h"

namespace icr_io {

void Converter::add_camera(const tinygltf::Node &node, size_t ni, const std::string &label, const Mat4 &world) {
    if (node.camera < 0 || size_t(node.camera) >= m_.cameras.size())
        fail(label + ": camera " + std::to_string(node.camera) + " out of range");
    const tinygltf::Camera &cam = m_.cameras[size_t(node.camera)];
    icr_camera out{};
    out.name = s_.keep(!node.name.empty() ? node.name : cam.name);
    if (cam.type == "perspective") {
        out.perspective = 1;
        out.yfov = float(cam.perspective.yfov);
        out.aspect = float(cam.perspective.aspectRatio);
    } else if (cam.type == "orthographic") {
        out.perspective = 0;
        out.xmag = float(cam.orthographic.xmag);
        out.ymag = float(cam.orthographic.ymag);
    } else {
        fail(label + ": camera type '" + shorten(cam.type) + "' is neither perspective nor orthographic");
    }
    for (int i = 0; i < 3; ++i) out.position[i] = world[size_t(12 + i)];
    transform_dir(world, 0, 0, -1, out.forward);
    transform_dir(world, 0, 1, 0, out.up);
    out.node = uint32_t(ni);
    s_.cameras.push_back(out);
}

}  // namespace icr_io
