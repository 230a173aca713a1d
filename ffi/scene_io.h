/*
 * C ABI between the C++ glTF loader (cpp/scene_io.cpp, tinygltf) and the Rust renderer.
 *
 * The loader only adapts: it parses the file, validates every accessor against the buffers it
 * reads, decodes textures, walks the node graph and hands back flat arrays. Meshes stay in their
 * own (object) space; each placement of a mesh by a node is an instance with a world matrix, so
 * a mesh used by many nodes is stored once. All arrays are owned by the icr_scene handle and live
 * until icr_scene_free.
 */
#ifndef ICR_SCENE_IO_H
#define ICR_SCENE_IO_H
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* One triangle primitive (glTF mode 4, or a non-indexed list) in object space. */
typedef struct icr_mesh {
    const float *positions;  /* 3 * vertex_count */
    const float *normals;    /* 3 * vertex_count, or NULL when the file has no NORMAL */
    const float *texcoords;  /* 2 * vertex_count (TEXCOORD_0), or NULL */
    const uint32_t *indices; /* 3 * triangle_count, each < vertex_count (checked by the loader) */
    uint32_t vertex_count;
    uint32_t triangle_count;
    int32_t material;        /* index into materials, or -1 for the glTF default material */
} icr_mesh;

/* A placement of a mesh primitive in the world: one per node naming the mesh, or with
 * EXT_mesh_gpu_instancing one per instance of the node (node world * instance TRS), in the
 * instances' order. */
typedef struct icr_instance {
    uint32_t mesh;           /* index into meshes */
    double world[16];         /* column-major 4x4, as glTF stores matrices */
    uint32_t node;           /* index of the glTF node that places it */
    const char *node_name;   /* that node's name; never NULL, "" when unnamed */
} icr_instance;

enum icr_alpha_mode { ICR_ALPHA_OPAQUE = 0, ICR_ALPHA_MASK = 1, ICR_ALPHA_BLEND = 2 };

/* The glTF material as written in the file, with extension values or their spec defaults. */
typedef struct icr_material {
    const char *name;             /* never NULL; "" when unnamed */
    float base_color[4];          /* baseColorFactor (linear) */
    int32_t base_color_texture;   /* index into textures, or -1 */
    float metallic;               /* metallicFactor */
    float roughness;              /* roughnessFactor (perceptual) */
    float emissive[3];            /* emissiveFactor */
    float emissive_strength;      /* KHR_materials_emissive_strength, 1 when absent */
    float specular_factor;        /* KHR_materials_specular specularFactor, 1 when absent */
    float specular_color[3];      /* KHR_materials_specular specularColorFactor, 1 when absent */
    int32_t alpha_mode;           /* icr_alpha_mode */
    float alpha_cutoff;
    int32_t double_sided;
} icr_material;

/* A decoded base-colour image: 8-bit RGBA, rows top to bottom, as glTF UVs address them. */
typedef struct icr_texture {
    const char *name;
    const uint8_t *rgba;          /* 4 * width * height */
    uint32_t width;
    uint32_t height;
    int32_t wrap_s;               /* glTF sampler wrap: 33071 clamp, 33648 mirrored, 10497 repeat */
    int32_t wrap_t;
    int32_t srgb;                 /* 1: the bytes are sRGB-encoded (base colour always is) */
} icr_texture;

enum icr_light_type { ICR_LIGHT_POINT = 0, ICR_LIGHT_SPOT = 1, ICR_LIGHT_DIRECTIONAL = 2 };

/* A KHR_lights_punctual light placed by a node, in world space. */
typedef struct icr_light {
    const char *name;
    int32_t type;                 /* icr_light_type */
    float color[3];
    float intensity;              /* candela (point, spot) or lux (directional) */
    float range;                  /* 0 when unbounded */
    float inner_cone;             /* radians, spot only */
    float outer_cone;
    double position[3];           /* world; double: a scene may sit 1e7 units from the origin */
    float direction[3];           /* world, unit: where the light points (node's -Z) */
} icr_light;

/* A camera placed by a node, in world space. */
typedef struct icr_camera {
    const char *name;
    int32_t perspective;          /* 1 perspective, 0 orthographic */
    float yfov;                   /* radians (perspective) */
    float aspect;                 /* 0 when the file leaves it to the viewport */
    float xmag, ymag;             /* orthographic half extents */
    double position[3];           /* world; double, as a light's */
    float forward[3];             /* world, unit (node's -Z) */
    float up[3];                  /* world, unit (node's +Y) */
} icr_camera;

typedef struct icr_scene_view {
    const icr_mesh *meshes;         size_t mesh_count;
    const icr_instance *instances;  size_t instance_count;
    const icr_material *materials;  size_t material_count;
    const icr_texture *textures;    size_t texture_count;
    const icr_light *lights;        size_t light_count;
    const icr_camera *cameras;      size_t camera_count;
    const char *warnings;           /* newline-separated loader warnings, "" when none */
} icr_scene_view;

typedef struct icr_scene icr_scene;

/* Flags of icr_scene_load. */
#define ICR_LOAD_ALLOW_OUTSIDE_REFS 1u /* buffers and images may lie outside the file's folder */
#define ICR_LOAD_FLATTEN 2u            /* the caller copies every placement of a mesh (memory estimate) */

/*
 * Loads a .gltf or .glb file. On failure returns NULL and writes a one-line, NUL-terminated
 * message (without the path; the caller names the file) into err[0..err_len).
 * memory_limit: bytes the loaded scene may take (0: only the machine's or the cgroup's
 * memory); a scene that would take more is refused before its arrays are allocated.
 */
icr_scene *icr_scene_load(const char *path, uint32_t flags, uint64_t memory_limit, char *err, size_t err_len);
/* The arrays of a loaded scene; valid until icr_scene_free. */
icr_scene_view icr_scene_get_view(const icr_scene *scene);
void icr_scene_free(icr_scene *scene);

#ifdef __cplusplus
}
#endif
#endif
