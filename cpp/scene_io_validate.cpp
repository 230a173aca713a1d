// Validation and hardening: checked arithmetic on the file's numbers, quoting names from the file
// safely, the limits on what a file may make the loader allocate (images, memory, node visits),
// and the screening of the JSON before tinygltf sees it.
//
// Part of the glTF loader (see scene_io.cpp and scene_io_internal.h).

#include "scene_io_internal.h"

// The JSON parser tinygltf itself uses, for screening the file before tinygltf sees it, included
// as tinygltf includes it (its symbols hidden), so that both see one and the same library.
#ifdef __GNUC__
#pragma GCC visibility push(hidden)
#endif
#include <nlohmann/json.hpp>
#ifdef __GNUC__
#pragma GCC visibility pop
#endif

namespace icr_io {

// 64-bit checked arithmetic: offsets and counts come straight from the file.
uint64_t add_checked(uint64_t a, uint64_t b, const std::string &what) {
    uint64_t r;
    if (__builtin_add_overflow(a, b, &r)) fail(what + ": size overflow");
    return r;
}

uint64_t mul_checked(uint64_t a, uint64_t b, const std::string &what) {
    uint64_t r;
    if (__builtin_mul_overflow(a, b, &r)) fail(what + ": size overflow");
    return r;
}

// A name or URI from the file, made fit for quoting in a one-line message: control characters
// escaped (a name must not start a line of its own, or move the terminal's cursor), and cut (a
// data URI can be megabytes long) at a UTF-8 sequence boundary.
std::string shorten(const std::string &text, size_t max) {
    size_t n = text.size();
    if (n > max) {
        n = max;
        while (n > 0 && (static_cast<unsigned char>(text[n]) & 0xC0) == 0x80) --n;
    }
    std::string out;
    out.reserve(n + 8);
    for (size_t i = 0; i < n; ++i) {
        const unsigned char c = static_cast<unsigned char>(text[i]);
        if (c >= 0x20 && c != 0x7F) {
            out.push_back(char(c));
        } else if (c == '\n') {
            out += "\\n";
        } else if (c == '\r') {
            out += "\\r";
        } else if (c == '\t') {
            out += "\\t";
        } else if (c == 0) {
            out += "\\0";
        } else {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\x%02x", c);
            out += buf;
        }
    }
    if (n < text.size()) out += "...";
    return out;
}

// Rejects JSON nested deeper than kMaxJsonDepth (see there for why). Brackets inside strings are
// skipped; anything malformed is left for the real parser to report.
void check_json_depth(const unsigned char *p, size_t n) {
    size_t depth = 0;
    bool in_string = false, escaped = false;
    for (size_t i = 0; i < n; ++i) {
        unsigned char c = p[i];
        if (in_string) {
            if (escaped) escaped = false;
            else if (c == '\\') escaped = true;
            else if (c == '"') in_string = false;
        } else if (c == '"') {
            in_string = true;
        } else if (c == '{' || c == '[') {
            if (++depth > kMaxJsonDepth) fail("JSON nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
        } else if (c == '}' || c == ']') {
            if (depth > 0) --depth;
        }
    }
}

// The media types tinygltf 2.7 decodes as base64 data URIs; any other "data:" URI it would take
// for a file name.
const char *const kDataUriHeaders[] = {
    "data:application/octet-stream;base64,", "data:application/gltf-buffer;base64,", "data:image/jpeg;base64,",
    "data:image/png;base64,",                "data:image/bmp;base64,",               "data:image/gif;base64,",
    "data:text/plain;base64,",
};

// Bytes tinygltf's base64 decoder produces from a data URI: it stops at the first '=' or
// non-base64 character and drops an incomplete last group's partial byte.
bool data_uri_payload_size(const std::string &uri, uint64_t *size) {
    for (const char *h : kDataUriHeaders) {
        size_t n = std::strlen(h);
        if (uri.compare(0, n, h) != 0) continue;
        uint64_t chars = 0;
        for (size_t i = n; i < uri.size(); ++i) {
            unsigned char c = static_cast<unsigned char>(uri[i]);
            bool b64 = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '+' || c == '/';
            if (!b64) break;
            ++chars;
        }
        *size = chars / 4 * 3 + (chars % 4 ? chars % 4 - 1 : 0);
        return true;
    }
    return false;
}

// Where and why nlohmann's parser stopped, without its "[json.exception...]" tag: "line L,
// column C: reason".
std::string json_error_place(const nlohmann::json::parse_error &e) {
    std::string what = e.what();
    const std::string marker = "parse error at ";
    size_t at = what.find(marker);
    if (at != std::string::npos) return what.substr(at + marker.size());
    return "byte " + std::to_string(e.byte) + ": " + what;
}

// A glTF 2.0 file is a JSON object with an "asset" object whose "version" is "<major>.<minor>":
// files of another major version, or whose "minVersion" asks for more than 2.0, cannot be read
// as glTF 2.0 and are refused rather than half-read.
void check_asset(const nlohmann::json &doc) {
    if (!doc.is_object()) fail("not a glTF file: the JSON is not an object");
    auto asset = doc.find("asset");
    if (asset == doc.end()) fail("not a glTF file: no \"asset\" object (every glTF file has one)");
    if (!asset->is_object()) fail("\"asset\" is not an object");
    auto parse_version = [](const nlohmann::json &v, unsigned long *major, unsigned long *minor) {
        if (!v.is_string()) return false;
        const std::string &text = v.get_ref<const std::string &>();
        size_t dot = text.find('.');
        if (dot == 0 || dot == std::string::npos || dot + 1 == text.size()) return false;
        for (size_t i = 0; i < text.size(); ++i)
            if (i != dot && !(text[i] >= '0' && text[i] <= '9')) return false;
        if (dot > 9 || text.size() - dot - 1 > 9) return false;
        *major = std::stoul(text.substr(0, dot));
        *minor = std::stoul(text.substr(dot + 1));
        return true;
    };
    unsigned long major = 0, minor = 0;
    auto version = asset->find("version");
    if (version == asset->end()) fail("\"asset\" has no \"version\" (a glTF 2.0 file says \"2.0\")");
    if (!parse_version(*version, &major, &minor))
        fail("asset.version " + shorten(version->dump(), 32) + " is not a version of the form \"2.0\"");
    if (major != 2)
        fail("asset.version \"" + std::to_string(major) + "." + std::to_string(minor) +
             "\": only glTF 2.x files can be read");
    auto min_version = asset->find("minVersion");
    if (min_version != asset->end()) {
        unsigned long min_major = 0, min_minor = 0;
        if (!parse_version(*min_version, &min_major, &min_minor))
            fail("asset.minVersion " + shorten(min_version->dump(), 32) + " is not a version of the form \"2.0\"");
        if (min_major != 2 || min_minor > 0)
            fail("asset.minVersion \"" + std::to_string(min_major) + "." + std::to_string(min_minor) +
                 "\": this loader reads glTF 2.0");
        if (min_minor > minor)
            fail("asset.minVersion is above asset.version");
    }
}

// Checks made on the JSON before tinygltf sees it, where tinygltf itself would misbehave or give
// an unreadable message:
// - A node with both a matrix and TRS: tinygltf keeps the matrix and drops the rest silently.
// - Text that is not JSON at all (a stray file, a .obj renamed): tinygltf passes on the JSON
//   parser's raw exception text; here the file is said not to be glTF, with the line and
//   column where parsing stopped. The asset object and version are checked (check_asset).
// - tinygltf 2.7 forms &buffer.data[bufferView.byteOffset] for an image stored in a bufferView
//   before anything checks that range; under _GLIBCXX_ASSERTIONS (hardened toolchains) that
//   alone aborts the process. Such files are refused first. Once tinygltf accepts a buffer its
//   data size equals the declared byteLength, so the declared values are what matters.
// - A buffer's data URI must hold exactly byteLength bytes; tinygltf refuses it otherwise but
//   quotes the whole URI (megabytes) in its message. A "data:" URI of a media type tinygltf
//   does not decode would be looked up as a file name.
void screen_json(const unsigned char *text, size_t n) {
    using nlohmann::json;
    // Only the few members involved are kept; everything else is discarded while parsing.
    json::parser_callback_t keep_needed = [](int depth, json::parse_event_t event, json &parsed) {
        if (event != json::parse_event_t::key || !parsed.is_string()) return true;
        const std::string &k = parsed.get_ref<const std::string &>();
        if (depth == 1) return k == "asset" || k == "images" || k == "bufferViews" || k == "buffers" || k == "nodes";
        if (depth == 3)
            return k == "bufferView" || k == "buffer" || k == "byteOffset" || k == "byteLength" || k == "uri" ||
                   k == "matrix" || k == "translation" || k == "rotation" || k == "scale";
        return true;
    };
    json doc;
    try {
        doc = json::parse(text, text + n, keep_needed);
    } catch (const json::parse_error &e) {
        fail("not a glTF file: not valid JSON (" + json_error_place(e) + ")");
    }
    check_asset(doc);
    auto array = [&](const char *key) -> const json * {
        auto it = doc.find(key);
        return it != doc.end() && it->is_array() ? &*it : nullptr;
    };
    const json *images = array("images"), *views = array("bufferViews"), *buffers = array("buffers");
    // glTF 2.0: a node has a matrix or translation/rotation/scale, not both; tinygltf
    // would drop the latter without a word.
    if (const json *nodes = array("nodes")) {
        for (size_t i = 0; i < nodes->size(); ++i) {
            const json &node = (*nodes)[i];
            if (node.is_object() && node.contains("matrix") &&
                (node.contains("translation") || node.contains("rotation") || node.contains("scale")))
                fail("node " + std::to_string(i) +
                     ": has both a matrix and translation/rotation/scale (glTF allows one or the other)");
        }
    }
    auto unsigned_member = [](const json &o, const char *key, uint64_t dflt) -> uint64_t {
        auto it = o.find(key);
        return it != o.end() && it->is_number_unsigned() ? it->get<uint64_t>() : dflt;
    };
    if (buffers) {
        for (size_t i = 0; i < buffers->size(); ++i) {
            const json &buf = (*buffers)[i];
            if (!buf.is_object()) continue;
            auto uri_it = buf.find("uri");
            if (uri_it == buf.end() || !uri_it->is_string()) continue;
            const std::string &uri = uri_it->get_ref<const std::string &>();
            if (!starts_with_ci(uri, "data:")) continue;
            const std::string what = "buffer " + std::to_string(i) + ": data URI '" + shorten(uri, 48) + "'";
            uint64_t holds;
            if (!data_uri_payload_size(uri, &holds))
                fail(what + " is not base64 data of a supported media type (application/octet-stream)");
            auto len_it = buf.find("byteLength");
            if (len_it == buf.end() || !len_it->is_number_unsigned()) continue;  // tinygltf's error
            uint64_t declared = len_it->get<uint64_t>();
            if (holds != declared)
                fail(what + " holds " + std::to_string(holds) + " bytes, but the buffer's byteLength is " +
                     std::to_string(declared));
        }
    }
    if (!images || !views || !buffers) return;
    for (size_t i = 0; i < images->size(); ++i) {
        const json &img = (*images)[i];
        if (!img.is_object()) continue;
        auto bv_it = img.find("bufferView");
        if (bv_it == img.end() || !bv_it->is_number_unsigned()) continue;
        uint64_t bvi = bv_it->get<uint64_t>();
        if (bvi >= views->size() || !(*views)[bvi].is_object()) continue;  // tinygltf checks this
        const json &bv = (*views)[bvi];
        uint64_t bi = unsigned_member(bv, "buffer", UINT64_MAX);
        if (bi >= buffers->size() || !(*buffers)[bi].is_object()) continue;  // tinygltf checks this
        uint64_t buffer_len = unsigned_member((*buffers)[bi], "byteLength", 0);
        uint64_t off = unsigned_member(bv, "byteOffset", 0), len = unsigned_member(bv, "byteLength", 0);
        uint64_t end;
        if (off >= buffer_len || __builtin_add_overflow(off, len, &end) || end > buffer_len)
            fail("image[" + std::to_string(i) + "]: bufferView " + std::to_string(bvi) + " (offset " +
                 std::to_string(off) + ", length " + std::to_string(len) + ") exceeds buffer " + std::to_string(bi) +
                 " of " + std::to_string(buffer_len) + " bytes");
    }
}

// Limits on what a file may make the loader allocate
std::string human_bytes(uint64_t bytes) {
    char buf[64];
    if (bytes == UINT64_MAX) return "more than 16 EiB";
    const char *units[] = {"bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
    double v = double(bytes);
    size_t u = 0;
    while (v >= 1024.0 && u + 1 < sizeof units / sizeof *units) {
        v /= 1024.0;
        ++u;
    }
    if (u == 0)
        std::snprintf(buf, sizeof buf, "%llu bytes", static_cast<unsigned long long>(bytes));
    else
        std::snprintf(buf, sizeof buf, "%.1f %s", v, units[u]);
    return buf;
}

// How much memory a loaded scene may take: ICRENDER_MAX_SCENE_MEMORY_MB (MiB) when set, for
// tests and fuzzing; else the machine's physical memory, or the cgroup's limit when lower.
uint64_t scene_memory_limit_of_machine(std::string *what);

// The caller's limit for the load in progress on this thread (--max-memory); 0 when none.
thread_local uint64_t t_requested_limit = 0;

uint64_t scene_memory_limit(std::string *what) {
    if (t_requested_limit > 0) {
        std::string machine;
        const uint64_t other = scene_memory_limit_of_machine(&machine);
        if (t_requested_limit <= other) {
            *what = "--max-memory";
            return t_requested_limit;
        }
        *what = machine;
        return other;
    }
    return scene_memory_limit_of_machine(what);
}

uint64_t scene_memory_limit_of_machine(std::string *what) {
    if (const char *env = std::getenv("ICRENDER_MAX_SCENE_MEMORY_MB")) {
        char *end = nullptr;
        errno = 0;
        unsigned long long mb = std::strtoull(env, &end, 10);
        if (end != env && *end == '\0' && errno == 0 && mb > 0 && mb < (1ull << 40)) {
            *what = "the limit set by ICRENDER_MAX_SCENE_MEMORY_MB";
            return uint64_t(mb) << 20;
        }
    }
    uint64_t limit = UINT64_MAX;
    *what = "this machine's memory";
    const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
    if (pages > 0 && page > 0) limit = uint64_t(pages) * uint64_t(page);
    if (FILE *f = std::fopen("/sys/fs/cgroup/memory.max", "r")) {
        unsigned long long v = 0;
        if (std::fscanf(f, "%llu", &v) == 1 && v > 0 && v < limit) {
            limit = v;
            *what = "the memory limit of this process's cgroup";
        }
        std::fclose(f);
    }
    return limit;
}

// The width and height in a PNG (IHDR) or JPEG (first SOFn) header; false for other formats
// or a header too short to say.
bool header_extent(const unsigned char *p, uint64_t size, uint32_t *w, uint32_t *h) {
    auto be16 = [&](uint64_t o) { return uint32_t(p[o]) << 8 | p[o + 1]; };
    auto be32 = [&](uint64_t o) { return be16(o) << 16 | be16(o + 2); };
    static const unsigned char png_sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    if (size >= 24 && std::memcmp(p, png_sig, 8) == 0 && std::memcmp(p + 12, "IHDR", 4) == 0) {
        *w = be32(16);
        *h = be32(20);
        return true;
    }
    if (size < 4 || p[0] != 0xFF || p[1] != 0xD8) return false;
    uint64_t o = 2;
    while (o + 4 <= size) {
        if (p[o] != 0xFF) return false;
        const unsigned m = p[o + 1];
        if (m == 0xFF) {  // fill byte
            ++o;
            continue;
        }
        if (m == 0xD9 || m == 0xDA) return false;  // EOI or SOS before any frame header
        if (m == 0x01 || (m >= 0xD0 && m <= 0xD7)) {  // markers without a length
            o += 2;
            continue;
        }
        const uint64_t len = be16(o + 2);
        if (m >= 0xC0 && m <= 0xCF && m != 0xC4 && m != 0xC8 && m != 0xCC) {
            if (o + 9 > size) return false;
            *h = be16(o + 5);
            *w = be16(o + 7);
            return true;
        }
        if (len < 2) return false;
        o += 2 + len;
    }
    return false;
}

// Checks the width and height an image header declares, before decoding: against fixed limits,
// and against what the encoded bytes can possibly hold (a header is cheap to forge, pixels are
// not). The bounds are the formats' best compression ratios: deflate (PNG) cannot expand one
// byte into more than 1032, baseline and progressive Huffman JPEG (stb has no arithmetic
// coding) spend at least one bit per 8x8 block and component; the other formats stb reads get
// PNG's bound for one-bit pixels.
void check_declared_extent(const std::string &what, const unsigned char *bytes, uint64_t size, int64_t w, int64_t h) {
    if (w <= 0 || h <= 0) fail(what + " has no pixels");
    const uint64_t uw = uint64_t(w), uh = uint64_t(h), pixels = uw * uh;
    if (uw > kMaxImageSide || uh > kMaxImageSide || pixels > kMaxImagePixels)
        fail(what + " declares " + std::to_string(uw) + " x " + std::to_string(uh) +
             " pixels, more than the limit of " + std::to_string(kMaxImageSide) + " per side and " +
             std::to_string(kMaxImagePixels) + " in all");
    static const unsigned char png_sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    const char *format = "image";
    uint64_t need = 0, can = 0;
    if (size >= 26 && std::memcmp(bytes, png_sig, 8) == 0 && std::memcmp(bytes + 12, "IHDR", 4) == 0) {
        // Raw scanlines: a filter byte and the packed samples per row.
        const unsigned depth = bytes[24], type = bytes[25];
        const unsigned channels = type == 0 ? 1 : type == 2 ? 3 : type == 3 ? 1 : type == 4 ? 2 : type == 6 ? 4 : 0;
        if (channels && depth && depth <= 16) {
            format = "PNG";
            need = uh * (1 + (uw * channels * depth + 7) / 8);
            can = 1032 * size;
        }
    } else if (size >= 2 && bytes[0] == 0xFF && bytes[1] == 0xD8) {
        format = "JPEG";
        need = pixels;
        can = 512 * size + 4096;
    }
    if (can == 0) {
        need = pixels;
        can = 8 * 1032 * size;
    }
    if (need > can)
        fail(what + " declares " + std::to_string(uw) + " x " + std::to_string(uh) + " pixels, more than its " +
             std::to_string(size) + " bytes of " + format + " data can hold");
}

std::string Converter::quoted_or_index(const std::string &name, const char *kind, size_t index) {
    if (!name.empty()) return std::string(kind) + " '" + shorten(name) + "'";
    return std::string(kind) + " " + std::to_string(index);
}

// What a mesh's triangle primitives take as icr_mesh arrays, from accessor counts checked
// against their buffers (view_accessor). A primitive that the conversion will skip or
// refuse counts nothing here; the conversion says why.
const Converter::MeshCost &Converter::mesh_cost(size_t mi) {
    MeshCost &c = mesh_cost_[mi];
    if (c.done) return c;
    c.done = true;
    for (const tinygltf::Primitive &prim : m_.meshes[mi].primitives) {
        if (prim.mode != TINYGLTF_MODE_TRIANGLES) continue;
        auto pos = prim.attributes.find("POSITION");
        if (pos == prim.attributes.end()) continue;
        try {
            const uint64_t nv = view_accessor(m_, pos->second, "POSITION").count;
            uint64_t per_vertex = 12;
            if (prim.attributes.count("NORMAL")) per_vertex += 12;
            if (prim.attributes.count("TEXCOORD_0")) per_vertex += 8;
            const uint64_t ni = prim.indices >= 0 ? view_accessor(m_, prim.indices, "indices").count : nv;
            c.bytes = sat_add(c.bytes, sat_add(sat_mul(nv, per_vertex), sat_mul(ni, 4)));
            c.triangles = sat_add(c.triangles, ni / 3);
            c.primitives = sat_add(c.primitives, 1);
        } catch (const LoadError &) {
            // reported by the conversion, with its context
        }
    }
    return c;
}

uint64_t Converter::sat_add(uint64_t a, uint64_t b) {
    uint64_t r;
    return __builtin_add_overflow(a, b, &r) ? UINT64_MAX : r;
}

uint64_t Converter::sat_mul(uint64_t a, uint64_t b) {
    uint64_t r;
    return __builtin_mul_overflow(a, b, &r) ? UINT64_MAX : r;
}

std::vector<int> Converter::scene_roots() const {
    std::vector<int> roots;
    if (!m_.scenes.empty()) {
        int si = m_.defaultScene >= 0 ? m_.defaultScene : 0;
        if (size_t(si) >= m_.scenes.size()) fail("default scene " + std::to_string(si) + " out of range");
        roots = m_.scenes[size_t(si)].nodes;
    } else {
        std::vector<char> is_child(m_.nodes.size(), 0);
        for (const tinygltf::Node &n : m_.nodes)
            for (int c : n.children)
                if (c >= 0 && size_t(c) < m_.nodes.size()) is_child[size_t(c)] = 1;
        for (size_t i = 0; i < m_.nodes.size(); ++i)
            if (!is_child[i]) roots.push_back(int(i));
        if (roots.empty() && !m_.nodes.empty()) fail("node graph has a cycle (no root nodes)");
    }
    return roots;
}

// One walk over the scene's node trees before anything is converted: refuses cycles, nodes
// used more than once (glTF nodes form disjoint trees; a node reused by several parents
// would let a small file expand exponentially) and nesting deeper than kMaxNodeDepth, then
// works out the memory the loaded scene will take and refuses the scene if that is more
// than the machine has: the arrays made here, the renderer's copy of them, its world-space
// copy of every mesh placed once (of every placed mesh with ICR_LOAD_FLATTEN; a mesh placed
// more often is held once more, by Embree), and the decoded textures (RGBA here and in the renderer, and
// the renderer's linear float copy).
void Converter::check_graph_and_memory() {
    mesh_cost_.assign(m_.meshes.size(), MeshCost{});
    extent_w_.assign(m_.images.size(), 0);
    extent_h_.assign(m_.images.size(), 0);
    std::vector<char> reached(m_.nodes.size(), 0), on_path(m_.nodes.size(), 0);
    std::vector<uint64_t> uses(m_.meshes.size(), 0);  // placements of each mesh
    std::vector<std::pair<size_t, size_t>> path;  // node, next child
    auto enter = [&](int index, int64_t parent) {
        if (index < 0 || size_t(index) >= m_.nodes.size()) {
            if (parent < 0) fail("scene root node " + std::to_string(index) + " out of range");
            fail(quoted_or_index(m_.nodes[size_t(parent)].name, "node", size_t(parent)) + ": child " +
                 std::to_string(index) + " out of range");
        }
        const size_t ni = size_t(index);
        if (on_path[ni]) fail("node graph has a cycle at node " + std::to_string(index));
        if (reached[ni])
            fail(quoted_or_index(m_.nodes[ni].name, "node", ni) +
                 " is used more than once (glTF nodes form trees: one parent each, and a scene lists each "
                 "root once)");
        if (path.size() > kMaxNodeDepth)
            fail("node graph deeper than " + std::to_string(kMaxNodeDepth) + " levels");
        reached[ni] = on_path[ni] = 1;
        const int mesh = m_.nodes[ni].mesh;
        if (mesh >= 0 && size_t(mesh) < m_.meshes.size()) {
            uint64_t count = 1;
            try {
                GpuInstancing g;
                const std::string label = quoted_or_index(m_.nodes[ni].name, "node", ni);
                if (gpu_instancing(m_.nodes[ni], label, &g, false))
                    count = std::max<uint64_t>(1, gpu_instance_count(g, label));
            } catch (const LoadError &) {
                // reported by the conversion, with its context
            }
            uses[size_t(mesh)] = sat_add(uses[size_t(mesh)], count);
        }
        path.emplace_back(ni, 0);
    };
    for (int root : scene_roots()) {
        enter(root, -1);
        while (!path.empty()) {
            auto &top = path.back();
            const tinygltf::Node &node = m_.nodes[top.first];
            if (top.second < node.children.size()) {
                int child = node.children[top.second++];
                enter(child, int64_t(path.back().first));
            } else {
                on_path[top.first] = 0;
                path.pop_back();
            }
        }
    }

    // A mesh placed once is copied into world space; one placed more often is stored once
    // (in the renderer and in Embree's prototype) unless the renderer flattens everything.
    // Placements are counted per primitive (each is a mesh of its own to the renderer). An
    // instanced placement costs about 1 KiB more than the small allocations every placement
    // has: its transforms, its world-space survey, its object's name and, unless it shares
    // a prototype instance with other meshes, an Embree instance.
    uint64_t distinct = 0, placed = 0, triangles = 0, placements = 0, instanced = 0;
    for (size_t m = 0; m < uses.size(); ++m) {
        if (uses[m] == 0) continue;
        const MeshCost &c = mesh_cost(m);
        const bool copied = flatten_ || uses[m] == 1;
        distinct = sat_add(distinct, c.bytes);
        placed = sat_add(placed, copied ? sat_mul(c.bytes, uses[m]) : c.bytes);
        triangles = sat_add(triangles, sat_mul(c.triangles, uses[m]));
        // Each primitive is a mesh of its own to the renderer, placed by every use.
        const uint64_t primitive_placements = sat_mul(c.primitives, uses[m]);
        placements = sat_add(placements, primitive_placements);
        if (!copied) instanced = sat_add(instanced, primitive_placements);
    }

    // Images are decoded only for textures used as base colour.
    uint64_t texels = 0;
    std::vector<char> image_seen(m_.images.size(), 0);
    for (const tinygltf::Material &mat : m_.materials) {
        int t = mat.pbrMetallicRoughness.baseColorTexture.index;
        if (t < 0 || size_t(t) >= m_.textures.size()) continue;
        int src = m_.textures[size_t(t)].source;
        if (src < 0 || size_t(src) >= m_.images.size() || image_seen[size_t(src)]) continue;
        image_seen[size_t(src)] = 1;
        uint32_t w, h;
        image_extent(size_t(src), &w, &h);
        texels = sat_add(texels, uint64_t(w) * uint64_t(h));
    }

    // Per placement the renderer also keeps a few small allocations (vectors, instance).
    const uint64_t need =
        sat_add(sat_add(sat_add(sat_mul(distinct, 2), placed), sat_mul(instanced, 1024)),
                sat_add(sat_mul(placements, 256), sat_mul(texels, 24)));
    std::string limited_by;
    const uint64_t limit = scene_memory_limit(&limited_by);
    if (need > limit)
        fail("the scene would take about " + human_bytes(need) + " of memory once loaded (" +
             std::to_string(triangles) + " triangles in " + std::to_string(placements) + " mesh placements, " +
             std::to_string(texels) + " texture pixels), more than " + limited_by + " (" + human_bytes(limit) +
             ")");
}

}  // namespace icr_io
