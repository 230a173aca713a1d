/*
 * C ABI over OpenImageIO (cpp/image_io.cpp): writing a multi-layer OpenEXR and a PNG preview,
 * and reading an EXR back channel by channel. Rust decides names, layers and temporary paths;
 * C++ only moves pixels. Every function returns 0 on success, or non-zero with a one-line,
 * NUL-terminated message in err[0..err_len).
 */
#ifndef ICR_IMAGE_IO_H
#define ICR_IMAGE_IO_H
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* One named float channel: its name and format (`data` is unused by the row writer). */
typedef struct icr_channel {
    const char *name;         /* e.g. "R", "direct.G" */
    const float *data;
    int32_t full_float;       /* 1: stored as 32-bit float even when the file is half */
} icr_channel;

/* A string attribute for the file header, e.g. {"icrender:options", "-ab 1 ..."}. */
typedef struct icr_attribute {
    const char *name;
    const char *value;
} icr_attribute;

/*
 * Where the pixels lie in the whole image: a data window of width x height pixels whose top
 * left pixel is (x, y) inside a display window full_width x full_height from (0, 0).
 * A whole image is {0, 0, width, height}.
 */
typedef struct icr_window {
    int32_t x;
    int32_t y;
    uint32_t full_width;
    uint32_t full_height;
} icr_window;

/*
 * Fills rows [y0, y1) of the data window (0 is its top row) into `strip`, interleaved: row by
 * row, pixel by pixel, every channel in the order given. Returns 0, or non-zero to abandon the
 * write (the writer then fails with "the pixels could not be made").
 */
typedef int (*icr_fill_rows)(void *context, uint32_t y0, uint32_t y1, float *strip);

/*
 * Writes an OpenEXR (half or float, chosen by `half_float`, except channels marked full_float,
 * which stay float: OpenImageIO's per-channel formats) with the channels in the order given,
 * to exactly `path` (which need not end in .exr: the caller writes to a temporary name and
 * renames). `compression` is OpenEXR's name of the codec (zip, piz, dwaa, none, ...); NULL or
 * empty means zip. The pixels come a strip of rows at a time from `fill` (called in order, top
 * to bottom): the caller need hold no planar copy of the image. The channels' `data` is not
 * read and may be NULL.
 */
int icr_exr_write_rows(const char *path, uint32_t width, uint32_t height, icr_window window,
                       const icr_channel *channels, size_t channel_count,
                       const icr_attribute *attributes, size_t attribute_count,
                       int half_float, const char *compression, icr_fill_rows fill, void *context,
                       char *err, size_t err_len);

/*
 * A tiled EXR written as its tiles finish, for the codecs OpenEXR's core library cannot encode
 * (ffi/exr_chunks.h does the others, DWA among them before OpenEXR 3.2): open it (tile_width x tile_height tiles, channels,
 * window, half_float and compression as for icr_exr_write_rows, and header_room bytes kept in
 * the header, as attribute "icrender/reserved", for what is known only at the end), write
 * rectangles of whole tiles in any order and from any thread, then end it (which writes its
 * chunk offsets and frees it); close abandons it. Then icr_exr_set_header puts the last
 * attributes into the room, or icr_exr_copy_with_header writes another file with them.
 */
typedef struct icr_exr_stream icr_exr_stream;
icr_exr_stream *icr_exr_stream_open(const char *path, uint32_t width, uint32_t height, icr_window window,
                                    const icr_channel *channels, size_t channel_count, int half_float,
                                    const char *compression, uint32_t tile_width, uint32_t tile_height,
                                    size_t header_room, char *err, size_t err_len);
/*
 * Writes the pixels [x0, x1) x [y0, y1) of the data window (0 is its first row and column):
 * x0 and y0 on the tile grid, x1 and y1 on it or at the window's edge; `pixels` interleaved,
 * row by row, every channel in the order given at open.
 */
int icr_exr_stream_write(icr_exr_stream *stream, uint32_t x0, uint32_t y0, uint32_t x1, uint32_t y1,
                         const float *pixels, char *err, size_t err_len);
int icr_exr_stream_end(icr_exr_stream *stream, char *err, size_t err_len);
void icr_exr_stream_close(icr_exr_stream *stream);
/*
 * Rewrites the header of the tiled EXR at `path` in place with the attributes added (the room
 * kept at open filled with an attribute of a type readers skip): 0 done, 2 no room (nothing
 * changed), 1 failed.
 */
int icr_exr_set_header(const char *path, const icr_attribute *attributes, size_t attribute_count, char *err,
                       size_t err_len);
/* Writes `to`: the tiled EXR `from` with the attributes added, its compressed tiles copied. */
int icr_exr_copy_with_header(const char *from, const char *to, const icr_attribute *attributes,
                             size_t attribute_count, char *err, size_t err_len);

/* Writes an 8-bit RGB PNG (rgb: 3 * width * height bytes) to exactly `path`. */
int icr_png_write(const char *path, uint32_t width, uint32_t height, const uint8_t *rgb,
                  char *err, size_t err_len);

typedef struct icr_image icr_image;

/* Reads every channel of the first subimage of an image file as float. NULL on failure. */
icr_image *icr_image_read(const char *path, char *err, size_t err_len);
uint32_t icr_image_width(const icr_image *image);
uint32_t icr_image_height(const icr_image *image);
/* The data window's place in the display window (a whole image: {0, 0, width, height}). */
icr_window icr_image_window(const icr_image *image);
/* Header attributes: how many, and the name of attribute i (valid until icr_image_free). */
size_t icr_image_attribute_count(const icr_image *image);
const char *icr_image_attribute_name(const icr_image *image, size_t i);
size_t icr_image_channel_count(const icr_image *image);
/* Name of channel i (valid until icr_image_free). */
const char *icr_image_channel_name(const icr_image *image, size_t i);
/* Plane of channel i: width * height floats, rows top to bottom. */
const float *icr_image_channel_data(const icr_image *image, size_t i);
/* Header attribute as text, or NULL when absent (valid until icr_image_free). */
const char *icr_image_attribute(const icr_image *image, const char *name);
void icr_image_free(icr_image *image);

#ifdef __cplusplus
}
#endif
#endif
