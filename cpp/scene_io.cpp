// glTF loading for icrender (implements ffi/scene_io.h on top of tinygltf 2.7).
//
// This file is only an adapter: it validates what it reads, converts to the flat arrays of the C
// ABI and leaves every rendering decision (degenerate triangles, NaNs, units, light models) to
// Rust. Nothing may escape across the ABI: every entry point catches all exceptions, and every
// index, offset and size taken from the file is checked before memory is touched.

#include "../ffi/scene_io.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <exception>
#include <initializer_list>
#include <limits>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
// glTF buffers are little-endian and are read here with memcpy.
#error "scene_io.cpp assumes a little-endian target"
#endif

// stb_image is compiled static so that this object cannot clash with another copy of stb linked
// into the final binary by some other crate; tinygltf is the only caller and lives in this TU.
#define STB_IMAGE_STATIC
// Readable decode errors ("Corrupt PNG") instead of stb's terse codes; they reach the user.
#define STBI_FAILURE_USERMSG
#define STB_IMAGE_IMPLEMENTATION
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE_WRITE
#include <tiny_gltf.h>

namespace {

// Internal failure; turned into the one-line error message at the ABI boundary.
struct LoadError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// A NUL byte (from a name or URI in the file) would silently cut the message short.
[[noreturn]] void fail(std::string msg) {
    for (size_t i = msg.find('\0'); i != std::string::npos; i = msg.find('\0', i + 2)) msg.replace(i, 1, "\\0");
    throw LoadError(msg);
}

constexpr size_t kMaxNodeDepth = 1024;
// Decoded texture images: wider than any GPU texture is refused before decoding (and so before
// allocating), as is a total that would need more than 1 GiB of RGBA.
constexpr uint64_t kMaxImageSide = 32768;
constexpr uint64_t kMaxImagePixels = uint64_t(1) << 28;
// Names and URIs quoted in messages are cut to this many bytes.
constexpr size_t kMaxQuoted = 96;
// Warnings beyond this many are summarised in one line.
constexpr size_t kMaxWarnings = 100;
// Nodes reused by several parents (which could expand exponentially) are refused before the
// walk, so the walk visits each node once; this bound is a second line of defence.
constexpr uint64_t kMaxNodeVisits = uint64_t(1) << 26;
// tinygltf converts "extensions" objects to its Value type recursively; deep nesting there would
// overflow the stack, so the JSON is screened before tinygltf sees it.
constexpr size_t kMaxJsonDepth = 256;
constexpr double kHalfPi = 1.57079632679489661923;
// Key times and values of all animations together (floats): a bound on what a file can make
// the loader allocate beyond its buffers.
constexpr uint64_t kMaxAnimationValues = uint64_t(1) << 26;

// tinygltf messages are newline-terminated lines; callers want single lines.
std::vector<std::string> split_lines(const std::string &text) {
    std::vector<std::string> lines;
    std::string cur;
    auto flush = [&]() {
        size_t b = cur.find_first_not_of(" \t");
        size_t e = cur.find_last_not_of(" \t");
        if (b != std::string::npos) lines.push_back(cur.substr(b, e - b + 1));
        cur.clear();
    };
    for (char c : text) {
        if (c == '\n' || c == '\r') {
            flush();
        } else {
            cur.push_back(static_cast<unsigned char>(c) < 0x20 ? ' ' : c);
        }
    }
    flush();
    return lines;
}

std::string join(const std::vector<std::string> &parts, const char *sep) {
    std::string out;
    for (size_t i = 0; i < parts.size(); ++i) {
        if (i) out += sep;
        out += parts[i];
    }
    return out;
}

std::string one_line(const std::string &text) { return join(split_lines(text), "; "); }

void write_error(char *err, size_t err_len, const std::string &msg) {
    if (!err || err_len == 0) return;
    std::string line = one_line(msg);
    if (line.empty()) line = "unknown error";
    size_t n = std::min(line.size(), err_len - 1);
    // Do not cut a UTF-8 sequence in half: Rust reads this as a str.
    if (n < line.size()) {
        while (n > 0 && (static_cast<unsigned char>(line[n]) & 0xC0) == 0x80) --n;
    }
    std::memcpy(err, line.data(), n);
    err[n] = '\0';
}

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

bool ends_with_ci(const std::string &s, const char *suffix) {
    size_t n = std::strlen(suffix);
    if (s.size() < n) return false;
    for (size_t i = 0; i < n; ++i) {
        char a = s[s.size() - n + i];
        if (a >= 'A' && a <= 'Z') a = char(a - 'A' + 'a');
        if (a != suffix[i]) return false;
    }
    return true;
}

bool is_regular_file(const std::string &path) {
    struct stat st;
    return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

bool starts_with_ci(const std::string &s, const char *prefix) {
    size_t n = std::strlen(prefix);
    if (s.size() < n) return false;
    for (size_t i = 0; i < n; ++i) {
        char a = s[i];
        if (a >= 'A' && a <= 'Z') a = char(a - 'A' + 'a');
        if (a != prefix[i]) return false;
    }
    return true;
}

// A name or URI from the file, made fit for quoting in a one-line message: control characters
// escaped (a name must not start a line of its own, or move the terminal's cursor), and cut (a
// data URI can be megabytes long) at a UTF-8 sequence boundary.
std::string shorten(const std::string &text, size_t max = kMaxQuoted) {
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

std::vector<unsigned char> read_file(const std::string &path) {
    struct stat st;
    if (::stat(path.c_str(), &st) != 0) fail(std::string("cannot open file: ") + std::strerror(errno));
    if (!S_ISREG(st.st_mode)) fail("not a regular file");
    // The size is known before reading: refuse what the loader cannot take before allocating.
    if (uint64_t(st.st_size) > std::numeric_limits<uint32_t>::max()) fail("file is larger than 4 GiB");
    FILE *f = std::fopen(path.c_str(), "rb");
    if (!f) fail(std::string("cannot open file: ") + std::strerror(errno));
    std::vector<unsigned char> data;
    unsigned char chunk[1 << 16];
    size_t n;
    try {
        data.reserve(size_t(st.st_size));
        while ((n = std::fread(chunk, 1, sizeof chunk, f)) > 0) {
            data.insert(data.end(), chunk, chunk + n);
            // The file grew while being read: never past the 4 GiB the ABI can take.
            if (data.size() > std::numeric_limits<uint32_t>::max()) fail("file is larger than 4 GiB");
        }
    } catch (...) {
        std::fclose(f);
        throw;
    }
    bool bad = std::ferror(f) != 0;
    std::fclose(f);
    if (bad) fail("read error");
    return data;
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

// Directory part of the path as tinygltf expects it (it joins with '/').
std::string base_dir_of(const std::string &path) {
    size_t slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    if (slash == 0) return "/";
    return path.substr(0, slash);
}

// ---------------------------------------------------------------------------------------------
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

// ---------------------------------------------------------------------------------------------
// External files (buffers and images named by URI)
//
// tinygltf joins the asset's directory and the URL-decoded URI, asks ExpandFilePath for the
// path to use, FileExists whether it is there, and ReadWholeFile for its bytes; it looks next to
// the asset first and then in the process's current directory. The policy lives in the first
// two callbacks:
// - the current-directory lookup is never admitted (a missing texture must not be silently
//   replaced by an unrelated file);
// - unless ICR_LOAD_ALLOW_OUTSIDE_REFS is given, a URI that leaves the scene's folder is refused:
//   absolute paths, file: URIs, '..' segments climbing out of it (refused whether or not the
//   target exists, so errors do not reveal what exists outside), and files whose real path
//   (symbolic links resolved) lies outside the folder's real path;
// - with the flag, absolute paths and file: URIs (empty or localhost authority) are read as
//   the paths they name;
// - only regular files are read, and what is read is the resolved real path that was checked.
// The first refusal is kept and becomes the load's error message.

struct FileAccess {
    std::string prefix;    // the asset directory as tinygltf writes it, ending in '/'
    std::string real_dir;  // realpath of the asset directory, ending in '/'
    bool allow_outside = false;
    std::string refused;
    // Every buffer and image entry is read on its own, even when many name the same file, so a
    // small file naming a big neighbour many times could ask for any amount of memory: the
    // total is checked against the memory limit before each read.
    uint64_t bytes_read = 0;
    uint64_t read_limit = UINT64_MAX;
    std::string limited_by;
};

// Whether a relative path's '..' segments climb above its starting directory (lexically; symbolic
// links are judged by their real path afterwards).
bool climbs_out(const std::string &rel) {
    int64_t depth = 0;
    size_t i = 0;
    while (i <= rel.size()) {
        size_t j = rel.find('/', i);
        if (j == std::string::npos) j = rel.size();
        const size_t len = j - i;
        if (len == 2 && rel.compare(i, 2, "..") == 0) {
            if (--depth < 0) return true;
        } else if (len > 0 && !(len == 1 && rel[i] == '.')) {
            ++depth;
        }
        i = j + 1;
    }
    return false;
}

// The local path a file: URI names (already URL-decoded by tinygltf), or "" if it names a host.
std::string file_uri_path(const std::string &uri) {
    std::string rest = uri.substr(5);  // after "file:"
    if (rest.compare(0, 2, "//") != 0) return rest;  // file:/path
    rest = rest.substr(2);
    size_t slash = rest.find('/');
    std::string host = slash == std::string::npos ? rest : rest.substr(0, slash);
    if (!host.empty() && !(host.size() == std::strlen("localhost") && starts_with_ci(host, "localhost"))) return {};
    return slash == std::string::npos ? std::string() : rest.substr(slash);
}

std::string real_path(const std::string &path) {
    char *rp = ::realpath(path.c_str(), nullptr);
    if (!rp) return {};
    std::string out(rp);
    std::free(rp);
    return out;
}

std::string expand_file_path(const std::string &joined, void *user) {
    FileAccess &fa = *static_cast<FileAccess *>(user);
    if (joined.compare(0, fa.prefix.size(), fa.prefix) != 0) return {};  // the current-directory lookup
    const std::string uri = joined.substr(fa.prefix.size());
    auto refuse = [&](const std::string &why) {
        if (fa.refused.empty())
            fa.refused = "'" + shorten(uri) + "' " + why +
                         ": refused (--allow-outside-refs allows files outside the scene's folder)";
        return std::string();
    };
    if (uri.find('\0') != std::string::npos) {
        if (fa.refused.empty()) fa.refused = "URI '" + shorten(uri) + "' contains a NUL byte";
        return {};
    }
    std::string target = joined;
    if (starts_with_ci(uri, "file:")) {
        if (!fa.allow_outside) return refuse("is a file: URI");
        target = file_uri_path(uri);
        if (target.empty() || target[0] != '/') {
            if (fa.refused.empty()) fa.refused = "file URI '" + shorten(uri) + "' does not name a local absolute path";
            return {};
        }
    } else if (!uri.empty() && uri[0] == '/') {
        if (!fa.allow_outside) return refuse("is an absolute path");
        target = uri;
    } else if (!fa.allow_outside && climbs_out(uri)) {
        return refuse("climbs out of the scene's folder");
    }
    std::string real = real_path(target);
    if (real.empty()) return target;  // missing: tinygltf reports it as not found
    if (real + "/" == fa.real_dir) return real;  // the folder itself ("", "."): not a file
    if (!fa.allow_outside && real.compare(0, fa.real_dir.size(), fa.real_dir) != 0)
        return refuse("resolves (through a symbolic link) to a file outside the scene's folder");
    return real;
}

bool file_exists(const std::string &path, void *) { return !path.empty() && is_regular_file(path); }

// tinygltf's ReadWholeFile, with the size taken before reading and counted against the limit.
bool read_whole_file(std::vector<unsigned char> *out, std::string *err, const std::string &path, void *user) {
    FileAccess &fa = *static_cast<FileAccess *>(user);
    struct stat st;
    if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) {
        if (err) *err += "File open error : " + shorten(path) + "\n";
        return false;
    }
    const uint64_t size = uint64_t(st.st_size);
    if (size == 0) {
        if (err) *err += "File is empty : " + shorten(path) + "\n";
        return false;
    }
    if (size > fa.read_limit || fa.bytes_read > fa.read_limit - size) {
        if (fa.refused.empty())
            fa.refused = "the files the scene refers to add up to more than " + fa.limited_by + " (" +
                         human_bytes(fa.read_limit) + ") at '" + shorten(path) + "'";
        return false;
    }
    fa.bytes_read += size;
    FILE *f = std::fopen(path.c_str(), "rb");
    if (!f) {
        if (err) *err += "File open error : " + shorten(path) + "\n";
        return false;
    }
    out->resize(size_t(size));
    const size_t got = std::fread(out->data(), 1, out->size(), f);
    std::fclose(f);
    if (got != out->size()) {
        out->clear();
        if (err) *err += "File read error : " + shorten(path) + "\n";
        return false;
    }
    return true;
}

// Image "loader" that decodes nothing. tinygltf 2.7 hands image bytes from a bufferView without
// checking byteOffset/byteLength against the buffer, so those bytes are not touched here; they
// are decoded later from a validated range. Bytes from files and data URIs come from a real
// vector and are kept as-is. Deferring also means only base-colour images get decoded at all.
bool defer_image_decode(tinygltf::Image *image, const int, std::string *, std::string *, int, int,
                        const unsigned char *bytes, int size, void *) {
    if (image->bufferView >= 0) return true;
    if (bytes && size > 0) image->image.assign(bytes, bytes + size);
    image->as_is = true;
    return true;
}

// ---------------------------------------------------------------------------------------------
// Accessors

struct AccessorView {
    const unsigned char *first = nullptr;  // element 0
    uint64_t stride = 0;
    uint64_t count = 0;
    int component_type = 0;
    int components = 0;
    bool normalized = false;
};

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

template <typename T>
T load(const unsigned char *p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

// ---------------------------------------------------------------------------------------------
// Matrices: column-major 4x4 in double, as glTF stores them.

using Mat4 = std::array<double, 16>;

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

// ---------------------------------------------------------------------------------------------
// Scene under construction / owned result

struct MeshData {
    std::vector<float> positions, normals, texcoords;
    std::vector<uint32_t> indices;
    bool has_normals = false, has_texcoords = false;
    int32_t material = -1;
};

}  // namespace

struct icr_scene {
    // deque: element addresses (and so c_str() of short strings) stay put as names are added.
    std::deque<std::string> strings;
    std::vector<MeshData> mesh_data;
    std::vector<std::vector<uint8_t>> pixels;  // decoded images, shared by textures
    std::vector<icr_mesh> meshes;
    std::vector<icr_instance> instances;
    std::vector<icr_material> materials;
    std::vector<icr_texture> textures;
    std::vector<icr_light> lights;
    std::vector<icr_camera> cameras;
    std::vector<icr_node> nodes;
    std::vector<icr_channel> channels;
    // Key times and values of the channels, one array per accessor read (channels may share
    // one); icr_channel's pointers are set once every array is in place.
    std::vector<std::vector<float>> anim_data;
    std::vector<std::pair<size_t, size_t>> channel_data;  // channel -> (times, values) in anim_data
    std::string warnings;

    const char *keep(std::string s) {
        strings.push_back(std::move(s));
        return strings.back().c_str();
    }
};

namespace {

class Converter {
  public:
    Converter(const tinygltf::Model &model, icr_scene &scene, bool flatten)
        : m_(model), s_(scene), flatten_(flatten) {}

    void run() {
        check_graph_and_memory();
        convert_textures_and_materials();
        walk_scene();
        convert_animations();
        finish();
    }

    std::vector<std::string> warnings;

  private:
    const tinygltf::Model &m_;
    icr_scene &s_;
    // The renderer copies every placement into world space (ICR_LOAD_FLATTEN): only the
    // memory estimate depends on it.
    const bool flatten_;
    std::vector<std::vector<int64_t>> mesh_prims_;  // glTF mesh -> icr_mesh per primitive (-1: skipped)
    std::vector<bool> mesh_done_;
    std::vector<int> image_pixels_;  // glTF image -> index into s_.pixels (-1: not decoded)
    std::vector<uint32_t> image_w_, image_h_;
    std::vector<uint32_t> extent_w_, extent_h_;  // declared (header) sizes, 0 until checked
    std::vector<char> on_path_;
    uint64_t visits_ = 0;
    bool warned_skin_ = false;
    std::vector<int64_t> anim_accessor_data_;  // glTF accessor -> index into s_.anim_data (-1: not read)
    uint64_t anim_values_ = 0;

    static std::string quoted_or_index(const std::string &name, const char *kind, size_t index) {
        if (!name.empty()) return std::string(kind) + " '" + shorten(name) + "'";
        return std::string(kind) + " " + std::to_string(index);
    }

    std::string image_label(size_t index) const {
        const tinygltf::Image &img = m_.images[index];
        if (!img.uri.empty()) return "'" + shorten(img.uri) + "'";
        if (!img.name.empty()) return "image[" + std::to_string(index) + "] '" + shorten(img.name) + "'";
        return "image[" + std::to_string(index) + "]";
    }

    // The encoded bytes of a glTF image (from its bufferView, a data URI or a file), with the
    // bufferView's range checked against its buffer.
    void image_bytes(size_t index, const unsigned char **bytes, uint64_t *size) const {
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
    void image_extent(size_t index, uint32_t *width, uint32_t *height) {
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
            if (!stbi_info_from_memory(bytes, int(size), &w, &h, &comp)) {
                const char *why = stbi_failure_reason();
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
    int decoded_image(size_t index) {
        if (image_pixels_[index] >= 0) return image_pixels_[index];
        uint32_t ew, eh;
        image_extent(index, &ew, &eh);
        const unsigned char *bytes = nullptr;
        uint64_t size = 0;
        image_bytes(index, &bytes, &size);
        int w = 0, h = 0, comp = 0;
        // Asking stb for 4 channels expands grey/grey+alpha/RGB to RGBA, and stbi_load (not _16)
        // reduces 16-bit PNGs to 8 bits, which is exactly the icr_texture format.
        unsigned char *px = stbi_load_from_memory(bytes, int(size), &w, &h, &comp, 4);
        if (!px) {
            const char *why = stbi_failure_reason();
            fail("cannot decode texture image " + image_label(index) + ": " + (why ? why : "unknown format"));
        }
        std::vector<uint8_t> rgba;
        try {
            if (w <= 0 || h <= 0) fail("texture image " + image_label(index) + " has no pixels");
            if (uint32_t(w) != ew || uint32_t(h) != eh)
                fail("texture image " + image_label(index) + " decodes to another size than its header says");
            rgba.assign(px, px + size_t(w) * size_t(h) * 4);
        } catch (...) {
            stbi_image_free(px);
            throw;
        }
        stbi_image_free(px);
        s_.pixels.push_back(std::move(rgba));
        image_pixels_[index] = int(s_.pixels.size() - 1);
        image_w_[index] = uint32_t(w);
        image_h_[index] = uint32_t(h);
        return image_pixels_[index];
    }

    // ----- the scene's size, before any of it is allocated

    struct MeshCost {
        bool done = false;
        uint64_t bytes = 0;      // icr_mesh arrays of its triangle primitives
        uint64_t triangles = 0;
        uint64_t primitives = 0;  // its triangle primitives: each placed on its own
    };
    std::vector<MeshCost> mesh_cost_;

    // What a mesh's triangle primitives take as icr_mesh arrays, from accessor counts checked
    // against their buffers (view_accessor). A primitive that the conversion will skip or
    // refuse counts nothing here; the conversion says why.
    const MeshCost &mesh_cost(size_t mi) {
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

    static uint64_t sat_add(uint64_t a, uint64_t b) {
        uint64_t r;
        return __builtin_add_overflow(a, b, &r) ? UINT64_MAX : r;
    }
    static uint64_t sat_mul(uint64_t a, uint64_t b) {
        uint64_t r;
        return __builtin_mul_overflow(a, b, &r) ? UINT64_MAX : r;
    }

    std::vector<int> scene_roots() const {
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
    void check_graph_and_memory() {
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

    void convert_textures_and_materials() {
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

    static bool number_member(const tinygltf::Value &obj, const char *key, double *out) {
        if (!obj.IsObject() || !obj.Has(key)) return false;
        const tinygltf::Value &v = obj.Get(key);
        if (!v.IsNumber()) return false;
        *out = v.GetNumberAsDouble();
        return true;
    }

    static bool number_array_member(const tinygltf::Value &obj, const char *key, double *out, size_t n) {
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

    // ----- meshes

    const std::vector<int64_t> &mesh_primitives(size_t mesh_index) {
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

    int64_t convert_primitive(const tinygltf::Primitive &prim, const std::string &ctx) {
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

    // ----- nodes

    // The node's local transform as the file gives it, into `pose`: its matrix, or its
    // translation, rotation (normalised) and scale with glTF's defaults where absent. Animations
    // replace parts of the TRS at other times (Rust recomputes the matrix the way
    // `local_transform` does).
    void local_pose(const tinygltf::Node &node, const std::string &label, icr_node *pose) {
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
    static bool normalise(double q[4]) {
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
    static Mat4 compose(const double t[3], const double q[4], const double s[3]) {
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
    static Mat4 trs_matrix(const double t[3], const double q_in[4], const double s[3], bool *no_length) {
        double q[4] = {q_in[0], q_in[1], q_in[2], q_in[3]};
        if (!normalise(q)) *no_length = true;
        return compose(t, q, s);
    }

    static Mat4 local_transform(const icr_node &pose) {
        if (pose.has_matrix) {
            Mat4 m{};
            for (size_t i = 0; i < 16; ++i) m[i] = pose.matrix[i];
            return m;
        }
        return compose(pose.translation, pose.rotation, pose.scale);
    }

    // ----- EXT_mesh_gpu_instancing

    struct GpuInstancing {
        int translation = -1, rotation = -1, scale = -1;  // accessors, -1 when absent
    };

    // The extension's attributes on a node, checked for what an index can be; false when the
    // node does not use it. `report`: warn about attributes it ignores.
    bool gpu_instancing(const tinygltf::Node &node, const std::string &label, GpuInstancing *out,
                        bool report = true) {
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
    uint64_t gpu_instance_count(const GpuInstancing &g, const std::string &ctx) {
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
    static void read_vector(const AccessorView &a, uint64_t i, double *out) {
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
    std::vector<Mat4> placements_of(const tinygltf::Node &node, const std::string &label, const Mat4 &world) {
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

    struct PathEntry {
        size_t node;
        Mat4 world;
        size_t next_child;
    };

    // Places one node (instances, camera, light) and returns its world matrix. `parent_index`
    // is -1 for a root.
    Mat4 place_node(size_t ni, const Mat4 &parent, int64_t parent_index) {
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
            add_light(node, label, lp->second, world);
            pose.places |= ICR_PLACES_LIGHT;
        }
        return world;
    }

    // Depth-first walk with an explicit stack: 1024 levels of recursion would not fit the 2 MiB
    // stack of a Rust thread comfortably. `path` is exactly the chain of ancestors, which is
    // what the cycle check needs.
    void walk_from(int root) {
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

    void add_camera(const tinygltf::Node &node, size_t ni, const std::string &label, const Mat4 &world) {
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

    void add_light(const tinygltf::Node &node, const std::string &label, const tinygltf::Value &ext,
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
        s_.lights.push_back(out);
    }

    void walk_scene() {
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
    }


    // ----- animations

    // An accessor's elements as floats (normalised integers converted as glTF 2.0 says), read
    // once however many channels use it.
    size_t animation_floats(int accessor, const std::string &what, bool times, bool rotation, int components) {
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
    void convert_animations() {
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
    void convert_channel(const tinygltf::Animation &anim, const tinygltf::AnimationChannel &ch,
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

    void finish() {
        for (size_t c = 0; c < s_.channels.size(); ++c) {
            const auto [times, values] = s_.channel_data[c];
            if (times == SIZE_MAX) continue;
            s_.channels[c].times = s_.anim_data[times].data();
            s_.channels[c].values = s_.anim_data[values].data();
        }
        s_.meshes.reserve(s_.mesh_data.size());
        for (const MeshData &md : s_.mesh_data) {
            icr_mesh out{};
            out.positions = md.positions.data();
            out.normals = md.has_normals ? md.normals.data() : nullptr;
            out.texcoords = md.has_texcoords ? md.texcoords.data() : nullptr;
            out.indices = md.indices.data();
            out.vertex_count = uint32_t(md.positions.size() / 3);
            out.triangle_count = uint32_t(md.indices.size() / 3);
            out.material = md.material;
            s_.meshes.push_back(out);
        }
    }
};

const char *const kSupportedRequired[] = {
    "EXT_mesh_gpu_instancing",
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_specular",
};

// Empty when every required extension is supported.
std::string unsupported_required(const tinygltf::Model &model) {
    std::vector<std::string> bad;
    for (const std::string &ext : model.extensionsRequired) {
        // glTF 2.0: every required extension is also listed as used.
        if (std::find(model.extensionsUsed.begin(), model.extensionsUsed.end(), ext) == model.extensionsUsed.end())
            return "extensionsRequired lists " + shorten(ext) + ", which extensionsUsed does not";
        bool ok = false;
        for (const char *s : kSupportedRequired) ok = ok || ext == s;
        if (!ok && std::find(bad.begin(), bad.end(), ext) == bad.end()) bad.push_back(ext);
    }
    if (bad.empty()) return {};
    return std::string(bad.size() == 1 ? "unsupported required extension " : "unsupported required extensions ") +
           join(bad, ", ");
}

icr_scene *load_scene(const std::string &path, uint32_t flags) {
    std::vector<unsigned char> data = read_file(path);
    if (data.empty()) fail("file is empty");
    if (data.size() > std::numeric_limits<uint32_t>::max()) fail("file is larger than 4 GiB");
    const size_t size = data.size();

    const bool binary = size >= 4 && std::memcmp(data.data(), "glTF", 4) == 0;
    if (!binary && ends_with_ci(path, ".glb")) fail("not a binary glTF file (no glTF magic)");

    const unsigned char *json_text = data.data();
    size_t json_len = size;
    if (binary) {
        // glTF 2.0: the GLB header's version is 2.
        if (size >= 8 && load<uint32_t>(data.data() + 4) != 2)
            fail("GLB version " + std::to_string(load<uint32_t>(data.data() + 4)) + ": only version 2 can be read");
        // Other malformed headers are left for tinygltf to report.
        json_len = 0;
        if (size >= 20) {
            const uint64_t length = load<uint32_t>(data.data() + 8);
            const uint64_t chunk_len = load<uint32_t>(data.data() + 12);
            if (chunk_len <= size - 20) {
                json_text = data.data() + 20;
                json_len = size_t(chunk_len);
            }
            // tinygltf 2.7 bounds the BIN chunk by the GLB length without counting the chunk's
            // own 8-byte header, and then reads up to 8 bytes past the end of the data.
            const uint64_t bin_header = 20 + chunk_len;
            if (length <= size && bin_header + 8 <= length &&
                bin_header + 8 + load<uint32_t>(data.data() + bin_header) > length)
                fail("GLB BIN chunk extends past the end of the file");
        }
    }
    check_json_depth(json_text, json_len);
    // A GLB whose header gives no JSON chunk is left for tinygltf to describe.
    if (!binary || json_len > 0) screen_json(json_text, json_len);

    std::string base_dir = base_dir_of(path);
    FileAccess access;
    access.prefix = base_dir.back() == '/' ? base_dir : base_dir + "/";
    access.real_dir = real_path(base_dir);
    if (access.real_dir.empty()) fail("cannot resolve the scene's folder: " + std::string(std::strerror(errno)));
    if (access.real_dir.back() != '/') access.real_dir += '/';
    access.allow_outside = (flags & ICR_LOAD_ALLOW_OUTSIDE_REFS) != 0;
    access.read_limit = scene_memory_limit(&access.limited_by);

    tinygltf::TinyGLTF loader;
    tinygltf::FsCallbacks fs{};
    fs.FileExists = &file_exists;
    fs.ExpandFilePath = &expand_file_path;
    fs.ReadWholeFile = &read_whole_file;
    fs.WriteWholeFile = &tinygltf::WriteWholeFile;
    fs.user_data = &access;
    loader.SetFsCallbacks(fs);
    loader.SetImageLoader(&defer_image_decode, nullptr);

    tinygltf::Model model;
    std::string terr, twarn;
    bool ok = binary ? loader.LoadBinaryFromMemory(&model, &terr, &twarn, data.data(), unsigned(size), base_dir)
                     : loader.LoadASCIIFromString(&model, &terr, &twarn, reinterpret_cast<const char *>(data.data()),
                                                  unsigned(size), base_dir);
    // A refused reference is the real reason for whatever tinygltf made of the missing file.
    if (!access.refused.empty()) fail(access.refused);
    // extensionsRequired is parsed before meshes and accessors, so even when tinygltf gives up
    // (e.g. on Draco accessors without bufferViews) the real reason can be reported.
    std::string unsupported = unsupported_required(model);
    if (!unsupported.empty()) fail(unsupported);
    if (!ok) {
        std::string msg = one_line(terr);
        if (msg.empty()) msg = one_line(twarn);
        fail(msg.empty() ? "invalid glTF" : msg);
    }

    std::unique_ptr<icr_scene> scene(new icr_scene());
    Converter conv(model, *scene, (flags & ICR_LOAD_FLATTEN) != 0);
    conv.run();

    std::vector<std::string> warnings = split_lines(twarn);
    // tinygltf reports some recoverable problems (e.g. a dropped primitive) in err while still
    // succeeding; they are warnings from the caller's point of view.
    for (std::string &l : split_lines(terr)) warnings.push_back(std::move(l));
    for (const std::string &w : conv.warnings)
        for (std::string &l : split_lines(w)) warnings.push_back(std::move(l));
    // A file can ask for a warning per primitive or image: keep the output readable.
    if (warnings.size() > kMaxWarnings) {
        const size_t more = warnings.size() - (kMaxWarnings - 1);
        warnings.resize(kMaxWarnings - 1);
        warnings.push_back("... and " + std::to_string(more) + " more warnings");
    }
    for (std::string &w : warnings) w = shorten(w, 4 * kMaxQuoted);
    scene->warnings = join(warnings, "\n");
    return scene.release();
}

}  // namespace

extern "C" icr_scene *icr_scene_load(const char *path, uint32_t flags, uint64_t memory_limit, char *err,
                                      size_t err_len) {
    if (err && err_len) err[0] = '\0';
    t_requested_limit = memory_limit;
    try {
        if (!path || !*path) {
            write_error(err, err_len, "empty path");
            return nullptr;
        }
        return load_scene(path, flags);
    } catch (const LoadError &e) {
        write_error(err, err_len, e.what());
    } catch (const std::bad_alloc &) {
        write_error(err, err_len, "out of memory");
    } catch (const std::exception &e) {
        write_error(err, err_len, std::string("glTF loading failed: ") + e.what());
    } catch (...) {
        write_error(err, err_len, "glTF loading failed: unknown exception");
    }
    return nullptr;
}

namespace {

// Empty arrays are reported with a non-NULL, suitably aligned pointer: Rust's
// slice::from_raw_parts requires one even for length 0.
template <typename T>
const T *array_ptr(const std::vector<T> &v) {
    static const T empty{};
    return v.empty() ? &empty : v.data();
}

}  // namespace

extern "C" icr_scene_view icr_scene_get_view(const icr_scene *scene) {
    icr_scene_view v{};
    if (!scene) {
        static const icr_scene none;
        scene = &none;
    }
    v.meshes = array_ptr(scene->meshes);
    v.mesh_count = scene->meshes.size();
    v.instances = array_ptr(scene->instances);
    v.instance_count = scene->instances.size();
    v.materials = array_ptr(scene->materials);
    v.material_count = scene->materials.size();
    v.textures = array_ptr(scene->textures);
    v.texture_count = scene->textures.size();
    v.lights = array_ptr(scene->lights);
    v.light_count = scene->lights.size();
    v.cameras = array_ptr(scene->cameras);
    v.camera_count = scene->cameras.size();
    v.nodes = array_ptr(scene->nodes);
    v.node_count = scene->nodes.size();
    v.channels = array_ptr(scene->channels);
    v.channel_count = scene->channels.size();
    v.warnings = scene->warnings.c_str();
    return v;
}

extern "C" void icr_scene_free(icr_scene *scene) { delete scene; }
