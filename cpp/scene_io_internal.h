// Shared by the glTF loader's translation units (implements ffi/scene_io.h on top of tinygltf 2.7):
// - scene_io.cpp            loading: the file, tinygltf, external files, the C ABI's entry points;
// - scene_io_validate.cpp   validation and hardening: checked numbers, limits, screening the JSON;
// - scene_io_mesh.cpp       mesh extraction: accessors, triangle primitives, GPU instancing;
// - scene_io_materials.cpp  materials and their textures' images;
// - scene_io_nodes.cpp      the node graph: transforms, the walk, what each node places;
// - scene_io_cameras.cpp    cameras;
// - scene_io_lights.cpp     KHR_lights_punctual lights;
// - scene_io_animation.cpp  animation channels.
// The loader is only an adapter: it validates what it reads, converts to the flat arrays of the
// C ABI and leaves every rendering decision (degenerate triangles, NaNs, units, light models) to
// Rust. Nothing may escape across the ABI: every entry point catches all exceptions, and every
// index, offset and size taken from the file is checked before memory is touched.

#pragma once

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
#error "the glTF loader assumes a little-endian target"
#endif

// Every translation unit sees tinygltf configured alike (scene_io.cpp also compiles it).
#ifndef TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#endif
#include <tiny_gltf.h>

namespace icr_io {

// Internal failure; turned into the one-line error message at the ABI boundary.
struct LoadError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// A NUL byte (from a name or URI in the file) would silently cut the message short.
[[noreturn]] inline void fail(std::string msg) {
    for (size_t i = msg.find('\0'); i != std::string::npos; i = msg.find('\0', i + 2)) msg.replace(i, 1, "\\0");
    throw LoadError(msg);
}

inline constexpr size_t kMaxNodeDepth = 1024;

// Decoded texture images: wider than any GPU texture is refused before decoding (and so before
// allocating), as is a total that would need more than 1 GiB of RGBA.
inline constexpr uint64_t kMaxImageSide = 32768;

inline constexpr uint64_t kMaxImagePixels = uint64_t(1) << 28;

// Names and URIs quoted in messages are cut to this many bytes.
inline constexpr size_t kMaxQuoted = 96;

// Warnings beyond this many are summarised in one line.
inline constexpr size_t kMaxWarnings = 100;

// Nodes reused by several parents (which could expand exponentially) are refused before the
// walk, so the walk visits each node once; this bound is a second line of defence.
inline constexpr uint64_t kMaxNodeVisits = uint64_t(1) << 26;

// tinygltf converts "extensions" objects to its Value type recursively; deep nesting there would
// overflow the stack, so the JSON is screened before tinygltf sees it.
inline constexpr size_t kMaxJsonDepth = 256;

inline constexpr double kHalfPi = 1.57079632679489661923;

// Key times and values of all animations together (floats): a bound on what a file can make
// the loader allocate beyond its buffers.
inline constexpr uint64_t kMaxAnimationValues = uint64_t(1) << 26;

std::vector<std::string> split_lines(const std::string &text);
std::string join(const std::vector<std::string> &parts, const char *sep);
std::string one_line(const std::string &text);
void write_error(char *err, size_t err_len, const std::string &msg);
uint64_t add_checked(uint64_t a, uint64_t b, const std::string &what);
uint64_t mul_checked(uint64_t a, uint64_t b, const std::string &what);
bool ends_with_ci(const std::string &s, const char *suffix);
bool is_regular_file(const std::string &path);
bool starts_with_ci(const std::string &s, const char *prefix);
std::string shorten(const std::string &text, size_t max = kMaxQuoted);
std::vector<unsigned char> read_file(const std::string &path);
void check_json_depth(const unsigned char *p, size_t n);
bool data_uri_payload_size(const std::string &uri, uint64_t *size);
void screen_json(const unsigned char *text, size_t n);
std::string base_dir_of(const std::string &path);
std::string human_bytes(uint64_t bytes);
// The caller's --max-memory for the load in progress on this thread (0: none).
extern thread_local uint64_t t_requested_limit;

uint64_t scene_memory_limit(std::string *what);
uint64_t scene_memory_limit_of_machine(std::string *what);
bool header_extent(const unsigned char *p, uint64_t size, uint32_t *w, uint32_t *h);
void check_declared_extent(const std::string &what, const unsigned char *bytes, uint64_t size, int64_t w, int64_t h);
bool climbs_out(const std::string &rel);
std::string file_uri_path(const std::string &uri);
std::string real_path(const std::string &path);
std::string expand_file_path(const std::string &joined, void *user);
bool file_exists(const std::string &path, void *);
bool read_whole_file(std::vector<unsigned char> *out, std::string *err, const std::string &path, void *user);
bool defer_image_decode(tinygltf::Image *image, const int, std::string *, std::string *, int, int,
                        const unsigned char *bytes, int size, void *);
// Accessors
struct AccessorView {
    const unsigned char *first = nullptr;  // element 0
    uint64_t stride = 0;
    uint64_t count = 0;
    int component_type = 0;
    int components = 0;
    bool normalized = false;
};

const char *type_name(int type);
const char *component_name(int ct);
AccessorView view_accessor(const tinygltf::Model &model, int index, const std::string &ctx);
template <typename T>
inline T load(const unsigned char *p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

// Matrices: column-major 4x4 in double, as glTF stores them.
using Mat4 = std::array<double, 16>;

Mat4 identity();
Mat4 mul(const Mat4 &a, const Mat4 &b);
void transform_dir(const Mat4 &m, double x, double y, double z, float out[3]);
// Scene under construction / owned result
struct MeshData {
    std::vector<float> positions, normals, texcoords;
    std::vector<uint32_t> indices;
    bool has_normals = false, has_texcoords = false;
    int32_t material = -1;
};

std::string unsupported_required(const tinygltf::Model &model);
icr_scene *load_scene(const std::string &path, uint32_t flags);

// stb_image is compiled static into scene_io.cpp (see there); the textures reach it through these.
bool image_info(const unsigned char *bytes, int size, int *w, int *h, int *comp);
unsigned char *image_load_rgba(const unsigned char *bytes, int size, int *w, int *h, int *comp);
void image_free(unsigned char *pixels);
const char *image_failure_reason();

}  // namespace icr_io

// The loaded scene the C ABI hands out: every array the icr_scene_view points into.
struct icr_scene {
    // deque: element addresses (and so c_str() of short strings) stay put as names are added.
    std::deque<std::string> strings;
    std::vector<icr_io::MeshData> mesh_data;
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

namespace icr_io {

// Converts a parsed glTF model into an icr_scene. Its members are defined by concern across
// the scene_io*.cpp files named at the top of this header.
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
    std::vector<size_t> skinned_;  // skins of placed meshes (their joints are marked after the walk)
    std::vector<int64_t> anim_accessor_data_;  // glTF accessor -> index into s_.anim_data (-1: not read)
    uint64_t anim_values_ = 0;

