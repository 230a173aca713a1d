// Animation: every channel of every animation read into key times and values, its sampler checked
// against glTF 2.0's rules. Which channels a render uses is Rust's decision.
//
// Part of the glTF loader (see scene_io.cpp and scene_io_internal.h).

#include "scene_io_internal.h"

namespace icr_io {

// An accessor's elements as floats (normalised integers converted as glTF 2.0 says), read
// once however many channels use it.
size_t Converter::animation_floats(int accessor, const std::string &what, bool times, bool rotation, int components) {
    AccessorView v = view_accessor(m_, accessor, what);
    const int ct = v.component_type;
    const bool is_float = ct == TINYGLTF_COMPONENT_TYPE_FLOAT;
    const bool is_normalised = v.normalized && (ct == TINYGLTF_COMPONENT_TYPE_BYTE ||
                                                ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                                                ct == TINYGLTF_COMPONENT_TYPE_SHORT ||
                                                ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT);
    if (v.components != components || !(is_float || (rotation && is_normalised)))
        fail(what + " must be " + (times ? "SCALAR float (key times in seconds)"
                                         : rotation ? "VEC4 of float or normalized integers (x y z w)"
                                                    : "VEC3 float") +
             ", got " + (v.normalized ? "normalized " : "") + component_name(ct) + " " +
             type_name(m_.accessors[size_t(accessor)].type));
    if (anim_accessor_data_[size_t(accessor)] >= 0) return size_t(anim_accessor_data_[size_t(accessor)]);
    const uint64_t n = mul_checked(v.count, uint64_t(components), what);
    anim_values_ = add_checked(anim_values_, n, what);
    if (anim_values_ > kMaxAnimationValues)
        fail("the animations hold more than " + std::to_string(kMaxAnimationValues) + " key values");
    std::vector<float> out(static_cast<size_t>(n));
    const int size = tinygltf::GetComponentSizeInBytes(uint32_t(ct));
    for (uint64_t i = 0; i < v.count; ++i) {
        const unsigned char *e = v.first + i * v.stride;
        for (int c = 0; c < components; ++c) {
            const unsigned char *p = e + c * size;
            float f;
            switch (ct) {
                case TINYGLTF_COMPONENT_TYPE_BYTE: f = std::max(float(int8_t(p[0])) / 127.0f, -1.0f); break;
                case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: f = float(p[0]) / 255.0f; break;
                case TINYGLTF_COMPONENT_TYPE_SHORT: f = std::max(float(load<int16_t>(p)) / 32767.0f, -1.0f); break;
                case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: f = float(load<uint16_t>(p)) / 65535.0f; break;
                default: f = load<float>(p); break;
            }
            if (!std::isfinite(f)) fail(what + ": element " + std::to_string(i) + " is not finite");
            out[size_t(i * uint64_t(components) + uint64_t(c))] = f;
        }
    }
    s_.anim_data.push_back(std::move(out));
    anim_accessor_data_[size_t(accessor)] = int64_t(s_.anim_data.size() - 1);
    return s_.anim_data.size() - 1;
}

// Every channel of every animation, its sampler checked against glTF 2.0's rules. Which of
// them a render uses (and whether it can) is Rust's decision.
void Converter::convert_animations() {
    anim_accessor_data_.assign(m_.accessors.size(), -1);
    for (size_t a = 0; a < m_.animations.size(); ++a) {
        const tinygltf::Animation &anim = m_.animations[a];
        const std::string alabel = quoted_or_index(anim.name, "animation", a);
        const char *aname = s_.keep(anim.name);
        for (size_t c = 0; c < anim.channels.size(); ++c) {
            const tinygltf::AnimationChannel &ch = anim.channels[c];
            const std::string clabel = alabel + ": channel " + std::to_string(c);
            icr_channel out{};
            out.animation = uint32_t(a);
            out.animation_name = aname;
            const bool node_ok = ch.target_node >= 0 && size_t(ch.target_node) < m_.nodes.size();
            out.node = node_ok ? uint32_t(ch.target_node) : UINT32_MAX;
            if (ch.target_path == "translation") out.path = ICR_ANIM_TRANSLATION;
            else if (ch.target_path == "rotation") out.path = ICR_ANIM_ROTATION;
            else if (ch.target_path == "scale") out.path = ICR_ANIM_SCALE;
            else if (ch.target_path == "weights") out.path = ICR_ANIM_WEIGHTS;
            else out.path = ICR_ANIM_OTHER;
            size_t times = SIZE_MAX, values = SIZE_MAX;
            // A channel that breaks glTF's rules is kept with its reason: a still render
            // never evaluates animations and loads the file as before; a render of frames
            // that needs the channel refuses it, naming the reason.
            try {
                convert_channel(anim, ch, clabel, out, &times, &values);
            } catch (const LoadError &e) {
                out.error = s_.keep(e.what());
                out.key_count = 0;
                out.components = 0;
                times = values = SIZE_MAX;
            }
            s_.channels.push_back(out);
            s_.channel_data.emplace_back(times, values);
        }
    }
}

// Reads one channel's sampler into `out` (the indices of its times and values in
// s_.anim_data), or fails with the rule it breaks.
void Converter::convert_channel(const tinygltf::Animation &anim, const tinygltf::AnimationChannel &ch,
                                const std::string &clabel, icr_channel &out, size_t *times_out, size_t *values_out) {
    if (out.node == UINT32_MAX) fail(clabel + ": target node " + std::to_string(ch.target_node) + " out of range");
    if (ch.sampler < 0 || size_t(ch.sampler) >= anim.samplers.size())
        fail(clabel + ": sampler " + std::to_string(ch.sampler) + " out of range");
    const tinygltf::AnimationSampler &sampler = anim.samplers[size_t(ch.sampler)];
    if (sampler.interpolation == "LINEAR") out.interpolation = ICR_INTERP_LINEAR;
    else if (sampler.interpolation == "STEP") out.interpolation = ICR_INTERP_STEP;
    else if (sampler.interpolation == "CUBICSPLINE") out.interpolation = ICR_INTERP_CUBICSPLINE;
    else
        fail(clabel + ": interpolation '" + shorten(sampler.interpolation) + "' is not LINEAR, STEP or CUBICSPLINE");
    // Not read: morph targets are not supported, and other paths belong to extensions this
    // loader does not implement.
    if (out.path == ICR_ANIM_WEIGHTS || out.path == ICR_ANIM_OTHER) return;
    const tinygltf::Node &target = m_.nodes[out.node];
    if (!target.matrix.empty())
        fail(clabel + ": " + quoted_or_index(target.name, "node", out.node) +
             " has a matrix and is animated (glTF 2.0 allows animating only nodes given by translation, "
             "rotation and scale)");
    const bool rotation = out.path == ICR_ANIM_ROTATION;
    const uint32_t components = rotation ? 4 : 3;
    const size_t times = animation_floats(sampler.input, clabel + ": input (key times)", true, false, 1);
    const size_t values = animation_floats(sampler.output, clabel + ": output", false, rotation, int(components));
    const std::vector<float> &t = s_.anim_data[times];
    if (t.size() > std::numeric_limits<uint32_t>::max() / 3) fail(clabel + ": too many keys");
    for (size_t k = 1; k < t.size(); ++k)
        if (!(t[k] > t[k - 1])) {
            char buf[160];
            std::snprintf(buf, sizeof buf, "key times must increase strictly, but key %zu is at %g s after %g s", k,
                          double(t[k]), double(t[k - 1]));
            fail(clabel + ": " + buf);
        }
    const uint64_t per_key = out.interpolation == ICR_INTERP_CUBICSPLINE ? 3 : 1;
    const uint64_t outputs = s_.anim_data[values].size() / components;
    if (outputs != per_key * t.size())
        fail(clabel + ": " + std::to_string(outputs) + " outputs for " + std::to_string(t.size()) + " key times (" +
             sampler.interpolation + " needs " +
             (per_key == 3 ? "three per key: in-tangent, value, out-tangent" : "one per key") + ")");
    if (per_key == 3 && t.size() < 2) fail(clabel + ": CUBICSPLINE needs at least two keys");
    out.components = components;
    out.key_count = uint32_t(t.size());
    *times_out = times;
    *values_out = values;
}

}  // namespace icr_io
