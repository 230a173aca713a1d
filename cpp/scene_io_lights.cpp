// Lights: KHR_lights_punctual's point, spot and directional lights as the ABI's icr_light in world
// space, their parameters checked against the extension's rules.
//
// Part of the glTF loader (see scene_io.cpp and scene_io_internal.h).

#include "scene_io_internal.h"

namespace icr_io {

void Converter::add_light(const tinygltf::Node &node, size_t ni, const std::string &label, const tinygltf::Value &ext,
                          const Mat4 &world) {
    double li;
    if (!number_member(ext, "light", &li))
        fail(label + ": KHR_lights_punctual has no light index");
    if (!(li >= 0.0) || li >= double(m_.lights.size()) || li != std::floor(li)) {
        char buf[64];
        std::snprintf(buf, sizeof buf, "%g", li);
        fail(label + ": light " + buf + " out of range");
    }
    const tinygltf::Light &light = m_.lights[size_t(li)];
    icr_light out{};
    out.name = s_.keep(!node.name.empty() ? node.name : light.name);
    if (light.type == "point") {
        out.type = ICR_LIGHT_POINT;
    } else if (light.type == "spot") {
        out.type = ICR_LIGHT_SPOT;
    } else if (light.type == "directional") {
        out.type = ICR_LIGHT_DIRECTIONAL;
    } else {
        fail(label + ": light type '" + shorten(light.type) + "' is not point, spot or directional");
    }
    if (!light.color.empty() && light.color.size() != 3) fail(label + ": light color must have 3 elements");
    for (int c = 0; c < 3; ++c) out.color[c] = light.color.empty() ? 1.0f : float(light.color[size_t(c)]);
    // KHR_lights_punctual: intensity >= 0; a spot's cone angles 0 <= inner < outer <= pi/2.
    if (!(light.intensity >= 0.0)) {
        char buf[64];
        std::snprintf(buf, sizeof buf, "%g", light.intensity);
        fail(label + ": light intensity " + buf + " is negative");
    }
    out.intensity = float(light.intensity);
    out.range = float(light.range);
    if (out.type == ICR_LIGHT_SPOT) {
        const double inner = light.spot.innerConeAngle, outer = light.spot.outerConeAngle;
        if (!(inner >= 0.0 && inner < outer && outer <= kHalfPi + 1e-9)) {
            char buf[128];
            std::snprintf(buf, sizeof buf, "spot cone angles inner %g, outer %g", inner, outer);
            fail(label + ": " + buf + " (glTF requires 0 <= inner < outer <= pi/2)");
        }
        out.inner_cone = float(inner);
        out.outer_cone = float(outer);
    }
    for (int i = 0; i < 3; ++i) out.position[i] = world[size_t(12 + i)];
    transform_dir(world, 0, 0, -1, out.direction);
    out.node = uint32_t(ni);
    s_.lights.push_back(out);
}

}  // namespace icr_io