    static std::string quoted_or_index(const std::string &name, const char *kind, size_t index);

    std::string image_label(size_t index) const;

    void image_bytes(size_t index, const unsigned char **bytes, uint64_t *size) const;

    void image_extent(size_t index, uint32_t *width, uint32_t *height);

    int decoded_image(size_t index);

    // ----- the scene's size, before any of it is allocated

    struct MeshCost {
        bool done = false;
        uint64_t bytes = 0;      // icr_mesh arrays of its triangle primitives
        uint64_t triangles = 0;
        uint64_t primitives = 0;  // its triangle primitives: each placed on its own
    };
    std::vector<MeshCost> mesh_cost_;

    const MeshCost &mesh_cost(size_t mi);

    static uint64_t sat_add(uint64_t a, uint64_t b);
    static uint64_t sat_mul(uint64_t a, uint64_t b);

    std::vector<int> scene_roots() const;

    void check_graph_and_memory();

    void convert_textures_and_materials();

    static bool number_member(const tinygltf::Value &obj, const char *key, double *out);

    static bool number_array_member(const tinygltf::Value &obj, const char *key, double *out, size_t n);

    // ----- meshes

    const std::vector<int64_t> &mesh_primitives(size_t mesh_index);

    int64_t convert_primitive(const tinygltf::Primitive &prim, const std::string &ctx);

    // ----- nodes

    void local_pose(const tinygltf::Node &node, const std::string &label, icr_node *pose);

    static bool normalise(double q[4]);

    static Mat4 compose(const double t[3], const double q[4], const double s[3]);

    static Mat4 trs_matrix(const double t[3], const double q_in[4], const double s[3], bool *no_length);

    static Mat4 local_transform(const icr_node &pose);

    // ----- EXT_mesh_gpu_instancing

    struct GpuInstancing {
        int translation = -1, rotation = -1, scale = -1;  // accessors, -1 when absent
    };

    bool gpu_instancing(const tinygltf::Node &node, const std::string &label, GpuInstancing *out,
                        bool report = true);

    uint64_t gpu_instance_count(const GpuInstancing &g, const std::string &ctx);

    static void read_vector(const AccessorView &a, uint64_t i, double *out);

    std::vector<Mat4> placements_of(const tinygltf::Node &node, const std::string &label, const Mat4 &world);

    struct PathEntry {
        size_t node;
        Mat4 world;
        size_t next_child;
    };

    Mat4 place_node(size_t ni, const Mat4 &parent, int64_t parent_index);

    void walk_from(int root);

    void add_camera(const tinygltf::Node &node, size_t ni, const std::string &label, const Mat4 &world);

    void add_light(const tinygltf::Node &node, size_t ni, const std::string &label, const tinygltf::Value &ext,
                   const Mat4 &world);

    void walk_scene();


    // ----- animations

    size_t animation_floats(int accessor, const std::string &what, bool times, bool rotation, int components);

    void convert_animations();

    void convert_channel(const tinygltf::Animation &anim, const tinygltf::AnimationChannel &ch,
                         const std::string &clabel, icr_channel &out, size_t *times_out, size_t *values_out);

    void finish();
};

}  // namespace icr_io
