// glTF loading for icrender (implements ffi/scene_io.h on top of tinygltf 2.7): the file read and
// screened, tinygltf run with the external-file policy below, the model converted (the
// Converter, whose parts live in the scene_io_*.cpp files: see scene_io_internal.h), and the
// C ABI's entry points, which turn every failure into a one-line message.

#include <sys/stat.h>
#include <unistd.h>

// stb_image is compiled static so that this object cannot clash with another copy of stb linked
// into the final binary by some other crate; tinygltf and the texture decoding (through the
// image_* functions below) are its callers.
#define STB_IMAGE_STATIC
// Readable decode errors ("Corrupt PNG") instead of stb's terse codes; they reach the user.
#define STBI_FAILURE_USERMSG
#define STB_IMAGE_IMPLEMENTATION
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE_WRITE
#include "scene_io_internal.h"

namespace icr_io {

bool image_info(const unsigned char *bytes, int size, int *w, int *h, int *comp) {
    return stbi_info_from_memory(bytes, size, w, h, comp) != 0;
}

unsigned char *image_load_rgba(const unsigned char *bytes, int size, int *w, int *h, int *comp) {
    return stbi_load_from_memory(bytes, size, w, h, comp, 4);
}

void image_free(unsigned char *pixels) { stbi_image_free(pixels); }

const char *image_failure_reason() { return stbi_failure_reason(); }

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

// Directory part of the path as tinygltf expects it (it joins with '/').
std::string base_dir_of(const std::string &path) {
    size_t slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    if (slash == 0) return "/";
    return path.substr(0, slash);
}

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

void Converter::finish() {
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

}  // namespace icr_io

using namespace icr_io;


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
