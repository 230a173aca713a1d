// Materials and textures: glTF's PBR materials and their extensions as the ABI's icr_material,
// and the images behind them decoded once, after their declared size is checked.
//
// Part of the glTF loader (see scene_io.cpp and scene_io_internal.h).

#include "scene_io_internal.h"

namespace icr_io {

std::string Converter::image_label(size_t index) const {
    const tinygltf::Image &img = m_.images[index];
    if (!img.uri.empty()) return "'" + shorten(img.uri) + "'";
    if (!img.name.empty()) return "image[" + std::to_string(index) + "] '" + shorten(img.name) + "'";
    return "image[" + std::to_string(index) + "]";
}

// The encoded bytes of a glTF image (from its bufferView, a data URI or a file), with the
// bufferView's range checked against its buffer.
void Converter::image_bytes(size_t index, const unsigned char **bytes, uint64_t *size) const {
    const tinygltf::Image &img = m_.images[index];
    if (img.bufferView >= 0) {
        std::string what = "image " + image_label(index);
        if (size_t(img.bufferView) >= m_.bufferViews.size()) fail(what + ": bufferView out of range");
        const tinygltf::BufferView &bv = m_.bufferViews[size_t(img.bufferView)];
        if (bv.buffer < 0 || size_t(bv.buffer) >= m_.buffers.size()) fail(what + ": buffer out of range");
        const tinygltf::Buffer &buf = m_.buffers[size_t(bv.buffer)];
        if (add_checked(bv.byteOffset, bv.byteLength, what) > buf.data.size())
            fail(what + ": bufferView exceeds its buffer");
        *bytes = buf.data.data() + bv.byteOffset;
        *size = bv.byteLength;
    } else {
        *bytes = img.image.data();
        *size = img.image.size();
    }
    if (*size == 0) {
        if (!img.uri.empty()) fail("missing texture image '" + shorten(img.uri) + "'");
        fail("texture image " + image_label(index) + " has no data");
    }
    if (*size > uint64_t(std::numeric_limits<int>::max()))
        fail("texture image " + image_label(index) + " is too large");
}

// Width and height an image's header declares, read without decoding and checked against
// the limits and against what its encoded bytes can hold, so that no allocation is ever
// made for pixels the file cannot contain.
void Converter::image_extent(size_t index, uint32_t *width, uint32_t *height) {
    if (extent_w_[index] == 0) {
        const unsigned char *bytes = nullptr;
        uint64_t size = 0;
        image_bytes(index, &bytes, &size);
        int w = 0, h = 0, comp = 0;
        // stb_image refuses some huge sizes itself but then says only "corrupt": read the
        // PNG and JPEG headers here so that the message says what the file claims.
        uint32_t hw = 0, hh = 0;
        if (header_extent(bytes, size, &hw, &hh))
            check_declared_extent("texture image " + image_label(index), bytes, size, int64_t(hw), int64_t(hh));
        if (!image_info(bytes, int(size), &w, &h, &comp)) {
            const char *why = image_failure_reason();
            fail("cannot decode texture image " + image_label(index) + ": " + (why ? why : "unknown format"));
        }
        check_declared_extent("texture image " + image_label(index), bytes, size, w, h);
        extent_w_[index] = uint32_t(w);
        extent_h_[index] = uint32_t(h);
    }
    *width = extent_w_[index];
    *height = extent_h_[index];
}

// Returns the index into s_.pixels for a glTF image, decoding it on first use so that
// textures sharing an image share its pixels.
int Converter::decoded_image(size_t index) {
    if (image_pixels_[index] >= 0) return image_pixels_[index];
    uint32_t ew, eh;
    image_extent(index, &ew, &eh);
    const unsigned char *bytes = nullptr;
    uint64_t size = 0;
    image_bytes(index, &bytes, &size);
    int w = 0, h = 0, comp = 0;
    // Asking stb for 4 channels expands grey/grey+alpha/RGB to RGBA, and stbi_load (not _16)
    // reduces 16-bit PNGs to 8 bits, which is exactly the icr_texture format.
    unsigned char *px = image_load_rgba(bytes, int(size), &w, &h, &comp);
    if (!px) {
        const char *why = image_failure_reason();
        fail("cannot decode texture image " + image_label(index) + ": " + (why ? why : "unknown format"));
    }
    std::vector<uint8_t> rgba;
    try {
        if (w <= 0 || h <= 0) fail("texture image " + image_label(index) + " has no pixels");
        if (uint32_t(w) != ew || uint32_t(h) != eh)
            fail("texture image " + image_label(index) + " decodes to another size than its header says");
        rgba.assign(px, px + size_t(w) * size_t(h) * 4);
    } catch (...) {
        image_free(px);
        throw;
    }
    image_free(px);
    s_.pixels.push_back(std::move(rgba));
    image_pixels_[index] = int(s_.pixels.size() - 1);
    image_w_[index] = uint32_t(w);
    image_h_[index] = uint32_t(h);
    return image_pixels_[index];
}

void Converter::convert_textures_and_materials() {
    image_pixels_.assign(m_.images.size(), -1);
    image_w_.assign(m_.images.size(), 0);
    image_h_.assign(m_.images.size(), 0);

    // icr textures exist only for glTF textures used as base colour, in glTF texture order.
    std::vector<char> used(m_.textures.size(), 0);
    for (size_t i = 0; i < m_.materials.size(); ++i) {
        int t = m_.materials[i].pbrMetallicRoughness.baseColorTexture.index;
        if (t < 0) continue;
        if (size_t(t) >= m_.textures.size())
            fail(quoted_or_index(m_.materials[i].name, "material", i) + ": baseColorTexture " +
                 std::to_string(t) + " out of range");
        used[size_t(t)] = 1;
    }
    std::vector<int32_t> tex_map(m_.textures.size(), -1);
    for (size_t t = 0; t < m_.textures.size(); ++t) {
        if (!used[t]) continue;
        const tinygltf::Texture &tex = m_.textures[t];
        std::string label = quoted_or_index(tex.name, "texture", t);
        if (tex.source < 0) {
            // Only possible with an image-format extension (e.g. KHR_texture_basisu) that is
            // not required, so the file allows rendering without it.
            warnings.push_back(label + " has no core image source; base colour texture ignored");
            continue;
        }
        if (size_t(tex.source) >= m_.images.size())
            fail(label + ": image " + std::to_string(tex.source) + " out of range");
        icr_texture out{};
        size_t src = size_t(tex.source);
        out.rgba = s_.pixels[size_t(decoded_image(src))].data();
        out.width = image_w_[src];
        out.height = image_h_[src];
        out.wrap_s = out.wrap_t = TINYGLTF_TEXTURE_WRAP_REPEAT;
        if (tex.sampler >= 0) {
            if (size_t(tex.sampler) >= m_.samplers.size())
                fail(label + ": sampler " + std::to_string(tex.sampler) + " out of range");
            out.wrap_s = m_.samplers[size_t(tex.sampler)].wrapS;
            out.wrap_t = m_.samplers[size_t(tex.sampler)].wrapT;
        }
        // Rust only has to understand the three modes glTF defines.
        for (int32_t *wrap : {&out.wrap_s, &out.wrap_t}) {
            if (*wrap != TINYGLTF_TEXTURE_WRAP_REPEAT && *wrap != TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE &&
                *wrap != TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT) {
                warnings.push_back(label + ": unknown sampler wrap mode " + std::to_string(*wrap) +
                                   ", using REPEAT");
                *wrap = TINYGLTF_TEXTURE_WRAP_REPEAT;
            }
        }
        out.srgb = 1;
        std::string name = tex.name;
        if (name.empty()) name = m_.images[src].name;
        if (name.empty()) name = m_.images[src].uri;
        out.name = s_.keep(name);
        tex_map[t] = int32_t(s_.textures.size());
        s_.textures.push_back(out);
    }

    for (size_t i = 0; i < m_.materials.size(); ++i) {
        const tinygltf::Material &mat = m_.materials[i];
        const std::string label = quoted_or_index(mat.name, "material", i);
        const tinygltf::PbrMetallicRoughness &pbr = mat.pbrMetallicRoughness;
        icr_material out{};
        out.name = s_.keep(mat.name);
        for (int c = 0; c < 4; ++c)
            out.base_color[c] = pbr.baseColorFactor.size() == 4 ? float(pbr.baseColorFactor[size_t(c)]) : 1.0f;
        out.base_color_texture = -1;
        if (pbr.baseColorTexture.index >= 0) {
            out.base_color_texture = tex_map[size_t(pbr.baseColorTexture.index)];
            if (pbr.baseColorTexture.texCoord != 0)
                warnings.push_back(label + ": baseColorTexture uses TEXCOORD_" +
                                   std::to_string(pbr.baseColorTexture.texCoord) +
                                   ", only TEXCOORD_0 is loaded");
            if (pbr.baseColorTexture.extensions.count("KHR_texture_transform"))
                warnings.push_back(label + ": KHR_texture_transform on baseColorTexture is ignored");
        }
        out.metallic = float(pbr.metallicFactor);
        out.roughness = float(pbr.roughnessFactor);
        for (int c = 0; c < 3; ++c)
            out.emissive[c] = mat.emissiveFactor.size() == 3 ? float(mat.emissiveFactor[size_t(c)]) : 0.0f;

        out.emissive_strength = 1.0f;
        auto es = mat.extensions.find("KHR_materials_emissive_strength");
        if (es != mat.extensions.end()) {
            double v;
            if (number_member(es->second, "emissiveStrength", &v)) out.emissive_strength = float(v);
        }
        out.specular_factor = 1.0f;
        out.specular_color[0] = out.specular_color[1] = out.specular_color[2] = 1.0f;
        auto sp = mat.extensions.find("KHR_materials_specular");
        if (sp != mat.extensions.end()) {
            double v;
            if (number_member(sp->second, "specularFactor", &v)) out.specular_factor = float(v);
            double col[3];
            if (number_array_member(sp->second, "specularColorFactor", col, 3))
                for (int c = 0; c < 3; ++c) out.specular_color[c] = float(col[c]);
        }

        if (mat.alphaMode == "OPAQUE") {
            out.alpha_mode = ICR_ALPHA_OPAQUE;
        } else if (mat.alphaMode == "MASK") {
            out.alpha_mode = ICR_ALPHA_MASK;
        } else if (mat.alphaMode == "BLEND") {
            out.alpha_mode = ICR_ALPHA_BLEND;
        } else {
            warnings.push_back(label + ": unknown alphaMode '" + shorten(mat.alphaMode) + "', using OPAQUE");
            out.alpha_mode = ICR_ALPHA_OPAQUE;
        }
        out.alpha_cutoff = float(mat.alphaCutoff);
        out.double_sided = mat.doubleSided ? 1 : 0;
        s_.materials.push_back(out);
    }
}

bool Converter::number_member(const tinygltf::Value &obj, const char *key, double *out) {
    if (!obj.IsObject() || !obj.Has(key)) return false;
    const tinygltf::Value &v = obj.Get(key);
    if (!v.IsNumber()) return false;
    *out = v.GetNumberAsDouble();
    return true;
}

bool Converter::number_array_member(const tinygltf::Value &obj, const char *key, double *out, size_t n) {
    if (!obj.IsObject() || !obj.Has(key)) return false;
    const tinygltf::Value &v = obj.Get(key);
    if (!v.IsArray() || v.ArrayLen() != n) return false;
    for (size_t i = 0; i < n; ++i) {
        const tinygltf::Value &e = v.Get(int(i));
        if (!e.IsNumber()) return false;
        out[i] = e.GetNumberAsDouble();
    }
    return true;
}

}  // namespace icr_io
