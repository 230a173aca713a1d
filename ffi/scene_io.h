/*
 * C ABI between the C++ glTF loader (cpp/scene_io*.cpp, tinygltf) and the Rust renderer.
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
    uint32_t node;                /* the glTF node that places it (animations move it) */
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
    uint32_t node;                /* the glTF node that places it (see icr_node, for animation) */
} icr_camera;

/* What a node places itself (not its children): bits of icr_node.places. */
#define ICR_PLACES_MESH 1u
#define ICR_PLACES_LIGHT 2u
#define ICR_PLACES_CAMERA 4u
#define ICR_PLACES_JOINT 8u      /* a joint of a skin that an in-scene mesh uses */

/*
 * A glTF node's rest pose, for evaluating animations: one per node of the file, in file order.
 * World matrices at rest are already in instances, lights and cameras; these let the renderer
 * recompute a node's world matrix at another time (parent first, as glTF composes them).
 */
typedef struct icr_node {
    const char *name;             /* never NULL; "" when unnamed */
    int32_t parent;               /* the parent node, -1 for a root or a node outside the scene */
    int32_t in_scene;             /* 1 when the scene's node trees reach it */
    uint32_t places;              /* ICR_PLACES_* bits */
    int32_t has_matrix;           /* 1: `matrix` is the local transform (such a node may not be animated) */
    double matrix[16];            /* column-major local matrix when has_matrix */
    double translation[3];        /* local TRS otherwise, glTF's defaults where absent */
    double rotation[4];           /* x y z w, normalised as the loader uses it */
    double scale[3];
} icr_node;

enum icr_anim_path {
    ICR_ANIM_TRANSLATION = 0,
    ICR_ANIM_ROTATION = 1,
    ICR_ANIM_SCALE = 2,
    ICR_ANIM_WEIGHTS = 3,         /* morph target weights: not read (key_count 0) */
    ICR_ANIM_OTHER = 4            /* a path of some extension: not read (key_count 0) */
};
enum icr_interpolation { ICR_INTERP_LINEAR = 0, ICR_INTERP_STEP = 1, ICR_INTERP_CUBICSPLINE = 2 };

/*
 * One animation channel with its sampler, checked against the glTF 2.0 rules: key times
 * finite and strictly increasing, as many outputs as keys (three per key for CUBICSPLINE: in-
 * tangent, value, out-tangent), at least two keys for CUBICSPLINE. Rotations stored as
 * normalised integers are converted to floats. A channel that breaks a rule is still listed,
 * with `error` set and no keys: a still render does not need it.
 */
typedef struct icr_channel {
    uint32_t animation;           /* index of its animation in the file */
    const char *animation_name;   /* never NULL; "" when unnamed */
    uint32_t node;                /* the target node (< node_count), or UINT32_MAX when the file's is out of range */
    int32_t path;                 /* icr_anim_path */
    int32_t interpolation;        /* icr_interpolation */
    uint32_t key_count;
    uint32_t components;          /* 3 (translation, scale) or 4 (rotation x y z w); 0 when not read */
    const float *times;           /* key_count seconds */
    const float *values;          /* key_count * components (x3 for CUBICSPLINE) */
    const char *error;            /* NULL, or why the channel breaks glTF's rules (then nothing is read) */
} icr_channel;

typedef struct icr_scene_view {
    const icr_mesh *meshes;         size_t mesh_count;
    const icr_instance *instances;  size_t instance_count;
    const icr_material *materials;  size_t material_count;
    const icr_texture *textures;    size_t texture_count;
    const icr_light *lights;        size_t light_count;
    const icr_camera *cameras;      size_t camera_count;
    const icr_node *nodes;          size_t node_count;
    const icr_channel *channels;    size_t channel_count;
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
